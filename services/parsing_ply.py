"""PLY reader (ascii, binary little/big endian) that extracts vertex x, y, z from bytes.

Only the vertex element is decoded. Elements before it are skipped (binary: only when they
have no list properties, whose size cannot be known without walking every item); elements
after it are ignored apart from a size plausibility check.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.errors import InvalidFragmentError
from services.parsing_common import (
    check_point_count,
    parse_ascii_block,
    read_binary_records,
    records_xyz,
    table_xyz,
)
from services.types import FloatArray

__all__ = ["read_ply_xyz"]

# PLY scalar type names (classic and sized aliases) -> numpy type code without byte order.
_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
_ENCODINGS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}
_XYZ = ("x", "y", "z")


@dataclass(frozen=True)
class _Property:
    name: str
    code: str  # numpy code of the value (of the items, for a list)
    count_code: str | None = None  # numpy code of the length prefix; None for scalars


@dataclass
class _Element:
    name: str
    count: int
    props: list[_Property]

    @property
    def has_list(self) -> bool:
        return any(p.count_code is not None for p in self.props)

    def dtype(self, order: str) -> np.dtype[np.void]:
        # Positional field names: PLY property names may repeat or be odd identifiers.
        return np.dtype(
            {
                "names": [f"f{i}" for i in range(len(self.props))],
                "formats": [order + p.code for p in self.props],
            }
        )

    def xyz_indices(self) -> list[int]:
        names = [p.name for p in self.props]
        missing = [axis for axis in _XYZ if axis not in names]
        if missing:
            raise InvalidFragmentError(
                f"PLY vertex element lacks x/y/z properties (missing {', '.join(missing)})"
            )
        return [names.index(axis) for axis in _XYZ]

    def min_size(self, order: str) -> int:
        # Bytes of one item when every list is empty: a lower bound for binary size checks.
        codes = [p.count_code or p.code for p in self.props]
        return self.count * sum(np.dtype(order + c).itemsize for c in codes)


@dataclass(frozen=True)
class _Header:
    order: str  # "" for ascii, "<" or ">" for binary
    elements: list[_Element]
    body_offset: int


def _type_code(name: str) -> str:
    try:
        return _TYPES[name]
    except KeyError:
        raise InvalidFragmentError(f"PLY header uses unknown property type {name!r}") from None


def _parse_int(token: str, what: str) -> int:
    try:
        return int(token)
    except ValueError:
        raise InvalidFragmentError(f"PLY header has a non-integer {what}: {token!r}") from None


def _parse_property(tokens: list[str]) -> _Property:
    if len(tokens) == 5 and tokens[1] == "list":
        return _Property(tokens[4], _type_code(tokens[3]), _type_code(tokens[2]))
    if len(tokens) == 3:
        return _Property(tokens[2], _type_code(tokens[1]))
    raise InvalidFragmentError(f"PLY header has a malformed property line: {' '.join(tokens)!r}")


def _split_header(data: bytes) -> tuple[list[str], int]:
    """Return the header lines (without ``end_header``) and the offset of the body."""
    marker = data.find(b"\nend_header")
    if marker < 0:
        raise InvalidFragmentError("PLY header has no end_header line")
    newline = data.find(b"\n", marker + 1)
    body_offset = len(data) if newline < 0 else newline + 1
    if data[marker + len(b"\nend_header") : body_offset].strip():
        raise InvalidFragmentError("PLY header has a malformed end_header line")
    # latin-1 never fails to decode; only ASCII keywords matter in the header.
    return data[:marker].decode("latin-1").splitlines(), body_offset


def _parse_header(data: bytes) -> _Header:
    lines, body_offset = _split_header(data)
    order: str | None = None
    elements: list[_Element] = []
    for line in lines[1:]:
        tokens = line.split()
        keyword = tokens[0] if tokens else "comment"
        if keyword in ("comment", "obj_info"):
            continue
        if keyword == "format" and len(tokens) == 3 and tokens[1] in _ENCODINGS:
            order = _ENCODINGS[tokens[1]]
        elif keyword == "element" and len(tokens) == 3:
            elements.append(_Element(tokens[1], _parse_int(tokens[2], "element count"), []))
        elif keyword == "property" and elements:
            elements[-1].props.append(_parse_property(tokens))
        else:
            raise InvalidFragmentError(f"PLY header has an unexpected line: {line.strip()!r}")
    if order is None:
        raise InvalidFragmentError("PLY header has no valid format line")
    return _Header(order, elements, body_offset)


def _find_vertex(header: _Header, max_points: int) -> int:
    index = next((i for i, e in enumerate(header.elements) if e.name == "vertex"), None)
    if index is None:
        raise InvalidFragmentError("PLY header declares no vertex element")
    vertex = header.elements[index]
    check_point_count(vertex.count, max_points, "PLY")
    if vertex.has_list:
        raise InvalidFragmentError("PLY vertex element with list properties is not supported")
    for element in header.elements:
        if element.count < 0:
            raise InvalidFragmentError(f"PLY element {element.name!r} has a negative count")
    return index


def _check_binary_tail(data: bytes, end: int, after: list[_Element], order: str) -> None:
    """Bytes after the vertex element must be explained by the elements declared after it."""
    remaining = len(data) - end
    minimum = sum(e.min_size(order) for e in after)
    if remaining < minimum:
        raise InvalidFragmentError(
            f"PLY binary data is truncated: elements after the vertices need at least "
            f"{minimum} bytes, only {remaining} present"
        )
    # With list properties the exact size is unknown without walking every item.
    if not any(e.has_list for e in after) and remaining > minimum:
        raise InvalidFragmentError(
            f"PLY header inconsistent with size: {remaining - minimum} unexpected bytes "
            f"after the declared elements"
        )


def _read_binary(data: bytes, header: _Header, index: int) -> FloatArray:
    vertex = header.elements[index]
    fields = [f"f{i}" for i in vertex.xyz_indices()]
    offset = header.body_offset
    for element in header.elements[:index]:
        if element.has_list:
            raise InvalidFragmentError(
                f"PLY element {element.name!r} with list properties before the vertex "
                f"element is not supported in binary files"
            )
        offset += element.count * element.dtype(header.order).itemsize
    records = read_binary_records(data, offset, vertex.dtype(header.order), vertex.count, "PLY")
    _check_binary_tail(data, offset + records.nbytes, header.elements[index + 1 :], header.order)
    return records_xyz(records, fields)


def _read_ascii(data: bytes, header: _Header, index: int) -> FloatArray:
    vertex = header.elements[index]
    columns = vertex.xyz_indices()
    body = data[header.body_offset :]
    first = sum(e.count for e in header.elements[:index])
    if first == 0 and index == len(header.elements) - 1:
        # Common case: the vertices are the whole body, no line bookkeeping needed.
        block = body
    else:
        # One element item per line: locate the vertex lines by their newline offsets.
        newlines = np.flatnonzero(np.frombuffer(body, dtype=np.uint8) == ord("\n"))
        last = first + vertex.count
        if len(newlines) < first:
            raise InvalidFragmentError(
                f"PLY ASCII data is truncated: {first} element lines expected before the "
                f"vertices, found {len(newlines)}"
            )
        start = int(newlines[first - 1]) + 1 if first > 0 else 0
        # A last vertex line without its newline runs to the end of the data.
        stop = int(newlines[last - 1]) + 1 if 0 < last <= len(newlines) else len(body)
        block = body[start:stop] if vertex.count else b""
    table = parse_ascii_block(block, vertex.count, len(vertex.props), "PLY")
    return table_xyz(table, columns)


def read_ply_xyz(data: bytes, max_points: int) -> FloatArray:
    """Decode the vertex coordinates of a PLY file.

    Parameters
    ----------
    data : bytes
        The whole file, starting with ``ply``.
    max_points : int
        Largest accepted vertex count, checked before any allocation.

    Returns
    -------
    ndarray
        ``(N, 3)`` float64 C-contiguous, fragment-local, meters; may contain non-finite rows.

    Raises
    ------
    InvalidFragmentError
        Malformed or inconsistent header, truncated body, no x/y/z.
    FragmentTooLargeError
        More vertices declared than ``max_points``.
    """
    header = _parse_header(data)
    index = _find_vertex(header, max_points)
    if header.order:
        return _read_binary(data, header, index)
    return _read_ascii(data, header, index)
