"""Frames turned on the spot: telling from two frames' views that they share their camera.

A robot turning on the spot, or a camera on a tripod, takes frames whose views often overlap.
Plain walls give ORB nothing to match (:mod:`services.frame_merge`), yet the overlap still
says something: seen from one point, the same direction meets the same wall at the same
distance. Each single frame keeps its *view ranges*: per half degree of azimuth around its
camera (aligned frame), how far away horizontally the walls stand (:func:`view_ranges`; the
floor and ceiling are left out, since they look alike from anywhere at one height). Two
frames share a station (:func:`shared_turn`) when one quarter turn of the second (give or
take the few degrees a Manhattan frame may be off) puts its ranges onto the first's over an
arc of ``station_view_overlap`` degrees at least, and they agree there almost everywhere
(``station_view_share``, within ``station_view_tolerance`` plus 1 % of the distance).

On the outside frame rooms (``bench.outside``, seeds 7 and 8) 112 of the 131 pairs that
passed share a station and the truth's turn; 18 found another turn (a room that looks alike
turned, as from the middle of a rectangle) and 1 was two stations whose views look alike.
So a pair is only a station for an assembly that turns its two pieces as the pair says
(:func:`services.refinement.refine_translations`, where the walls may still refuse it), and
a merge only when asked (``layout.frame.merge_stations``,
:func:`services.frame_merge.station_groups`: on rooms whose frames overlap by metres it did
no better).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping

import numpy as np

from schemas.params import PlacementParams
from services.types import FloatArray, LocalLayout

__all__ = [
    "BIN",
    "range_towards",
    "shared_turn",
    "station_mates",
    "view_ranges",
    "without_odd_triangles",
]

BIN = math.radians(0.5)  # azimuth bin of the view ranges, radians
_BINS = round(2.0 * math.pi / BIN)
_OVER_FLOOR = 0.3  # m: points this near the floor (its clutter too) are left out
_UNDER_CEILING = 0.15  # m: and this near the ceiling
_MIN_POINTS = 5  # points a bin needs for a range
_FAR_SHARE = 0.8  # a bin's range: this quantile of its distances (the wall behind low clutter)
_YAW_SLACK = 6  # bins (3 degrees) a turn may be off: two frames' Manhattan frames differ so


def view_ranges(
    aligned: FloatArray, centre: FloatArray, floor_z: float, ceiling_z: float | None
) -> FloatArray:
    """(B, 2) per azimuth bin with enough wall points: the bin's centre (radians, in
    [-pi, pi)) and its horizontal range from ``centre`` (m).

    aligned: (N, 3) a frame's points in its aligned frame; centre: (2,) its camera there.

    >>> pts = np.array([[2.0, 0.001 * i, 0.5 + 0.01 * i] for i in range(40)])
    >>> view_ranges(pts, np.zeros(2), 0.0, 2.5).round(3).tolist()
    [[0.004, 2.0], [0.013, 2.0], [0.022, 2.0]]
    """
    up = aligned[:, 2]
    keep = up > floor_z + _OVER_FLOOR
    if ceiling_z is not None:
        keep &= up < ceiling_z - _UNDER_CEILING
    offset = aligned[keep, :2] - centre
    if len(offset) == 0:
        return np.zeros((0, 2))
    azimuth = np.arctan2(offset[:, 1], offset[:, 0])
    distance = np.hypot(offset[:, 0], offset[:, 1])
    bins = np.minimum(np.floor((azimuth + math.pi) / BIN).astype(np.int64), _BINS - 1)
    order = np.lexsort((distance, bins))
    bins, distance = bins[order], distance[order]
    labels, start, count = np.unique(bins, return_index=True, return_counts=True)
    full = count >= _MIN_POINTS
    pick = start[full] + np.floor(_FAR_SHARE * (count[full] - 1)).astype(np.int64)
    centres = (labels[full] + 0.5) * BIN - math.pi
    return np.column_stack([centres, distance[pick]]).astype(np.float64)


def _dense(ranges: FloatArray) -> FloatArray:
    """(_BINS,) the ranges on the full circle, NaN where the view saw no wall."""
    out = np.full(_BINS, np.nan)
    index = np.floor((ranges[:, 0] + math.pi) / BIN).astype(np.int64) % _BINS
    out[index] = ranges[:, 1]
    return out


def range_towards(
    ranges: FloatArray, centre: FloatArray, points: FloatArray, widen: int = 0
) -> FloatArray:
    """(M,) the view range (:func:`view_ranges`, seen from ``centre``) in the direction of
    each floor-plan point (M, 2), the farthest of the ``widen`` bins either side as well (a
    lone bin's stray reading does not hide what lies behind it); NaN where the view saw no
    wall that way.

    >>> ranges = np.array([[0.004, 2.0], [0.013, 3.0]])
    >>> range_towards(ranges, np.zeros(2), np.array([[3.0, 0.01], [0.0, 3.0]])).tolist()
    [2.0, nan]
    >>> range_towards(ranges, np.zeros(2), np.array([[3.0, 0.01]]), widen=1).tolist()
    [3.0]
    """
    offset = points - centre
    azimuth = np.arctan2(offset[:, 1], offset[:, 0])
    index = np.floor((azimuth + math.pi) / BIN).astype(np.int64)
    dense = _dense(ranges)
    near = dense[(index[:, None] + np.arange(-widen, widen + 1)[None, :]) % _BINS]
    found: FloatArray = np.full(len(points), np.nan)
    seen = ~np.all(np.isnan(near), axis=1)
    found[seen] = np.nanmax(near[seen], axis=1)
    return found


def shared_turn(
    first: FloatArray, second: FloatArray, params: PlacementParams = PlacementParams()
) -> int | None:
    """The quarter turns r (0-3) taking the second frame's aligned frame onto the first's
    (``aligned_first = rot90(r) @ aligned_second``) when their view ranges say the two
    frames share a camera; None when they overlap too little or disagree, or when two turns
    pass (a view that looks alike turned).

    first, second: (B, 2) :func:`view_ranges` of two frames.
    """
    if len(first) == 0 or len(second) == 0:
        return None
    return _turn_between(_dense(first), _dense(second), params)


def _turn_between(a: FloatArray, b: FloatArray, params: PlacementParams) -> int | None:
    """:func:`shared_turn` of two frames' ranges on the full circle (:func:`_dense`)."""
    tolerance = params.station_view_tolerance
    turns = np.repeat(np.arange(4), 2 * _YAW_SLACK + 1)
    shifts = turns * (_BINS // 4) + np.tile(np.arange(-_YAW_SLACK, _YAW_SLACK + 1), 4)
    # Row s: the second's ranges turned by shifts[s] bins (np.roll of each shift at once).
    turned = b[(np.arange(_BINS)[None, :] - shifts[:, None]) % _BINS]
    both = ~np.isnan(a)[None, :] & ~np.isnan(turned)
    near = np.where(both, a[None, :], 0.0)
    agree = both & (np.abs(near - np.where(both, turned, 0.0)) <= tolerance + 0.01 * near)
    overlap = both.sum(axis=1)
    least = max(1, round(math.radians(params.station_view_overlap) / BIN))
    share = agree.sum(axis=1) / np.maximum(overlap, 1)
    passed = set(turns[(overlap >= least) & (share >= params.station_view_share)].tolist())
    return passed.pop() if len(passed) == 1 else None


def station_mates(
    layouts: Mapping[str, LocalLayout], params: PlacementParams = PlacementParams()
) -> dict[str, dict[str, int]]:
    """Per fragment id, the other fragments whose single frame shares its camera, with the
    quarter turns taking the other's aligned frame onto its own (:func:`shared_turn`), less
    the pairs of triangles whose turns do not add up (:func:`without_odd_triangles`);
    fragments without view ranges (clouds, merged frames) have none."""
    ids = sorted(fid for fid, lay in layouts.items() if len(lay.view_ranges))
    mates: dict[str, dict[str, int]] = {fid: {} for fid in layouts}
    if params.station_view_overlap == 0.0:
        return mates
    dense = {fid: _dense(layouts[fid].view_ranges) for fid in ids}
    for i, first in enumerate(ids):
        for second in ids[i + 1 :]:
            turn = _turn_between(dense[first], dense[second], params)
            if turn is not None:
                mates[first][second] = turn
                mates[second][first] = (-turn) % 4
    return without_odd_triangles(mates)


def without_odd_triangles(mates: Mapping[str, Mapping[str, int]]) -> dict[str, dict[str, int]]:
    """The pairs of :func:`station_mates` less every pair in a triangle whose turns do not
    add up: frames of one station turn into each other consistently, so one of the three
    only looked alike (as from the middle of a rectangle), and none of them is trusted.

    >>> mates = {"a": {"b": 1, "c": 0}, "b": {"a": 3, "c": 0}, "c": {"a": 0, "b": 0}}
    >>> without_odd_triangles(mates)
    {'a': {}, 'b': {}, 'c': {}}
    >>> mates["a"]["c"] = mates["c"]["a"] = 1
    >>> mates["c"]["a"] = 3
    >>> without_odd_triangles(mates) == mates
    True
    """
    ids = sorted(mates)
    odd = {
        frozenset(pair)
        for a, b, c in itertools.combinations(ids, 3)
        if b in mates[a] and c in mates[a] and c in mates[b]
        and (mates[a][b] + mates[b][c] - mates[a][c]) % 4
        for pair in ((a, b), (b, c), (a, c))
    }  # fmt: skip
    return {a: {b: t for b, t in mates[a].items() if frozenset((a, b)) not in odd} for a in ids}
