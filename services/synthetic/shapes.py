"""Clean near-Manhattan room outlines into rectilinear polygons the generator can use.

An outline drawn by hand or annotated on real scans is close to Manhattan but not exactly:
walls a few degrees off, jogs of a few centimeters, duplicate or collinear vertices, either
winding. :func:`clean_outline` turns it into a simple, counter-clockwise, axis-aligned polygon
(:meth:`services.synthetic.room.Room.from_polygon` takes it as is) or rejects it.

Pure: arrays in, arrays out, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from services.geometry import cross, signed_area
from services.types import FloatArray

__all__ = ["OutlineLimits", "clean_outline", "dominant_angle", "is_simple_rectilinear"]

BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class OutlineLimits:
    """What a cleaned outline must satisfy (meters, square meters, degrees).

    min_edge: shorter edges are removed by snapping their two neighbours onto one line.
    max_off_axis_deg, max_off_axis_share: an outline is not Manhattan when more than this
    share of its perimeter lies on edges more than this many degrees off both axes.
    min_area, min_side: smallest area and smallest bounding-box side.
    min_corners, max_corners: corner count after cleaning.
    """

    min_edge: float = 0.3
    max_off_axis_deg: float = 10.0
    max_off_axis_share: float = 0.1
    min_area: float = 4.0
    min_side: float = 1.5
    min_corners: int = 4
    max_corners: int = 16


def clean_outline(outline: FloatArray, limits: OutlineLimits | None = None) -> FloatArray | None:
    """A near-Manhattan outline as a clean rectilinear polygon, or None when it is unusable.

    Steps: drop repeated vertices, make the winding counter-clockwise, rotate by minus the
    :func:`dominant_angle` (about the origin), snap every edge to the nearer axis (one line
    per run of edges along one axis, at their length-weighted mean), remove edges shorter than
    ``limits.min_edge`` by merging their neighbours, then check the limits.

    Parameters
    ----------
    outline : (V, 2) float64
        Vertices in order, either winding, meters; the first vertex may be repeated at the end.
    limits : OutlineLimits, optional
        Acceptance limits; the defaults when None.

    Returns
    -------
    (K, 2) float64 or None
        Counter-clockwise, only axis-aligned edges, no collinear or repeated vertices,
        ``min_corners <= K <= max_corners``, bounding-box minimum at the origin (the frame is
        the input's, rotated by the dominant angle and shifted). None when the outline is not
        close to Manhattan, not simple, too small, or outside the corner limits.

    Examples
    --------
    >>> square = np.array([[0.0, 0.0], [0.0, 3.0], [3.0, 3.0], [3.0, 0.0]])  # clockwise
    >>> clean_outline(square).tolist()
    [[0.0, 0.0], [3.0, 0.0], [3.0, 3.0], [0.0, 3.0]]
    >>> clean_outline(np.zeros((0, 2))) is None
    True
    """
    limits = limits or OutlineLimits()
    points = _distinct_vertices(np.asarray(outline, dtype=np.float64).reshape(-1, 2))
    if len(points) < 4 or not np.all(np.isfinite(points)) or signed_area(points) == 0.0:
        return None
    if signed_area(points) < 0.0:
        points = points[::-1]
    points = points @ _rotation(-dominant_angle(points)).T
    if _off_axis_share(points, limits.max_off_axis_deg) > limits.max_off_axis_share:
        return None
    snapped = _snap_runs(points, limits.min_edge)
    if snapped is None or not _acceptable(snapped, limits):
        return None
    return _start_at_lowest(snapped - snapped.min(axis=0))


def dominant_angle(polygon: FloatArray) -> float:
    """The wall axis of a closed (V, 2) polygon: edge-length-weighted mean angle modulo 90 deg.

    Returns radians in (-pi/4, pi/4]; rotating by minus it brings the walls closest to x and y.

    >>> round(math.degrees(dominant_angle(np.array([[0, 0], [2, 1], [1, 3], [-1, 2.0]]))), 3)
    26.565
    """
    delta = np.roll(polygon, -1, axis=0) - polygon
    lengths = np.linalg.norm(delta, axis=1)
    four = 4.0 * np.arctan2(delta[:, 1], delta[:, 0])
    angle = 0.25 * math.atan2(float(lengths @ np.sin(four)), float(lengths @ np.cos(four)))
    return angle if angle > -math.pi / 4 else angle + math.pi / 2


def is_simple_rectilinear(polygon: FloatArray) -> bool:
    """True for a (V, 2) polygon, V >= 4, whose edges are axis-aligned, non-zero, turn at
    every vertex and touch only their two neighbours (at the shared vertex)."""
    n = len(polygon)
    if n < 4:
        return False
    delta = np.roll(polygon, -1, axis=0) - polygon
    following = np.roll(delta, -1, axis=0)
    axis_aligned = (delta[:, 0] == 0.0) ^ (delta[:, 1] == 0.0)
    turns = cross(delta, following) != 0.0
    if not (axis_aligned.all() and turns.all()):
        return False
    lo = np.minimum(polygon, np.roll(polygon, -1, axis=0))
    hi = np.maximum(polygon, np.roll(polygon, -1, axis=0))
    touching = np.all((lo[:, None] <= hi[None]) & (lo[None] <= hi[:, None]), axis=2)
    gap = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    return not np.any(touching & (gap > 1) & (gap < n - 1))


def _distinct_vertices(points: FloatArray) -> FloatArray:
    """Drop vertices equal (within 1 mm) to their predecessor, the closing one included."""
    if len(points) == 0:
        return points
    step = np.linalg.norm(points - np.roll(points, 1, axis=0), axis=1)
    kept: FloatArray = points[step > 1e-3]
    return kept


def _rotation(angle: float) -> FloatArray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def _off_axis_share(polygon: FloatArray, max_deg: float) -> float:
    """Share of the perimeter on edges more than ``max_deg`` degrees from both axes."""
    delta = np.roll(polygon, -1, axis=0) - polygon
    lengths = np.linalg.norm(delta, axis=1)
    angle = np.degrees(np.arctan2(np.abs(delta[:, 1]), np.abs(delta[:, 0])))  # [0, 90]
    off = np.minimum(angle, 90.0 - angle) > max_deg
    return float(lengths[off].sum() / lengths.sum())


def _snap_runs(polygon: FloatArray, min_edge: float) -> FloatArray | None:
    """Axis-aligned polygon from runs of edges along one axis; short edges merged away.

    Returns (K, 2) with K even, or None when fewer than four runs remain.
    """
    delta = np.roll(polygon, -1, axis=0) - polygon
    horizontal = np.abs(delta[:, 0]) >= np.abs(delta[:, 1])
    starts = np.flatnonzero(horizontal != np.roll(horizontal, 1))
    if len(starts) < 4:
        return None
    # Runs: maximal cyclic sequences of edges along one axis, starting at a change of axis.
    run_of_edge = (np.searchsorted(starts, np.arange(len(polygon)), side="right") - 1) % len(starts)
    lengths = np.linalg.norm(delta, axis=1)
    middle = polygon + 0.5 * delta
    across = np.where(horizontal, middle[:, 1], middle[:, 0])  # the coordinate a run fixes
    weight = np.bincount(run_of_edge, lengths, len(starts))
    levels = np.bincount(run_of_edge, lengths * across, len(starts)) / weight
    runs = _merge_short_runs(levels, horizontal[starts], min_edge)
    return None if runs is None else _corners(*runs)


def _merge_short_runs(
    levels: FloatArray, horizontal: BoolArray, min_edge: float
) -> tuple[FloatArray, BoolArray] | None:
    """Remove the shortest run while it is shorter than ``min_edge``.

    ``levels`` (R,) are the coordinates the runs fix (y of a horizontal run, x of a vertical
    one), ``horizontal`` (R,) their axes, alternating; run k spans from run k-1's level to run
    k+1's. Removing run k puts runs k-1 and k+1 (parallel) on one line, their length-weighted
    mean, and joins them. Returns the remaining (levels, horizontal), four runs or more, or
    None.
    """
    while len(levels) >= 4:
        lengths = np.abs(np.roll(levels, -1) - np.roll(levels, 1))
        k = int(np.argmin(lengths))
        if lengths[k] >= min_edge:
            return levels, horizontal
        if len(levels) == 4:
            return None
        before, after = (k - 1) % len(levels), (k + 1) % len(levels)
        w = lengths[[before, after]]
        pair = levels[[before, after]]
        levels = levels.copy()
        levels[before] = float(pair @ w / w.sum()) if w.sum() > 0.0 else float(pair.mean())
        levels, horizontal = np.delete(levels, [k, after]), np.delete(horizontal, [k, after])
    return None


def _corners(levels: FloatArray, horizontal: BoolArray) -> FloatArray:
    """(R, 2) corners where run k meets run k + 1 (runs alternate axes)."""
    following = np.roll(levels, -1)
    x = np.where(horizontal, following, levels)
    y = np.where(horizontal, levels, following)
    return np.column_stack([x, y])


def _acceptable(polygon: FloatArray, limits: OutlineLimits) -> bool:
    size = polygon.max(axis=0) - polygon.min(axis=0)
    return (
        limits.min_corners <= len(polygon) <= limits.max_corners
        and signed_area(polygon) >= limits.min_area
        and float(size.min()) >= limits.min_side
        and is_simple_rectilinear(polygon)
    )


def _start_at_lowest(polygon: FloatArray) -> FloatArray:
    """Roll the vertices so the first is the lowest, then leftmost (a canonical start)."""
    first = int(np.lexsort((polygon[:, 0], polygon[:, 1]))[0])
    return np.roll(polygon, -first, axis=0)
