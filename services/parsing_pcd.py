"""PCD reader (DATA ascii and binary) that extracts x, y, z from bytes.

binary_compressed (LZF) is rejected: decoding it is inherently sequential and not worth a
pure-Python implementation here.
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

__all__ = ["read_pcd_xyz"]

# PCD TYPE letter -> numpy kind, and the SIZEs each accepts.
_KINDS = {"I": ("i", (1, 2, 4, 8)), "U": ("u", (1, 2, 4, 8)), "F": ("f", (4, 8))}
_XYZ = ("x", "y", "z")
_MAX_HEADER_LINES = 256  # a real header has ~11 lines; stops runaway scans of binary junk


@dataclass(frozen=True)
class _Header:
    fields: list[str]
    codes: list[str]  # numpy code per field, little-endian
    counts: list[int]
    n_points: int
    data: str
    body_offset: int


def _read_lines(data: bytes) -> tuple[dict[str, list[str]], int]:
    """Collect ``KEY values...`` lines up to ``DATA``; return them and the body offset."""
    entries: dict[str, list[str]] = {}
    pos = 0
    for _ in range(_MAX_HEADER_LINES):
        if pos >= len(data):
            break
        end = data.find(b"\n", pos)
        end = len(data) if end < 0 else end
        # latin-1 never fails to decode; only ASCII keywords matter in the header.
        tokens = data[pos:end].decode("latin-1").split()
        pos = end + 1
        if not tokens or tokens[0].startswith("#"):
            continue
        entries[tokens[0].upper()] = tokens[1:]
        if tokens[0].upper() == "DATA":
            return entries, min(pos, len(data))
    raise InvalidFragmentError("PCD header has no DATA line")


def _ints(entries: dict[str, list[str]], key: str, default: list[int] | None = None) -> list[int]:
    if key not in entries:
        if default is None:
            raise InvalidFragmentError(f"PCD header has no {key} line")
        return default
    try:
        return [int(v) for v in entries[key]]
    except ValueError:
        raise InvalidFragmentError(f"PCD header has a non-integer {key} value") from None


def _field_codes(sizes: list[int], types: list[str]) -> list[str]:
    codes = []
    for size, letter in zip(sizes, types, strict=True):
        kind, allowed = _KINDS.get(letter.upper(), ("", ()))
        if size not in allowed:
            raise InvalidFragmentError(f"PCD header uses unknown field type {letter} {size}")
        codes.append(f"<{kind}{size}")
    return codes


def _point_count(entries: dict[str, list[str]]) -> int:
    declared = _ints(entries, "POINTS", [-1])
    shape = _ints(entries, "WIDTH", [-1]) + _ints(entries, "HEIGHT", [1])
    if len(declared) != 1 or len(shape) != 2:
        raise InvalidFragmentError("PCD header has a malformed POINTS/WIDTH/HEIGHT line")
    if shape[0] >= 0 and declared[0] >= 0 and shape[0] * shape[1] != declared[0]:
        raise InvalidFragmentError(
            f"PCD header inconsistent: WIDTH x HEIGHT = {shape[0] * shape[1]} "
            f"but POINTS = {declared[0]}"
        )
    if declared[0] >= 0:
        return declared[0]
    if shape[0] >= 0:
        return shape[0] * shape[1]
    raise InvalidFragmentError("PCD header has neither POINTS nor WIDTH")


def _parse_header(data: bytes, max_points: int) -> _Header:
    entries, body_offset = _read_lines(data)
    fields = entries.get("FIELDS", [])
    if not fields:
        raise InvalidFragmentError("PCD header has no FIELDS line")
    sizes = _ints(entries, "SIZE")
    types = entries.get("TYPE", [])
    counts = _ints(entries, "COUNT", [1] * len(fields))
    if not len(fields) == len(sizes) == len(types) == len(counts):
        raise InvalidFragmentError(
            "PCD header inconsistent: FIELDS, SIZE, TYPE and COUNT differ in length"
        )
    if any(c < 1 for c in counts):
        raise InvalidFragmentError("PCD header has a COUNT below 1")
    n_points = _point_count(entries)
    check_point_count(n_points, max_points, "PCD")
    mode = entries["DATA"][0].lower() if entries["DATA"] else ""
    if mode == "binary_compressed":
        raise InvalidFragmentError("PCD DATA binary_compressed is not supported")
    if mode not in ("ascii", "binary"):
        raise InvalidFragmentError(f"PCD header has an unknown DATA type {mode!r}")
    return _Header(fields, _field_codes(sizes, types), counts, n_points, mode, body_offset)


def _xyz_fields(header: _Header) -> list[int]:
    missing = [axis for axis in _XYZ if axis not in header.fields]
    if missing:
        raise InvalidFragmentError(f"PCD header lacks x/y/z fields (missing {', '.join(missing)})")
    indices = [header.fields.index(axis) for axis in _XYZ]
    if any(header.counts[i] != 1 for i in indices):
        raise InvalidFragmentError("PCD x/y/z fields must have COUNT 1")
    return indices


def _read_binary(data: bytes, header: _Header, xyz: list[int]) -> FloatArray:
    # Positional field names: PCD allows repeated names such as the "_" padding field.
    dtype: np.dtype[np.void] = np.dtype(
        {
            "names": [f"f{i}" for i in range(len(header.fields))],
            "formats": [
                code if count == 1 else (code, (count,))
                for code, count in zip(header.codes, header.counts, strict=True)
            ],
        }
    )
    records = read_binary_records(data, header.body_offset, dtype, header.n_points, "PCD")
    trailing = len(data) - header.body_offset - records.nbytes
    if trailing:
        raise InvalidFragmentError(
            f"PCD header inconsistent with size: {trailing} unexpected bytes after "
            f"{header.n_points} points"
        )
    return records_xyz(records, [f"f{i}" for i in xyz])


def _read_ascii(data: bytes, header: _Header, xyz: list[int]) -> FloatArray:
    # Values of a field with COUNT > 1 occupy consecutive columns.
    starts = np.concatenate([[0], np.cumsum(header.counts)[:-1]])
    table = parse_ascii_block(
        data[header.body_offset :], header.n_points, sum(header.counts), "PCD"
    )
    return table_xyz(table, [int(starts[i]) for i in xyz])


def read_pcd_xyz(data: bytes, max_points: int) -> FloatArray:
    """Decode the x, y, z fields of a PCD file.

    Parameters
    ----------
    data : bytes
        The whole file (header starting with ``# .PCD``, ``VERSION`` or ``FIELDS``).
    max_points : int
        Largest accepted point count, checked before any allocation.

    Returns
    -------
    ndarray
        ``(N, 3)`` float64 C-contiguous, fragment-local, meters; may contain non-finite rows
        (organized clouds mark missing returns with NaN).

    Raises
    ------
    InvalidFragmentError
        Malformed or inconsistent header, truncated body, no x/y/z, binary_compressed data.
    FragmentTooLargeError
        More points declared than ``max_points``.
    """
    header = _parse_header(data, max_points)
    xyz = _xyz_fields(header)
    if header.data == "binary":
        return _read_binary(data, header, xyz)
    return _read_ascii(data, header, xyz)
