"""Decode a fragment file (PLY or PCD) from its bytes into finite local points.

Pure numpy, no temporary files: open3d cannot parse from memory, and uploads arrive as bytes.
The format readers live in :mod:`services.parsing_ply` and :mod:`services.parsing_pcd`.
"""

from __future__ import annotations

import numpy as np

from schemas.params import ParserLimits
from services.errors import InvalidFragmentError, UnsupportedFormatError
from services.parsing_pcd import read_pcd_xyz
from services.parsing_ply import read_ply_xyz
from services.types import FloatArray, ParsedFragment

__all__ = ["detect_format", "parse_fragment"]

_PLY_MAGIC = (b"ply\n", b"ply\r\n")
_PCD_MAGIC = (b"# .PCD", b"VERSION", b"FIELDS")


def detect_format(data: bytes) -> str:
    r"""Name the point-cloud format of ``data`` from its first bytes.

    Parameters
    ----------
    data : bytes
        A whole file.

    Returns
    -------
    str
        ``"ply"`` or ``"pcd"``.

    Raises
    ------
    UnsupportedFormatError
        Empty, or neither PLY nor PCD.

    Examples
    --------
    >>> detect_format(b"ply\nformat ascii 1.0\n")
    'ply'
    >>> detect_format(b"# .PCD v0.7\n")
    'pcd'
    """
    if not data:
        raise UnsupportedFormatError("empty fragment: no bytes")
    if data.startswith(_PLY_MAGIC):
        return "ply"
    if data.startswith(_PCD_MAGIC):
        return "pcd"
    raise UnsupportedFormatError(
        f"unsupported format: not PLY or PCD (starts with {bytes(data[:8])!r})"
    )


def _keep_finite(xyz: FloatArray, fmt: str, limits: ParserLimits) -> ParsedFragment:
    finite = np.isfinite(xyz).all(axis=1)
    kept = int(np.count_nonzero(finite))
    dropped = len(xyz) - kept
    if kept < limits.min_points:
        raise InvalidFragmentError(
            f"too few finite points: {kept} (of {len(xyz)}, {dropped} non-finite dropped), "
            f"fewer than the minimum of {limits.min_points}"
        )
    points = xyz if dropped == 0 else xyz[finite]
    return ParsedFragment(np.ascontiguousarray(points, dtype=np.float64), fmt, dropped)


def parse_fragment(data: bytes, limits: ParserLimits = ParserLimits()) -> ParsedFragment:
    """Decode a PLY or PCD fragment from bytes.

    Parameters
    ----------
    data : bytes
        The whole file. PLY: ascii, binary_little_endian or binary_big_endian, any vertex
        property types, other elements allowed. PCD: DATA ascii or binary.
    limits : ParserLimits
        ``max_points`` bounds the declared count (checked before allocating);
        ``min_points`` bounds the number of finite points.

    Returns
    -------
    ParsedFragment
        ``points``: (N, 3) float64 C-contiguous, fragment-local, meters, all finite;
        ``format``: ``"ply"`` or ``"pcd"``; ``dropped_nonfinite``: rows with NaN/inf removed.

    Raises
    ------
    UnsupportedFormatError
        Empty bytes, or neither PLY nor PCD.
    InvalidFragmentError
        Malformed or inconsistent header, truncated body, no x/y/z, unsupported encoding,
        fewer finite points than ``limits.min_points``.
    FragmentTooLargeError
        More points declared than ``limits.max_points``.

    Examples
    --------
    >>> from services.point_io import encode_ply
    >>> pts = np.arange(12.0).reshape(4, 3)
    >>> parse_fragment(encode_ply(pts), ParserLimits(min_points=1)).points.shape
    (4, 3)
    """
    fmt = detect_format(data)
    reader = read_ply_xyz if fmt == "ply" else read_pcd_xyz
    try:
        xyz = reader(data, limits.max_points)
    except (ValueError, TypeError, IndexError, OverflowError, UnicodeDecodeError) as exc:
        # Safety net: malformed input must surface as a fragment error, never a raw one.
        raise InvalidFragmentError(f"malformed {fmt.upper()} file: {exc}") from exc
    return _keep_finite(xyz, fmt, limits)
