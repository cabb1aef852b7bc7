"""Encode points as PLY or PCD bytes: the inverse of :mod:`services.parsing`.

Used by the scene generator, the CLI and tests. Pure: returns bytes, writes no file.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from services.types import FloatArray

__all__ = ["encode_pcd", "encode_ply"]

# numpy dtype -> PLY type name (classic names, understood by every reader).
_PLY_NAMES = {
    np.dtype("i1"): "char",
    np.dtype("u1"): "uchar",
    np.dtype("i2"): "short",
    np.dtype("u2"): "ushort",
    np.dtype("i4"): "int",
    np.dtype("u4"): "uint",
    np.dtype("f4"): "float",
    np.dtype("f8"): "double",
}
_PCD_TYPES = {"i": "I", "u": "U", "f": "F"}

Column = tuple[str, NDArray[np.generic]]


def _as_points(points: ArrayLike) -> FloatArray:
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {pts.shape}")
    return pts


def _columns(
    pts: FloatArray, dtype: np.dtype[np.floating], extra: Mapping[str, ArrayLike] | None
) -> list[Column]:
    columns: list[Column] = [(axis, pts[:, j].astype(dtype)) for j, axis in enumerate("xyz")]
    for name, values in (extra or {}).items():
        arr = np.asarray(values)
        if name in ("x", "y", "z") or not name or any(c.isspace() for c in name):
            raise ValueError(f"invalid extra property name {name!r}")
        if arr.shape != (len(pts),):
            raise ValueError(f"extra property {name!r} must have shape ({len(pts)},)")
        columns.append((name, arr.astype(arr.dtype.newbyteorder("="))))
    return columns


def _binary_body(columns: list[Column], order: str) -> bytes:
    dtype = np.dtype([(f"f{i}", order + col.dtype.str[1:]) for i, (_, col) in enumerate(columns)])
    records = np.empty(len(columns[0][1]), dtype=dtype)
    for i, (_, col) in enumerate(columns):
        records[f"f{i}"] = col
    return records.tobytes()


def _ascii_body(columns: list[Column]) -> bytes:
    # Shortest round-trip precision per type; one C-level % over all values, no row loop.
    formats = {"f4": "%.9g", "f8": "%.17g"}
    row = " ".join(formats.get(col.dtype.str[1:], "%d") for _, col in columns) + "\n"
    table = np.column_stack([col.astype(np.float64) for _, col in columns])
    return ((row * len(table)) % tuple(table.ravel().tolist())).encode("ascii")


def encode_ply(
    points: ArrayLike,
    *,
    binary: bool = True,
    big_endian: bool = False,
    double: bool = False,
    extra_properties: Mapping[str, ArrayLike] | None = None,
) -> bytes:
    """Encode points as a PLY file with one vertex element.

    Parameters
    ----------
    points : array_like
        (N, 3) coordinates, meters.
    binary : bool
        Binary body (default) or ASCII.
    big_endian : bool
        With ``binary``: ``binary_big_endian`` instead of ``binary_little_endian``.
    double : bool
        Store x, y, z as double instead of float.
    extra_properties : mapping of str to array_like, optional
        More vertex properties after x, y, z, each (N,) of int8/16/32, uint8/16/32,
        float32 or float64 (e.g. ``{"red": uint8_array, "nx": float32_array}``).

    Returns
    -------
    bytes
        The file contents.

    Raises
    ------
    ValueError
        Bad point shape, or an extra property with a bad name, shape or dtype.

    Examples
    --------
    >>> encode_ply([[0.0, 1.0, 2.0]], binary=False).decode().splitlines()[-1]
    '0 1 2'
    """
    pts = _as_points(points)
    columns = _columns(pts, np.dtype("f8" if double else "f4"), extra_properties)
    types = []
    for name, col in columns:
        if col.dtype not in _PLY_NAMES:
            raise ValueError(f"property {name!r} has dtype {col.dtype}, not a PLY type")
        types.append(f"property {_PLY_NAMES[col.dtype]} {name}")
    encoding = "ascii"
    if binary:
        encoding = "binary_big_endian" if big_endian else "binary_little_endian"
    lines = ["ply", f"format {encoding} 1.0", "comment floorplan-jigsaw"]
    header = "\n".join([*lines, f"element vertex {len(pts)}", *types, "end_header", ""])
    body = _binary_body(columns, ">" if big_endian else "<") if binary else _ascii_body(columns)
    return header.encode("ascii") + body


def encode_pcd(
    points: ArrayLike,
    *,
    binary: bool = True,
    extra_fields: Mapping[str, ArrayLike] | None = None,
    height: int = 1,
) -> bytes:
    """Encode points as a PCD v0.7 file with float32 x, y, z.

    Parameters
    ----------
    points : array_like
        (N, 3) coordinates, meters; NaN rows are kept (organized clouds).
    binary : bool
        ``DATA binary`` (little-endian, default) or ``DATA ascii``.
    extra_fields : mapping of str to array_like, optional
        More fields after x, y, z, each (N,) of a signed/unsigned integer or float dtype
        (e.g. ``{"rgb": uint32_array}``).
    height : int
        HEIGHT of an organized cloud; N must be a multiple of it (WIDTH = N / HEIGHT).

    Returns
    -------
    bytes
        The file contents.

    Raises
    ------
    ValueError
        Bad point shape or height, or an extra field with a bad name, shape or dtype.

    Examples
    --------
    >>> encode_pcd([[0.0, 1.0, 2.0]], binary=False).decode().splitlines()[-1]
    '0 1 2'
    """
    pts = _as_points(points)
    if height < 1 or len(pts) % height:
        raise ValueError(f"height {height} does not divide the {len(pts)} points")
    columns = _columns(pts, np.dtype("f4"), extra_fields)
    for name, col in columns:
        if col.dtype.kind not in _PCD_TYPES or col.dtype == np.dtype("f2"):
            raise ValueError(f"field {name!r} has dtype {col.dtype}, not a PCD type")
    header = "\n".join(
        [
            "# .PCD v0.7 - Point Cloud Data file format",
            "VERSION 0.7",
            "FIELDS " + " ".join(name for name, _ in columns),
            "SIZE " + " ".join(str(col.dtype.itemsize) for _, col in columns),
            "TYPE " + " ".join(_PCD_TYPES[col.dtype.kind] for _, col in columns),
            "COUNT " + " ".join("1" for _ in columns),
            f"WIDTH {len(pts) // height}",
            f"HEIGHT {height}",
            "VIEWPOINT 0 0 0 1 0 0 0",
            f"POINTS {len(pts)}",
            f"DATA {'binary' if binary else 'ascii'}",
            "",
        ]
    )
    body = _binary_body(columns, "<") if binary else _ascii_body(columns)
    return header.encode("ascii") + body
