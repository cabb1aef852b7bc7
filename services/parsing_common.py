"""Helpers shared by the PLY and PCD readers: count checks, ASCII numbers, column extraction.

Everything here works on whole blocks with numpy; nothing loops over points.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from services.errors import FragmentTooLargeError, InvalidFragmentError
from services.types import FloatArray

__all__ = [
    "check_point_count",
    "parse_ascii_block",
    "read_binary_records",
    "records_xyz",
    "table_xyz",
]


def check_point_count(count: int, max_points: int, fmt: str) -> None:
    """Reject a declared point count before anything is allocated for it.

    Parameters
    ----------
    count : int
        Number of points the header declares.
    max_points : int
        Largest accepted count (``ParserLimits.max_points``).
    fmt : str
        Format name for the message (``"PLY"`` or ``"PCD"``).

    Raises
    ------
    InvalidFragmentError
        The count is negative.
    FragmentTooLargeError
        The count exceeds ``max_points``.
    """
    if count < 0:
        raise InvalidFragmentError(f"{fmt} header declares a negative point count ({count})")
    if count > max_points:
        raise FragmentTooLargeError(
            f"{fmt} header declares {count} points, more than the maximum of {max_points}"
        )


def parse_ascii_block(text: bytes, n_rows: int, n_cols: int, fmt: str) -> FloatArray:
    r"""Parse whitespace-separated numbers into an ``(n_rows, n_cols)`` float64 table.

    Parameters
    ----------
    text : bytes
        The data lines (any whitespace, including ``\r\n``, separates values).
    n_rows, n_cols : int
        Shape the header declares.
    fmt : str
        Format name for messages.

    Returns
    -------
    ndarray
        ``(n_rows, n_cols)`` float64; ``nan``/``inf`` tokens are kept as such.

    Raises
    ------
    InvalidFragmentError
        A token is not a number, or the number of values differs from the declared shape
        (fewer: truncated body; more: inconsistent header).
    """
    expected = n_rows * n_cols
    if not text or text.isspace():
        # np.fromstring returns [-1.] for whitespace-only input instead of an empty array.
        values: FloatArray = np.empty(0, dtype=np.float64)
    else:
        try:
            with warnings.catch_warnings():
                # numpy < 2.3 only warns (DeprecationWarning) on unparsable data.
                warnings.simplefilter("error", DeprecationWarning)
                values = np.fromstring(text, dtype=np.float64, sep=" ")
        except (ValueError, DeprecationWarning) as exc:
            raise InvalidFragmentError(f"{fmt} ASCII data contains a non-numeric value") from exc
    if values.size < expected:
        raise InvalidFragmentError(
            f"{fmt} ASCII data is truncated: header declares {n_rows} points x {n_cols} "
            f"values = {expected} values, found {values.size}"
        )
    if values.size > expected:
        raise InvalidFragmentError(
            f"{fmt} header inconsistent with data: declares {expected} values "
            f"({n_rows} points x {n_cols}), found {values.size}"
        )
    return values.reshape(n_rows, n_cols)


def read_binary_records(
    data: bytes, offset: int, dtype: np.dtype[np.void], count: int, fmt: str
) -> NDArray[np.void]:
    """View ``count`` packed records of ``dtype`` starting at ``offset`` (no copy).

    Raises
    ------
    InvalidFragmentError
        Fewer bytes than the records need (truncated body).
    """
    need = count * dtype.itemsize
    available = len(data) - offset
    if available < need:
        raise InvalidFragmentError(
            f"{fmt} binary data is truncated: header declares {count} points "
            f"({need} bytes), only {max(available, 0)} bytes present"
        )
    return np.frombuffer(data, dtype=dtype, count=count, offset=offset)


def records_xyz(records: NDArray[np.void], fields: Sequence[str]) -> FloatArray:
    """Copy three fields of a structured array into an ``(N, 3)`` float64 C-contiguous array.

    Byte order and width (float, double, integer) are converted by numpy during the copy.
    """
    out = np.empty((len(records), 3), dtype=np.float64)
    for j, name in enumerate(fields):
        out[:, j] = records[name]
    return out


def table_xyz(table: FloatArray, columns: Sequence[int]) -> FloatArray:
    """Take three columns of an ``(N, K)`` table as an ``(N, 3)`` float64 C-contiguous array."""
    return np.ascontiguousarray(table[:, list(columns)], dtype=np.float64)
