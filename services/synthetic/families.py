"""Families of random room shapes: carved grids, long thin rooms, L, T, U, combs, notches.

Every shape is a simple counter-clockwise rectilinear polygon, world frame (x, y meters),
bounding-box minimum at (0, 0), first vertex random, no edge shorter than ``min_edge``. The
families other than "carved" are made of grid cells (:func:`~services.synthetic.room.grid_outline`)
and then turned by a random quarter turn.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import numpy as np
from numpy.typing import NDArray

from services.synthetic.room import grid_lines, grid_outline, random_rectilinear_polygon
from services.types import FloatArray

__all__ = ["FAMILIES", "family_corners", "pick_family", "random_room"]

BoolArray = NDArray[np.bool_]
_Grid = tuple[FloatArray, FloatArray, BoolArray]  # x lines (nx + 1,), y lines, (nx, ny) cells

FAMILIES = ("carved", "thin", "L", "T", "U", "comb", "notched")
_CORNERS = {
    "carved": tuple(range(4, 17, 2)),
    "thin": (4,),
    "L": (6,),
    "T": (8,),
    "U": (8,),
    "comb": (8, 12, 16),  # 2, 3 or 4 teeth
    "notched": (8, 12, 16),  # 1, 2 or 3 notches in the middle of walls
}


def family_corners(family: str, n_corners_range: tuple[int, int]) -> tuple[int, ...]:
    """The corner counts a family can make within ``n_corners_range`` (inclusive)."""
    lo, hi = n_corners_range
    return tuple(n for n in _CORNERS[family] if lo <= n <= hi)


def pick_family(rng: np.random.Generator, n_corners_range: tuple[int, int]) -> str:
    """One family drawn uniformly among those that fit ``n_corners_range``."""
    fitting = [f for f in FAMILIES if family_corners(f, n_corners_range)]
    return fitting[int(rng.integers(len(fitting)))]


def random_room(
    rng: np.random.Generator,
    family: str,
    size: tuple[float, float],
    n_corners_range: tuple[int, int],
    min_edge: float,
) -> FloatArray:
    """A random room of one family.

    Parameters
    ----------
    family : str
        One of :data:`FAMILIES`.
    size : (float, float)
        Bounding box (x, y), meters; "thin" keeps only the longer side and makes the other 3 to
        6 times shorter (at least 1.5 m); the other grid families may swap the axes.
    n_corners_range : (int, int)
        Allowed corner counts (inclusive); must fit the family (:func:`family_corners`).
    min_edge : float
        Shortest edge, meters.

    Returns
    -------
    (V, 2) float64
        World frame, counter-clockwise, bounding-box minimum at (0, 0), first vertex random.
    """
    corners = family_corners(family, n_corners_range)
    if not corners:
        raise ValueError(f"a {family!r} room cannot have {n_corners_range} corners")
    target = int(rng.choice(corners))
    if family == "carved":
        return random_rectilinear_polygon(rng, size, target, min_edge)
    xs, ys, occupied = _GRIDS[family](rng, size, target, min_edge)
    loop = grid_outline(occupied)
    assert loop is not None and len(loop) == target
    polygon = np.array([[xs[i], ys[j]] for i, j in loop])
    quarter = int(rng.integers(4))
    turn = np.linalg.matrix_power(np.array([[0.0, -1.0], [1.0, 0.0]]), quarter)
    polygon = polygon @ turn.T
    polygon -= polygon.min(axis=0)
    return np.roll(polygon, -int(rng.integers(len(polygon))), axis=0)


def _thin(
    rng: np.random.Generator, size: tuple[float, float], target: int, min_edge: float
) -> _Grid:
    """A rectangle 3 to 6 times longer than wide (a corridor, a gallery)."""
    long = max(size)
    short = round(max(long / float(rng.uniform(3.0, 6.0)), 1.5, min_edge), 2)
    return np.array([0.0, long]), np.array([0.0, short]), np.ones((1, 1), dtype=bool)


def _l_shape(
    rng: np.random.Generator, size: tuple[float, float], target: int, min_edge: float
) -> _Grid:
    """A 2 x 2 grid without one corner cell."""
    xs, ys = _lines(rng, size, (2, 2), min_edge)
    occupied = np.ones((2, 2), dtype=bool)
    occupied[int(rng.integers(2)), int(rng.integers(2))] = False
    return xs, ys, occupied


def _fixed(
    occupied: BoolArray,
    rng: np.random.Generator,
    size: tuple[float, float],
    target: int,
    min_edge: float,
) -> _Grid:
    """A fixed pattern of occupied cells on random grid lines."""
    xs, ys = _lines(rng, size, (occupied.shape[0], occupied.shape[1]), min_edge)
    return xs, ys, occupied.copy()


# occupied[i, j]: cell i along x, j along y. T: a bar across the top (row 1) on a stem (the
# middle cell of row 0). U: a 3 x 2 grid without its top middle cell.
_T_CELLS = np.array([[False, True], [True, True], [False, True]])
_U_CELLS = np.array([[True, True], [True, False], [True, True]])


def _comb(
    rng: np.random.Generator, size: tuple[float, float], target: int, min_edge: float
) -> _Grid:
    """``target`` / 4 teeth on a base: row 0 full, row 1 only in the even columns."""
    teeth = target // 4
    long, short = max(size), min(size)
    xs, ys = _lines(rng, (long, short), (2 * teeth - 1, 2), min_edge)
    occupied = np.ones((2 * teeth - 1, 2), dtype=bool)
    occupied[1::2, 1] = False
    return xs, ys, occupied


def _notched(
    rng: np.random.Generator, size: tuple[float, float], target: int, min_edge: float
) -> _Grid:
    """A rectangle with (target - 4) / 4 notches in the middle of distinct walls.

    A 5 x 5 grid whose outer ring is thin (0.8 to 1.5 m, the notch depth); a notch removes the
    middle cell of one side."""
    xs = _notch_lines(rng, size[0], min_edge)
    ys = _notch_lines(rng, size[1], min_edge)
    occupied = np.ones((5, 5), dtype=bool)
    sides = np.array([[2, 0], [4, 2], [2, 4], [0, 2]])
    for i, j in sides[rng.permutation(4)[: (target - 4) // 4]]:
        occupied[i, j] = False
    return xs, ys, occupied


def _notch_lines(rng: np.random.Generator, length: float, min_edge: float) -> FloatArray:
    """(6,) grid lines: thin outer cells (the notch depth) around three random middle cells;
    a side too short for five cells is lengthened to the shortest that fits."""
    cell = min_edge + 0.02
    length = max(length, 5 * cell + 0.01)
    high = max(min(1.5, (length - 3 * cell) / 2.0), cell)
    a, b = np.round(rng.uniform(cell, high, 2), 2)
    middle = a + grid_lines(rng, float(length - a - b), 3, min_edge)
    return np.concatenate([[0.0], middle, [length]])


def _lines(
    rng: np.random.Generator, size: tuple[float, float], cells: tuple[int, int], min_edge: float
) -> tuple[FloatArray, FloatArray]:
    """Random grid lines over ``size`` with ``cells`` cells; a side too short for its cells
    is lengthened to the shortest that fits."""
    need = [n * (min_edge + 0.02) + 0.01 for n in cells]
    x, y = (max(s, n) for s, n in zip(size, need, strict=True))
    return grid_lines(rng, x, cells[0], min_edge), grid_lines(rng, y, cells[1], min_edge)


_GRIDS: dict[str, Callable[[np.random.Generator, tuple[float, float], int, float], _Grid]] = {
    "thin": _thin,
    "L": _l_shape,
    "T": partial(_fixed, _T_CELLS),
    "U": partial(_fixed, _U_CELLS),
    "comb": _comb,
    "notched": _notched,
}
