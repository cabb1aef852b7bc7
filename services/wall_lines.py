"""Candidate walls of one fragment on the projection grid (paper 3.1, wall estimation graph).

Works in the aligned frame (z up, walls along x or y). A wall is an axis-parallel line with
an offset found at sub-cell precision (a peak in the histogram of wall-point offsets) and a
row of grid cells of size ``s`` along it. A cell on a line has high wall evidence when

* its column is tall: at least N occupied ``s``-sized height bins (N*s of wall; N shrinks for
  low rooms and sparse sensors, see :func:`evidence_threshold`), and
* it bounds the scanned space: the strip behind it holds far less than the strip in front.
  Furniture faces fail this (the wall behind them is seen above or beside them); real room
  walls pass it and tell which side is the interior.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import maximum_filter1d

from schemas.params import LayoutParams
from services.frustum import CameraView, visible_band
from services.types import FloatArray

__all__ = [
    "MAX_DOORWAY",
    "MAX_FURNITURE_DEPTH",
    "MAX_OPEN_ABOVE",
    "MAX_WALL_THICKNESS",
    "WallLine",
    "evidence_threshold",
    "find_wall_lines",
    "run_axis",
    "scan_top",
    "wall_line_of",
]

_HIST_BIN = 0.01  # m, offset histogram resolution
_LINE_TOLERANCE = 0.05  # m, wall points kept around a line offset
_MERGE_DISTANCE = 0.15  # m, parallel peaks closer than this are one wall
_NEAR_STRIP = 0.12  # m, the strips skip the wall's own noisy band
MAX_FURNITURE_DEPTH = 0.75  # m, deepest step into the room read as a furniture front
MAX_WALL_THICKNESS = 0.3  # m, deepest top or side of a wall's opening (furniture is deeper)
_FAR_STRIP = 1.0  # m, depth of the strips in front of and behind a wall
_MIN_BEHIND = 0.5  # m, the shallowest strip a bridge is checked with (one camera)
_BEHIND_RATIO = 0.3  # behind/front occupancy above which a cell is not a boundary
_MAX_GAP_CELLS = 2  # low cells bridged inside one candidate segment
_OCCLUSION_REACH = 3.0  # m, longest occluded stretch bridged between parallel walls
_ONE_CAMERA_REACH = 3.5  # m, the same for one camera (a step's side it saw edge-on)
_MAX_ARM_DEPTH = 7.0  # m, longest hidden side of a room's arm bridged (one camera's range)
_SHADOW_SLACK = 0.3  # m, a wall's end casts its shadow this close to where a wall is seen again
_MIN_ARM_SIDE = 0.5  # least share of an arm's depth its other side is seen along
_SUPPORT_POINTS = 3  # interior-strip points that show the line's cell borders scanned space
# Share of the floor-to-ceiling band a wall column must reach: walls meet the ceiling, a
# wardrobe stops 0.2-0.5 m short of it (at 0.85 its side became a wall at a scan's end).
_TOP_REACH = 0.95
# A thin scan's column may show that reach by a point of its own or of a column this many
# cells along the line: its few points leave most columns short of the top, while a
# wardrobe's columns all stop short. (Dense scans without it: fewer wrong chains.)
_THIN_REACH_CELLS = 2
_MIN_VISIBLE = 0.5  # m, least height of a column a camera must see to judge it
_AXIS_COS = float(np.cos(np.radians(25.0)))  # a normal within 25 deg of an axis faces along it
# m, widest doorway: a gap in a wall read as a door here, and the longest stretch a wall may
# run with space seen on both sides (services.wall_graph, services.frame_layout)
MAX_DOORWAY = 2.0
_RECESS_DEPTH = 0.3  # m, a wall reaching this far behind a gap's edge: a recess, not a door
_MIN_DOORWAY = 0.3  # m, least doorway a wall's end is carried across
_MIN_HIDDEN_WALL = 0.6  # m, least wall seen only over tall furniture a wall's end runs on along
# m, longest stretch of partly hidden wall (points at some height only) a wall's end is
# carried across to a lintel past it
_MAX_HIDDEN_LEAD = 1.0
_LINTEL_BINS = 3  # height bins a column seen only high up must hold to count as wall
_LINTEL_LOW = 1.6  # m over the floor: a column whose wall points all stand higher is wall over
# an opening (a lintel) or over tall furniture (wardrobes, shelves, fridges: 1.6 m and up)
_SEEN_THROUGH_REACH = 5.0  # m, farthest behind a wall's opening the next room's wall is taken
_SEEN_OPENING_CELLS = 3  # cells of opening (and of whole wall) a wall seen through one shows
_WINDOW_HEIGHT = 0.5  # m, least gap in a column's wall under wall seen over _LINTEL_LOW: a window
# m over the floor: a camera's ray crossing a line this high saw over where a door's lintel
# stands (doors of both generators top out at 2.15 m; real ones mostly at 2.0-2.1 m)
_OVER_DOORS = 2.3
# m, longest stretch of a line seen through over a door's top that a wall may still span
# (a few cells: stray ceiling points); past it the room goes on there
MAX_OPEN_ABOVE = 0.3


@dataclass(frozen=True)
class WallLine:
    """An axis-parallel wall line and its per-cell evidence.

    axis: 0 for a wall running along x (constant y), 1 for one running along y.
    offset: the constant coordinate (y for axis 0, x for axis 1), meters.
    travel: +1 or -1, the direction along the run axis that keeps the interior on the left.
    origin: run coordinate of the first cell's lower edge; cells are ``cell_size`` long.
    high: (C,) bool, high wall-evidence per cell.
    unsupported: (C,) bool or None: cells with no evidence and nothing scanned on the
    interior side (None: every cell counts as supported, as on a deduced wall).
    segments: (S, 2) float64 run-coordinate spans [start, end] of the candidate segments.
    virtual: True for a line deduced across an occluded stretch (no points of its own).
    seen_through: (C,) bool or None: cells with no evidence where space was scanned behind
    the line as well as in front (None on a deduced wall).
    occupied: (C,) bool or None: cells holding any wall point of the line, at any height.
    lintel: (C,) bool or None: cells whose wall stands over an opening: all its points over
    ``_LINTEL_LOW`` (above a door, or above tall furniture), or over and under a window.
    open_above: (C,) bool or None: cells through which one camera saw space beyond the line
    higher than any door's lintel (``_OVER_DOORS``): no wall stands there, nor a door.
    """

    axis: int
    offset: float
    travel: int
    origin: float
    cell_size: float
    high: NDArray[np.bool_]
    segments: FloatArray
    virtual: bool = False
    unsupported: NDArray[np.bool_] | None = None
    seen_through: NDArray[np.bool_] | None = None
    occupied: NDArray[np.bool_] | None = None
    lintel: NDArray[np.bool_] | None = None
    open_above: NDArray[np.bool_] | None = None

    def open_gap(self, start: float, end: float) -> float:
        """Longest stretch (m) between two run coordinates with neither wall evidence nor
        scanned space on the interior side: the line runs outside the room there."""
        return self._longest_run(self.unsupported, start, end)

    def crossing_gap(self, start: float, end: float) -> float:
        """Longest stretch (m) between two run coordinates where the scan saw space on both
        sides of the line: no wall stands there, at most a doorway."""
        return self._longest_run(self.seen_through, start, end)

    def high_wall_beyond(self, run: float, outward: int) -> float:
        """How far (m) the wall runs on, seen only high up (lintel), from a segment end at
        run coordinate ``run`` in direction ``outward`` (+1 or -1), starting within a few
        cells of the end or of up to 1 m of wall seen only in part past it (a jamb, a low
        cabinet; counted in): the lintel over a doorway (space seen behind the line under it)
        or a wall whose lower part tall furniture hides. 0 when there is none, or it is too
        short (0.3 m for a doorway, 0.6 m for a hidden wall: a corner's clutter) or wider
        than a doorway."""
        if self.seen_through is None or self.lintel is None:
            return 0.0
        first = int(np.rint((run - self.origin) / self.cell_size)) - (outward < 0)
        lead = self._hidden_lead(first, outward)
        first += outward * lead
        limit = int(np.ceil(MAX_DOORWAY / self.cell_size)) + _MAX_GAP_CELLS + 1
        span = _run_ahead(self.lintel, first, outward, limit)
        if span is None:
            return 0.0
        start, stop = span
        doorway = bool(_cells_ahead(self.seen_through, first, outward, limit)[start:stop].any())
        least = _MIN_DOORWAY if doorway else _MIN_HIDDEN_WALL
        if (stop - start) * self.cell_size < least or stop * self.cell_size > MAX_DOORWAY:
            return 0.0
        return (lead + stop) * self.cell_size

    def _hidden_lead(self, first: int, outward: int) -> int:
        """Cells from ``first`` on (walking ``outward``) where the wall shows only in part:
        wall points at some height, neither whole wall nor lintel (a door's jamb, a low
        cabinet in front of it); at most ``_MAX_HIDDEN_LEAD``; 0 on a line without cells
        of its own."""
        if self.occupied is None:
            return 0
        partly = self.occupied & ~self.high
        if self.lintel is not None:
            partly &= ~self.lintel
        limit = int(_MAX_HIDDEN_LEAD / self.cell_size)
        ahead = _cells_ahead(partly, first, outward, limit)
        return int(np.argmin(ahead)) if not ahead.all() else len(ahead)

    def open_above_gap(self, start: float, end: float) -> float:
        """Longest stretch (m) between two run coordinates that a camera saw through
        above a door's top: the room goes on there, past where the line would stand."""
        return self._longest_run(self.open_above, start, end)

    def high_run_beyond(self, run: float, outward: int) -> float:
        """How far (m) the line's high evidence goes on from run coordinate ``run`` in
        direction ``outward`` (+1 or -1): a run of high cells (gaps of two cells bridged)
        starting within two cells past ``run``; 0 when there is none."""
        first = int(np.floor((run - self.origin) / self.cell_size))
        span = _run_ahead(self.high, first + outward, outward)
        return 0.0 if span is None else span[1] * self.cell_size

    def _longest_run(self, flags: NDArray[np.bool_] | None, start: float, end: float) -> float:
        if flags is None:
            return 0.0
        i0, i1 = self._cells(start, end)
        # A stray cell or two (a sparse patch, a lone outlier) does not interrupt a gap, as
        # it does not interrupt a wall.
        spans = _runs(flags[i0:i1], max_gap=_MAX_GAP_CELLS, min_len=1)
        return max((end - start for start, end in spans), default=0) * self.cell_size

    def standing_share(self, start: float, end: float) -> float:
        """The share of the cells between two run coordinates where the line's wall stands,
        whole (high evidence) or over an opening (seen only high up, a lintel); 0 where
        none lie between."""
        i0, i1 = self._cells(start, end)
        if i1 <= i0:
            return 0.0
        standing = self.high[i0:i1]
        if self.lintel is not None:
            standing = standing | self.lintel[i0:i1]
        return float(np.mean(standing))

    def _cells(self, start: float, end: float) -> tuple[int, int]:
        lo, hi = sorted((start, end))
        i0 = int(np.clip(np.rint((lo - self.origin) / self.cell_size), 0, len(self.high)))
        i1 = int(np.clip(np.rint((hi - self.origin) / self.cell_size), 0, len(self.high)))
        return i0, i1

    def evidence(self, start: float, end: float) -> tuple[float, int]:
        """Length L in cells and the count H of high cells between two run coordinates."""
        i0, i1 = self._cells(start, end)
        high = int(np.count_nonzero(self.high[i0:i1]))
        return abs(end - start) / self.cell_size, high

    def wall_cells(self, start: float, end: float) -> tuple[int, int]:
        """Between two run coordinates: the cells holding any wall point of the line, and
        the unknown cells (no wall point and no space seen behind the line). (0, 0) on a
        deduced wall, which has no cells of its own."""
        if self.occupied is None or self.seen_through is None:
            return 0, 0
        i0, i1 = self._cells(start, end)
        occupied = self.occupied[i0:i1]
        unknown = ~occupied & ~self.seen_through[i0:i1]
        return int(np.count_nonzero(occupied)), int(np.count_nonzero(unknown))

    def high_cells(self, min_cells: int) -> FloatArray:
        """(H, 2) centres of the high-evidence cells in runs of at least ``min_cells``
        (gaps of two cells bridged, as a wall is): the wall this line shows, wherever a
        chain uses it or not. Empty on a deduced wall."""
        if self.virtual:
            return np.zeros((0, 2))
        spans = _runs(self.high, _MAX_GAP_CELLS, min_cells)
        cells = np.concatenate(
            [np.zeros(0, dtype=np.int64), *(np.flatnonzero(self.high[i:j]) + i for i, j in spans)]
        )
        run = self.origin + (cells + 0.5) * self.cell_size
        offset = np.full(len(run), self.offset)
        centres: FloatArray = np.column_stack([run, offset] if self.axis == 0 else [offset, run])
        return centres

    def seen_spans(self, max_gap: float) -> FloatArray:
        """(S, 2) run-coordinate spans of the cells holding the line's wall points at any
        height (its high cells on a line without that record), gaps up to ``max_gap`` m
        bridged."""
        cells = self.high if self.occupied is None else self.occupied | self.high
        runs = _runs(cells, int(max_gap / self.cell_size), 1)
        spans = self.origin + self.cell_size * np.array(runs, dtype=np.float64)
        return spans.reshape(-1, 2)

    def point(self, run: float) -> FloatArray:
        """The (x, y) point at run coordinate ``run`` on this line."""
        return np.array([run, self.offset] if self.axis == 0 else [self.offset, run])


def run_axis(step: FloatArray) -> int:
    """The axis (0: x, 1: y) a floor-plan step along a Manhattan wall runs on."""
    return 0 if abs(step[0]) >= abs(step[1]) else 1


def wall_line_of(
    lines: Sequence[WallLine], a: FloatArray, b: FloatArray, seen_only: bool = False
) -> WallLine | None:
    """The candidate line a chain's wall from keypoint ``a`` to ``b`` runs on (keypoints sit
    on their lines' offsets exactly); with ``seen_only``, not a deduced (virtual) one."""
    step = b - a
    axis = run_axis(step)
    travel = 1 if step[axis] > 0 else -1
    offset = a[1 - axis]
    for line in lines:
        if seen_only and line.virtual:
            continue
        if line.axis == axis and line.travel == travel and abs(line.offset - offset) < 1e-6:
            return line
    return None


def evidence_threshold(column_counts: NDArray[np.int64], band: float, params: LayoutParams) -> int:
    """Effective N: the paper's N, capped by the wall height and the sensor's density.

    A cell cannot hold more height bins than the band between floor and ceiling allows, and
    a sparse sensor (few rings, long range) fills fewer of them; so N is capped at half the
    band and at half the 90th percentile of occupied columns. This keeps "a wall stands
    here" meaning the same for a dense RGB-D scan and a 16-ring LiDAR.
    """
    n = float(params.min_cell_points)
    n = min(n, 0.5 * band / params.cell_size)
    occupied = column_counts[column_counts > 0]
    if len(occupied):
        n = min(n, 0.5 * float(np.percentile(occupied, 90)))
    return max(3, round(n))


def offset_peaks(offsets: FloatArray, min_support: float) -> FloatArray:
    """Offsets of the walls: peaks of the smoothed offset histogram, strongest first."""
    if len(offsets) == 0:
        return np.zeros(0)
    lo = float(offsets.min()) - 0.05
    n_bins = int(np.ceil((float(offsets.max()) + 0.05 - lo) / _HIST_BIN)) + 1
    hist = np.bincount(((offsets - lo) / _HIST_BIN).astype(np.int64), minlength=n_bins)
    kernel = np.exp(-0.5 * (np.arange(-4, 5) / 1.5) ** 2)
    window = np.convolve(hist, np.ones(2 * round(_LINE_TOLERANCE / _HIST_BIN) + 1), mode="same")
    smooth = np.convolve(hist, kernel, mode="same")
    order = np.argsort(-smooth, kind="stable")  # equal peaks in offset order on any machine
    peaks: list[float] = []
    # A peak needs points near it, however low the support asked for.
    for idx in order[window[order] >= max(min_support, 1.0)]:
        position = lo + (idx + 0.5) * _HIST_BIN
        if all(abs(position - p) > _MERGE_DISTANCE for p in peaks):
            peaks.append(position)
    return np.asarray(peaks)


def _cells_ahead(
    flags: NDArray[np.bool_], start: int, outward: int, limit: int | None = None
) -> NDArray[np.bool_]:
    """The flags from cell ``start`` on, walking ``outward`` (+1 or -1), at most ``limit``
    cells (to the line's end without one)."""
    if outward > 0:
        return flags[max(start, 0) : None if limit is None else start + limit]
    lowest = 0 if limit is None else max(start - limit + 1, 0)
    return flags[lowest : max(start + 1, 0)][::-1]


def _run_ahead(
    flags: NDArray[np.bool_], start: int, outward: int, limit: int | None = None
) -> tuple[int, int] | None:
    """The first run of True cells walking ``outward`` from cell ``start`` (gaps of two
    cells bridged), as [begin, end) cells from ``start``, if it begins within two cells."""
    spans = _runs(_cells_ahead(flags, start, outward, limit), max_gap=_MAX_GAP_CELLS, min_len=1)
    if not spans or spans[0][0] > _MAX_GAP_CELLS:
        return None
    return spans[0]


def _runs(mask: NDArray[np.bool_], max_gap: int, min_len: int) -> list[tuple[int, int]]:
    """Spans [i, j) of True cells, bridging gaps of at most ``max_gap`` False cells."""
    idx = np.flatnonzero(mask)
    if len(idx) == 0:
        return []
    breaks = np.flatnonzero(np.diff(idx) > max_gap + 1)
    starts = np.concatenate([[idx[0]], idx[breaks + 1]])
    ends = np.concatenate([idx[breaks], [idx[-1]]]) + 1
    return [(int(s), int(e)) for s, e in zip(starts, ends, strict=True) if e - s >= min_len]


@dataclass(frozen=True)
class _Grid:
    """Column occupancy of the whole fragment on the projection grid (aligned frame)."""

    origin: FloatArray  # (2,) x, y of cell (0, 0)'s lower corner
    cell: float
    occupancy: NDArray[np.int64]  # (nx, ny) thinned horizontal-surface points per column

    def strip_sums(
        self, axis: int, offset: float, cells: NDArray[np.int64], depth: float = _FAR_STRIP
    ) -> FloatArray:
        """Occupancy in the strips on the negative and positive side of a line, per cell,
        from ``_NEAR_STRIP`` to ``depth`` meters off it.

        Returns (2, C): row 0 behind (lower offset), row 1 in front (higher offset).
        """
        occ = self.occupancy if axis == 0 else self.occupancy.T
        run_ok = (cells >= 0) & (cells < occ.shape[0])
        cum = np.concatenate([np.zeros((occ.shape[0], 1)), np.cumsum(occ, axis=1)], axis=1)
        base = self.origin[1 - axis]

        def band(d0: float, d1: float) -> FloatArray:
            # Whole cells only, so the wall's own noisy band never leaks into a strip.
            j0 = int(np.clip(np.ceil((offset + d0 - base) / self.cell), 0, occ.shape[1]))
            j1 = int(np.clip(np.floor((offset + d1 - base) / self.cell), 0, occ.shape[1]))
            out = np.zeros(len(cells))
            out[run_ok] = cum[cells[run_ok], j1] - cum[cells[run_ok], j0]
            return out

        return np.vstack([band(-depth, -_NEAR_STRIP), band(_NEAR_STRIP, depth)])


def _make_grid(xy: FloatArray, cell: float, counted: NDArray[np.bool_]) -> _Grid:
    """The projection grid over all points; occupancy counts the ``counted`` ones."""
    origin = np.floor(xy.min(axis=0) / cell) * cell - 2 * _FAR_STRIP
    ij = ((xy - origin) / cell).astype(np.int64)
    margin = int(3 * _FAR_STRIP / cell)
    shape = (int(ij[:, 0].max()) + 1 + margin, int(ij[:, 1].max()) + 1 + margin)
    ij = ij[counted]
    flat = np.bincount(ij[:, 0] * shape[1] + ij[:, 1], minlength=shape[0] * shape[1])
    occupancy = flat.reshape(shape).astype(np.int64)
    return _Grid(origin=origin, cell=cell, occupancy=occupancy)


_HORIZON_BIN = float(np.radians(1.0))  # bearing bins of a camera's occlusion horizon
_OCCLUDER_GAP = 0.3  # m, points this close in front of a wall column do not hide it
_KEY_SPAN = 1000.0  # m, longer than any distance: a bin's sort keys never reach the next's


@dataclass(frozen=True)
class _Horizon:
    """What stands between one camera and the walls (aligned frame).

    Furniture stands on the floor, so a cabinet hides the wall behind it from the floor up
    to where the camera's rays pass over its top. Per bearing bin the occluding points are
    sorted by distance with the highest elevation angle seen so far, so the lowest height
    of a wall column the camera saw over nearer things is one lookup.

    keys: (M,) bearing bin * ``_KEY_SPAN`` + distance, sorted; elevation: (M,) the highest
    elevation angle (radians, from the camera) up to each point within its bin.
    """

    centre: FloatArray
    keys: FloatArray
    elevation: FloatArray

    @classmethod
    def of(cls, centre: FloatArray, points: FloatArray) -> _Horizon:
        """The horizon of the standing points (M, 3) seen from ``centre`` (3,)."""
        offset = points[:, :2] - centre[:2]
        distance = np.hypot(offset[:, 0], offset[:, 1])
        near = distance > _OCCLUDER_GAP  # the camera's own surroundings hide nothing here
        bins = np.floor(np.arctan2(offset[near, 1], offset[near, 0]) / _HORIZON_BIN)
        elevation = np.arctan2(points[near, 2] - centre[2], distance[near])
        keys = bins * _KEY_SPAN + distance[near]
        order = np.argsort(keys, kind="stable")
        # A running max that restarts in every bin: each bin is lifted above the one before
        # (elevations span less than 4 radians).
        lift = 4.0 * (bins[order] - (bins.min() if len(bins) else 0.0))
        running = np.maximum.accumulate(elevation[order] + lift) - lift
        return cls(centre, keys[order], running)

    def lowest_seen(self, xy: FloatArray) -> FloatArray:
        """(C,) the lowest height at which the camera saw past nearer standing points to
        each column ``xy`` (C, 2); -inf where nothing stands in front of it."""
        offset = xy - self.centre[:2]
        distance = np.hypot(offset[:, 0], offset[:, 1])
        start = np.floor(np.arctan2(offset[:, 1], offset[:, 0]) / _HORIZON_BIN) * _KEY_SPAN
        first = np.searchsorted(self.keys, start)
        last = np.searchsorted(self.keys, start + np.maximum(distance - _OCCLUDER_GAP, 0.0))
        angle = self.elevation[np.maximum(last - 1, 0)] if len(self.keys) else np.zeros(len(xy))
        return np.where(last > first, self.centre[2] + np.tan(angle) * distance, -np.inf)


@dataclass(frozen=True)
class _TallRule:
    """When a cell's column counts as standing wall: N height bins, reaching the top part
    of the floor-to-ceiling band (furniture stops lower; walls reach the ceiling), itself
    or through a column up to ``reach_cells`` along the line.

    With camera views (an RGB-D frame), both are measured against the part of the column
    the cameras saw: a wall near the camera shows only its lower part, and a wall behind a
    cabinet only its part over the cabinet (``horizon``, one camera), which need hold only
    half its height in bins (at least 3).
    """

    n: int
    floor_z: float
    top_bin: int
    top_z: float = np.inf
    views: tuple[CameraView, ...] = ()
    horizon: _Horizon | None = None
    reach_cells: int = 0

    def per_cell(self, xy: FloatArray, cell: float) -> tuple[FloatArray, FloatArray]:
        """(C,) least height bins and (C,) least top bin of the columns at ``xy`` (C, 2)."""
        n = np.full(len(xy), float(self.n))
        top = np.full(len(xy), float(self.top_bin))
        if not self.views:
            return n, top
        low, high = visible_band(self.views, xy)
        seen = ~np.isnan(high)
        high = np.minimum(high[seen], self.top_z)
        low = np.maximum(low[seen], self.floor_z + 0.1)
        visible = high - low
        if self.horizon is not None:
            low = np.maximum(low, self.horizon.lowest_seen(xy[seen]))
        # A column in view over less than half a meter cannot tell a wall from furniture.
        least = np.clip(0.5 * (high - low) / cell, 3, self.n)
        n[seen] = np.where(visible < _MIN_VISIBLE, np.inf, least)
        top[seen] = np.minimum(top[seen], np.floor((high - self.floor_z - 0.25) / cell))
        return n, top


def _depth_behind(axis: int, offset: float, points: FloatArray, camera: FloatArray) -> FloatArray:
    """(P,) how far (m) each point (P, 2 or 3) lies behind a line as seen from ``camera``:
    positive on the far side, 0 for every point when the camera stands on the line."""
    o = 1 - axis
    depth: FloatArray = (offset - points[:, o]) * np.sign(camera[o] - offset)
    return depth


def _sight_crossings(
    axis: int, offset: float, behind: FloatArray, camera: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Where the sight lines from ``camera`` to points behind a line cross it: the share
    of the way to each point, and the run coordinate along the line."""
    o, r = 1 - axis, axis
    t = (offset - camera[o]) / (behind[:, o] - camera[o])
    run: FloatArray = camera[r] + t * (behind[:, r] - camera[r])
    return t, run


def _per_cell(run: FloatArray, origin: float, cell: float, n_cells: int) -> NDArray[np.int64]:
    """(C,) how many of the run coordinates fall in each cell of a line."""
    cells = np.floor((run - origin) / cell).astype(np.int64)
    return np.bincount(cells[(cells >= 0) & (cells < n_cells)], minlength=n_cells)


def _ray_crossings(
    axis: int,
    offset: float,
    flat_xy: FloatArray,
    depth: FloatArray,
    centre: FloatArray,
    origin: float,
    cell: float,
    n_cells: int,
) -> FloatArray:
    """(C,) per cell of a line, the scanned points behind it (seen from ``centre``, 0.12-1 m
    behind; ``depth``: :func:`_depth_behind` of ``flat_xy``) whose line of sight crosses the
    line in that cell: space seen through the cell itself, not through a door or window
    beside it."""
    behind = flat_xy[(depth >= _NEAR_STRIP) & (depth <= _FAR_STRIP)]
    _, run = _sight_crossings(axis, offset, behind, centre)
    return _per_cell(run, origin, cell, n_cells).astype(np.float64)


def _seen_over_doors(
    axis: int,
    offset: float,
    flat: FloatArray,
    depth: FloatArray,
    camera: FloatArray,
    over: float,
    origin: float,
    cell: float,
    n_cells: int,
) -> NDArray[np.bool_]:
    """(C,) per cell of a line, whether a ray of the camera (at ``camera``, (3,)) crossed it
    there at height ``over`` or higher on its way to a horizontal surface (``flat``, (F, 3):
    the ceiling) more than a furniture's depth behind it: space beyond the line where a
    door's lintel would have stopped the ray (the ceiling over a wardrobe, seen past its
    front, lies closer). ``depth``: :func:`_depth_behind` of ``flat``."""
    behind = flat[(depth > MAX_FURNITURE_DEPTH) & (depth <= _SEEN_THROUGH_REACH)]
    t, run = _sight_crossings(axis, offset, behind, camera)
    height = camera[2] + t * (behind[:, 2] - camera[2])
    return _per_cell(run[height >= over], origin, cell, n_cells) > 0


def _framed(keys: NDArray[np.int64], n_cells: int, s: float) -> NDArray[np.bool_]:
    """(C,) cells whose wall points leave a gap of ``_WINDOW_HEIGHT`` or more that ends over
    ``_LINTEL_LOW``: wall under and over a window (or a picture, a screen hiding it), which
    stands there as the wall over a door does. keys: sorted unique ``cell * 4096 + bin``."""
    cells, bins = keys // 4096, keys % 4096
    same = cells[1:] == cells[:-1]
    gap = (bins[1:] - bins[:-1] - 1) * s
    window = same & (gap >= _WINDOW_HEIGHT) & (bins[1:] * s >= _LINTEL_LOW)
    out = np.zeros(n_cells, dtype=bool)
    out[cells[1:][window]] = True
    return out


def _beside_opening(
    lintel: NDArray[np.bool_], far_side: NDArray[np.float64], cell: float
) -> NDArray[np.bool_]:
    """(C,) cells of a cloud's line within a strip's depth of an opening in it (wall over
    it, space seen behind it), not in one. Through a door the view widens past its jambs,
    so the floor seen behind the wall beside a door says nothing of that wall: it was seen
    through the door. A tall surface standing free in the room has no wall over the space
    seen past its ends."""
    opening = lintel & (far_side >= _SUPPORT_POINTS)
    if not opening.any():
        return np.zeros(len(lintel), dtype=bool)
    reach = 2 * round(_FAR_STRIP / cell) + 1
    near: NDArray[np.bool_] = (maximum_filter1d(opening.astype(np.uint8), reach) > 0) & ~opening
    return near


def _lines_from_peak(
    axis: int,
    offset: float,
    members: FloatArray,
    grid: _Grid,
    rule: _TallRule,
    params: LayoutParams,
    flat: FloatArray,
) -> list[WallLine]:
    """Evidence along one line from its member points (aligned frame, (M, 3)).

    Each side is tried as the interior: a line yields one wall per side whose cells bound
    the scanned space from that side (two walls when collinear walls face each other).
    flat: (F, 3) the fragment's horizontal-surface points (floor, ceiling), aligned frame;
    with a single camera, what is seen behind a cell is counted where its ray crosses the line.
    """
    flat_xy = flat[:, :2]
    s = params.cell_size
    origin = grid.origin[axis]
    cells = ((members[:, axis] - origin) / s).astype(np.int64)
    z_bins = np.clip(((members[:, 2] - rule.floor_z) / s).astype(np.int64), 0, 4095)
    # The flags cover the whole grid along the line, not just its points' extent: a path
    # may follow the line past its last segment (to a deduced corner), and the gap tests
    # must see what lies there.
    n_cells = max(int(cells.max()) + 1, grid.occupancy.shape[axis])
    keys = np.unique(cells * 4096 + z_bins)
    reach = np.zeros(n_cells, dtype=np.int64)
    np.maximum.at(reach, keys // 4096, keys % 4096)
    lowest = np.full(n_cells, 4096, dtype=np.int64)
    np.minimum.at(lowest, keys // 4096, keys % 4096)
    lintel = ((lowest < 4096) & (lowest * s >= _LINTEL_LOW)) | _framed(keys, n_cells, s)
    run = origin + (np.arange(n_cells) + 0.5) * s
    xy = np.column_stack([run, np.full(n_cells, offset)])
    least_n, least_top = rule.per_cell(xy if axis == 0 else xy[:, ::-1], s)
    near_reach = maximum_filter1d(reach, 2 * rule.reach_cells + 1, mode="constant", cval=0)
    bins = np.bincount(keys // 4096, minlength=n_cells)
    # A column seen only high up (lintel) that reaches the ceiling is wall over furniture
    # (or a lintel, told apart by the space seen behind it below).
    tall = ((bins >= least_n) | (lintel & (bins >= _LINTEL_BINS))) & (near_reach >= least_top)
    behind, front = grid.strip_sums(axis, offset, np.arange(n_cells))
    one_camera = len(rule.views) == 1
    open_above = None
    if one_camera:
        # One camera: what was seen behind a cell is what its rays saw through that cell, not
        # the floor seen through a door beside it.
        camera = rule.views[0].centre
        centre = camera[:2]
        depth = _depth_behind(axis, offset, flat_xy, centre)
        crossing = _ray_crossings(axis, offset, flat_xy, depth, centre, origin, s, n_cells)
        over = rule.floor_z + _OVER_DOORS
        open_above = _seen_over_doors(axis, offset, flat, depth, camera, over, origin, s, n_cells)
        if centre[1 - axis] > offset:
            behind = crossing
        else:
            front = crossing
    lines = []
    occupied = np.bincount(cells, minlength=n_cells) > 0
    for sign, near_side, far_side in ((1, front, behind), (-1, behind, front)):
        high = tall & (far_side <= _BEHIND_RATIO * np.maximum(near_side, 1.0))
        if not rule.views and far_side[occupied].sum() < near_side[occupied].sum():
            # Beside a door the floor seen through it lies behind the wall too, yet along the
            # wall less is seen behind it than in front (from the next room, the other way).
            beside = _beside_opening(lintel, far_side, s) & (far_side <= near_side)
            high |= tall & beside
        spans = _runs(high, _MAX_GAP_CELLS, params.min_wall_cells)
        if not spans or (not rule.views and _faces_away(spans, near_side, far_side, occupied)):
            continue
        segments = np.array([[origin + a * s, origin + b * s] for a, b in spans])
        # Interior on the left: along x, interior +y means travelling +x; along y,
        # interior +x means travelling -y.
        travel = sign if axis == 0 else -sign
        unsupported = ~high & (near_side < _SUPPORT_POINTS)
        seen_through = ~high & (far_side >= _SUPPORT_POINTS)
        if one_camera:
            unsupported &= ~seen_through  # a doorway: crossing_gap bounds it
        if rule.views:
            # A frame sees the floor before a wall only where nothing stands against it (a
            # sofa, a cabinet): the wall's own points over it were scanned all the same.
            unsupported &= ~occupied
        lines.append(
            WallLine(
                axis,
                offset,
                travel,
                origin,
                s,
                high,
                segments,
                False,
                unsupported,
                seen_through,
                occupied,
                lintel,
                open_above,
            )
        )
    return lines


def _occluded_links(
    lines: list[WallLine], grid: _Grid, camera: FloatArray | None = None, jambs: bool = False
) -> list[WallLine]:
    """Deduced walls joining misaligned parallel segments that face the same interior.

    Only where the deduced wall bounds the scanned space like a real one (nothing seen
    behind it): a bridge across observed floor would be a shortcut, not an occluded wall.

    With one ``camera`` ((2,) its position on the floor plan, aligned frame) the hidden
    stretch is the one the nearer wall's end casts on the farther wall (a step's side that
    the camera saw would be a wall line of its own), so the bridge stands at the nearer
    wall's end; and what lies behind it is looked for no deeper than the shorter of the two
    walls' seen runs, so floor seen past a pillar's far side does not count against it.
    A step deeper than ``_ONE_CAMERA_REACH`` is bridged only where it closes an arm of the
    room (:func:`_closes_an_arm`).

    With ``jambs`` (clouds) no bridge stands at a wall's end next to a door or window of its
    line (:func:`_opening_near`): that end is a jamb, the wall goes on over the opening, and
    the other wall is one seen through it (a scan cut in a doorway). A frame's line shows
    such cells where its view ends too (wall seen only high up): frames keep those bridges.
    """
    cell = grid.cell
    longest = _OCCLUSION_REACH if camera is None else _MAX_ARM_DEPTH
    reach = _OCCLUSION_REACH if camera is None else _ONE_CAMERA_REACH
    deduced: list[WallLine] = []
    for a in lines:
        for b in lines:
            if a is b or a.axis != b.axis or a.travel != b.travel or a.virtual or b.virtual:
                continue
            if not 2 * cell <= abs(a.offset - b.offset) <= longest:
                continue  # a step too small to be a wall, or too long to be hidden
            for seg_a in a.segments:
                end = seg_a[1] if a.travel > 0 else seg_a[0]
                for seg_b in b.segments:
                    start = seg_b[0] if a.travel > 0 else seg_b[1]
                    if -2 * cell <= (start - end) * a.travel <= reach:
                        deduced += _hidden_walls(
                            a, b, (seg_a, seg_b), (end, start), grid, camera, lines, jambs
                        )
    return deduced


def _hidden_walls(
    a: WallLine,
    b: WallLine,
    segments: tuple[FloatArray, FloatArray],
    gap: tuple[float, float],
    grid: _Grid,
    camera: FloatArray | None,
    lines: list[WallLine],
    jambs: bool,
) -> list[WallLine]:
    """The bridges of :func:`_occluded_links` from a segment of line ``a`` over to the next
    segment of ``b`` along their travel (``segments``: the two, ``gap``: the run where the
    first ends and the second starts; ``jambs``: none from a doorway's side)."""
    seg_a, seg_b = segments
    end, start = gap
    runs: tuple[float, ...] = (end, start)
    depth = _FAR_STRIP
    if camera is not None:
        seen = camera[1 - a.axis]
        a_nearer = abs(a.offset - seen) < abs(b.offset - seen)
        if abs(a.offset - b.offset) > _ONE_CAMERA_REACH:
            near, far = (end, a.offset), (start, b.offset)
            if not a_nearer:
                near, far = far, near
            far_seen = seg_b if a_nearer else seg_a
            if not _closes_an_arm(near, far, far_seen, a.axis, camera, lines):
                return []
        runs = (end,) if a_nearer else (start,)
        shorter = min(seg_a[1] - seg_a[0], seg_b[1] - seg_b[0])
        depth = float(np.clip(shorter, _MIN_BEHIND, _FAR_STRIP))
    if jambs and (_opening_near(a, end) or _opening_near(b, start)):
        return []  # a doorway's jamb, not a wall's end: the wall goes on over the door
    bridges = (_bridge(a, b, run) for run in runs)
    return [
        br
        for br in bridges
        if _bounds_scan(br, grid, depth) and not _explained(br, lines, grid.cell)
    ]


def _opening_near(line: WallLine, run: float) -> bool:
    """Whether ``line`` has a door or window cell (:func:`_opening`) within two cells of
    run coordinate ``run`` (a segment's end)."""
    if line.lintel is None or line.seen_through is None:
        return False
    at = int(np.floor((run - line.origin) / line.cell_size))
    lo, hi = max(at - _MAX_GAP_CELLS, 0), max(at + _MAX_GAP_CELLS + 1, 0)
    return bool(_opening(line)[lo:hi].any())


def _closes_an_arm(
    near: tuple[float, float],
    far: tuple[float, float],
    far_seen: FloatArray,
    axis: int,
    camera: FloatArray,
    lines: Sequence[WallLine],
) -> bool:
    """Whether one camera saw a deep arm of the room past a wall's end, its side hidden.

    A pier or a wing's wall can hide the near side of a deep arm of the room (a camera
    behind that side's plane never sees it): the camera sees the wall ending, the arm's far
    wall beyond it from where the end's shadow falls, and the arm's other side. The bridge
    at the end is that hidden side when the ray from the camera past the end lands within
    ``_SHADOW_SLACK`` of where the far wall's seen part starts, and a seen wall across
    meets the far wall's other end and runs at least half the way back to the near wall.
    Without the last test a long bridge mostly joined walls of another room or across it.

    near, far: (run, offset) of the nearer wall's end and of the far wall's seen start, on
    lines of ``axis``; far_seen: (2,) the far wall's seen run span; camera: (2,) its
    position on the floor plan.
    """
    camera_run, camera_offset = camera[axis], camera[1 - axis]
    near_depth, far_depth = near[1] - camera_offset, far[1] - camera_offset
    if near_depth * far_depth <= 0 or abs(far_depth) <= abs(near_depth):
        return False  # the far wall is not behind the near one, seen from the camera
    shadow = camera_run + (near[0] - camera_run) * far_depth / near_depth
    if abs(shadow - far[0]) > _SHADOW_SLACK:
        return False
    other_end = (
        far_seen[0] if abs(far_seen[0] - far[0]) > abs(far_seen[1] - far[0]) else far_seen[1]
    )
    lo, hi = sorted((near[1], far[1]))
    for side in lines:
        if side.virtual or side.axis == axis or abs(side.offset - other_end) > _SHADOW_SLACK:
            continue
        spans = np.clip(side.segments, lo, hi)
        if float(np.sum(spans[:, 1] - spans[:, 0])) >= _MIN_ARM_SIDE * (hi - lo):
            return True
    return False


def _explained(bridge: WallLine, lines: list[WallLine], cell: float) -> bool:
    """True when a real wall already runs where the bridge would (within two cells)."""
    return any(
        not line.virtual
        and line.axis == bridge.axis
        and abs(line.offset - bridge.offset) <= 2 * cell
        for line in lines
    )


def _bounds_scan(line: WallLine, grid: _Grid, depth: float = _FAR_STRIP) -> bool:
    """True when little was seen behind the (deduced) wall compared to in front of it,
    within ``depth`` meters of it."""
    run = line.origin + (np.arange(len(line.high)) + 0.5) * line.cell_size
    # Skip the ends: there the strips run along the walls the line joins, not past it.
    start, stop = line.origin, line.origin + len(line.high) * line.cell_size
    run = run[(run > start + _NEAR_STRIP) & (run < stop - _NEAR_STRIP)]
    if len(run) == 0:
        return True
    cells = np.floor((run - grid.origin[line.axis]) / grid.cell).astype(np.int64)
    behind, front = grid.strip_sums(line.axis, line.offset, cells, depth)
    interior = line.travel if line.axis == 0 else -line.travel
    near, far = (front, behind) if interior > 0 else (behind, front)
    return bool(far.sum() <= _BEHIND_RATIO * max(float(near.sum()), float(len(cells))))


def _bridge(a: WallLine, b: WallLine, run: float) -> WallLine:
    """A fully evidenced wall at run coordinate ``run`` from line ``a`` over to line ``b``."""
    lo, hi = sorted((a.offset, b.offset))
    cells = max(1, round((hi - lo) / a.cell_size))
    # The chain walks along a, then across to b: the bridge is travelled from a to b.
    travel = 1 if b.offset > a.offset else -1
    return WallLine(
        axis=1 - a.axis,
        offset=float(run),
        travel=travel,
        origin=lo,
        cell_size=(hi - lo) / cells,
        high=np.ones(cells, dtype=bool),
        segments=np.array([[lo, hi]]),
        virtual=True,
    )


def scan_top(aligned: FloatArray, ceiling_z: float | None) -> float:
    """The ceiling's height, or the top of the scan (bar outliers) when it saw no ceiling;
    ``aligned``: (M, 3) points, M > 0, aligned frame."""
    return ceiling_z if ceiling_z is not None else float(np.percentile(aligned[:, 2], 99.5))


def find_wall_lines(
    aligned: FloatArray,
    normals: FloatArray,
    floor_z: float,
    ceiling_z: float | None,
    params: LayoutParams,
    views: Sequence[CameraView] = (),
    thin: bool = False,
) -> list[WallLine]:
    """Detect candidate wall lines with their evidence.

    Parameters
    ----------
    aligned : (M, 3) float64, thinned points in the aligned frame, meters.
    normals : (M, 3) float64, their unit normals in the aligned frame.
    floor_z, ceiling_z : heights in the aligned frame (ceiling None when unseen).
    params : grid cell size, N, shortest segment.
    views : the cameras of an RGB-D frame (aligned frame): the height a wall column must
        show is then measured against what they saw of it.
    thin : a cloud thinner than the calibration's: a column's neighbours along the line may
        show how high it reaches.
    """
    if len(aligned) == 0:
        return []
    top = scan_top(aligned, ceiling_z)
    in_band = (aligned[:, 2] > floor_z + 0.1) & (aligned[:, 2] < top - 0.1)
    band = max(top - floor_z - 0.2, params.cell_size)
    # Scanned space is told by points on horizontal surfaces (floor, ceiling, table tops):
    # stray points (outliers, reflections) have no consistent normal, and a wall's far
    # face standing behind it is not space the scanner saw.
    horizontal = np.abs(normals[:, 2]) > _AXIS_COS
    grid = _make_grid(aligned[:, :2], params.cell_size, horizontal)
    columns = ((aligned[in_band, :2] - grid.origin) / params.cell_size).astype(np.int64)
    z_bins = ((aligned[in_band, 2] - floor_z) / params.cell_size).astype(np.int64)
    keys = np.unique((columns[:, 0] * grid.occupancy.shape[1] + columns[:, 1]) * 4096 + z_bins)
    rule = _TallRule(
        n=evidence_threshold(np.bincount(keys // 4096), band, params),
        floor_z=floor_z,
        top_bin=int((0.1 + _TOP_REACH * band) / params.cell_size),
        top_z=top,
        views=tuple(views),
        # One camera: what stands in front of a wall hides its foot (many cameras: none).
        horizon=_Horizon.of(views[0].centre, aligned[in_band]) if len(views) == 1 else None,
        reach_cells=_THIN_REACH_CELLS if thin else 0,
    )
    flat = aligned[horizontal]
    flat_xy = flat[:, :2]

    def along(axis: int, on: _Grid) -> list[WallLine]:
        facing = in_band & (np.abs(normals[:, 1 - axis]) > _AXIS_COS)
        return _axis_lines(axis, aligned[facing], on, rule, params, flat)

    first = [along(0, grid), along(1, grid)]
    lines = first[0] + first[1]
    if not views:
        # The floor seen through a door lies behind the walls beside it too (a notch's side,
        # a wing's end next to the door): it is no space seen past those. (A frame's camera
        # tells what it saw through which cell; a cloud's points do not.)
        redone = list(first)
        for axis in (0, 1):
            through = _through_openings(first[1 - axis], flat_xy)
            if through.any():
                counted = horizontal.copy()
                counted[np.flatnonzero(horizontal)[through]] = False
                redone[axis] = along(axis, _make_grid(aligned[:, :2], params.cell_size, counted))
        lines = redone[0] + redone[1]
    else:
        lines = _facing_cameras(lines, views, params)
    lines = [line for line in lines if not _seen_through_opening(line, lines)]
    camera = views[0].centre[:2] if len(views) == 1 else None
    return lines + _occluded_links(lines, grid, camera, jambs=not views)


def _faces_away(
    spans: Sequence[tuple[int, int]],
    near_side: FloatArray,
    far_side: FloatArray,
    occupied: NDArray[np.bool_],
) -> bool:
    """Whether a cloud's wall, its interior on the near side, shows space only behind it.

    Nowhere along its spans is space seen in front of it, and somewhere along the wall
    (``occupied``: cells holding its points) space is seen behind it. The next room's wall
    seen through a door is seen from the front, where the floor through the door lies, and
    not at all from behind; beside the view through the door, nothing shows on either side
    of it, and it would pass for a wall of a room lying behind it. (A scan of walls alone
    shows space on neither side and keeps every wall.)"""
    if any(np.any(near_side[a:b] >= _SUPPORT_POINTS) for a, b in spans):
        return False
    return bool(np.any(far_side[occupied] >= _SUPPORT_POINTS))


def _axis_lines(
    axis: int,
    wall_points: FloatArray,
    grid: _Grid,
    rule: _TallRule,
    params: LayoutParams,
    flat: FloatArray,
) -> list[WallLine]:
    """The wall lines along ``axis`` of the wall points facing across it, strongest first."""
    offset_axis = 1 - axis
    lines: list[WallLine] = []
    min_support = params.min_wall_cells * rule.n * 0.5
    for peak in offset_peaks(wall_points[:, offset_axis], min_support):
        near = np.abs(wall_points[:, offset_axis] - peak) < _LINE_TOLERANCE
        members = wall_points[near]
        if len(members) == 0:
            continue  # a peak of the binned histogram can fall between the points
        offset = float(np.median(members[:, offset_axis]))
        lines += _lines_from_peak(axis, offset, members, grid, rule, params, flat)
    return lines


def _through_openings(lines: Sequence[WallLine], flat_xy: FloatArray) -> NDArray[np.bool_]:
    """(F,) the horizontal-surface points ``flat_xy`` seen through a door or window of one of
    ``lines``: behind it, within ``_SEEN_THROUGH_REACH``, in front of the opening or off to
    its side by no more than their depth behind it (the view widens past the jambs), and
    behind the wall itself, not past its ends (there the room may go on round a corner).
    The view stops at a wall behind the line that faces away from it: past that wall lies
    another part of the room (a U's other arm behind the window of the gap between the
    arms), seen from inside, not through the opening."""
    out = np.zeros(len(flat_xy), dtype=bool)
    for line in lines:
        if line.virtual or line.lintel is None or line.seen_through is None:
            continue
        spans = _opening_runs(line)
        if not spans:
            continue
        walls = _wall_runs(line)
        depth = (line.offset - flat_xy[:, 1 - line.axis]) * _interior_sign(line)
        run = flat_xy[:, line.axis]
        behind = (depth >= _NEAR_STRIP) & (depth <= _SEEN_THROUGH_REACH)
        behind &= ~_past_back_wall(line, lines, flat_xy, depth)
        cell = line.cell_size
        for a, b in spans:
            i, j = next((i, j) for i, j in walls if i <= a and b <= j)
            lo, hi = line.origin + a * cell, line.origin + b * cell
            wall_lo, wall_hi = line.origin + i * cell, line.origin + j * cell
            out |= (
                behind
                & (run >= np.maximum(lo - depth, wall_lo))
                & (run <= np.minimum(hi + depth, wall_hi))
            )
    return out


def _past_back_wall(
    line: WallLine, lines: Sequence[WallLine], flat_xy: FloatArray, depth: FloatArray
) -> NDArray[np.bool_]:
    """(F,) the points of ``flat_xy`` (``depth`` behind ``line``) that lie past a wall of
    another line along the same axis, behind ``line``, whose interior faces away from it."""
    past = np.zeros(len(flat_xy), dtype=bool)
    sign = _interior_sign(line)
    for back in lines:
        if back.axis != line.axis or back.virtual or _interior_sign(back) != -sign:
            continue
        back_depth = (line.offset - back.offset) * sign
        if not 0.0 < back_depth <= _SEEN_THROUGH_REACH:
            continue
        cells = np.floor((flat_xy[:, line.axis] - back.origin) / back.cell_size).astype(np.int64)
        standing = _span_mask(_wall_runs(back), len(back.high) + 1)  # the last: off the line
        cells = np.where((cells >= 0) & (cells < len(back.high)), cells, len(back.high))
        past |= (depth > back_depth) & standing[cells]
    return past


def _seen_through_opening(far: WallLine, lines: Sequence[WallLine]) -> bool:
    """Whether ``far`` is a wall of the next room seen through a door or window of a nearer
    wall facing the same way: that wall shows an opening in front of ``far`` and whole wall
    beside the opening (not only over it: a soffit), stands (whole, or over the opening) in
    front of most of ``far``'s wall where the scan saw it at all (a scan that ends in a
    doorway may see on through it past its own end), and no wall facing the other way lies
    between the two (a room's own recess or arm would). Where the room steps back instead,
    the space behind the nearer wall's line is seen open in front of ``far``.

    Through a doorway a scan sees the next room's far wall whole and longer than the door
    (the view widens past it), often more wall than the short stretches either side of
    the door: the chain would otherwise run along it, outside the room."""
    if far.virtual:
        return False
    far_cells = np.flatnonzero(far.high)
    if len(far_cells) == 0:
        return False
    first, last = int(far_cells[0]), int(far_cells[-1]) + 1
    for near in lines:
        if near is far or near.virtual or near.lintel is None or near.seen_through is None:
            continue
        depth = (near.offset - far.offset) * _interior_sign(near)
        if not (
            near.axis == far.axis
            and near.travel == far.travel
            and MAX_WALL_THICKNESS < depth <= _SEEN_THROUGH_REACH
            and near.origin == far.origin
            and len(near.high) >= last
        ):
            continue
        standing = maximum_filter1d((near.high | near.lintel).astype(np.uint8), 3) > 0
        known = (near.occupied if near.occupied is not None else near.high) | near.seen_through
        seen = far_cells[known[far_cells]]
        opening = _span_mask(_opening_runs(near), len(near.high))
        in_front = np.flatnonzero(opening[first:last]) + first
        if (
            len(seen)
            and np.mean(standing[seen]) >= 0.5
            and len(in_front) >= _SEEN_OPENING_CELLS
            and any(
                i <= in_front[0] < j and np.count_nonzero(near.high[i:j]) >= _SEEN_OPENING_CELLS
                for i, j in _wall_runs(near)
            )
            and not _wall_between(far, near, lines, first, last)
        ):
            return True
    return False


def _opening(line: WallLine) -> NDArray[np.bool_]:
    """(C,) cells of a door or window in the line: wall only over it (or over and under),
    space seen behind it, no whole wall. The line has ``lintel`` and ``seen_through``."""
    assert line.lintel is not None and line.seen_through is not None
    opening: NDArray[np.bool_] = line.lintel & ~line.high & line.seen_through
    return opening


def _opening_runs(line: WallLine) -> list[tuple[int, int]]:
    """Spans [i, j) of the line's doors and windows: runs of ``_SEEN_OPENING_CELLS`` or more
    :func:`_opening` cells without a gap (single columns seen only high up are stray points
    over the floor, not a lintel). The line has ``lintel`` and ``seen_through``."""
    return _runs(_opening(line), 0, _SEEN_OPENING_CELLS)


def _span_mask(spans: Sequence[tuple[int, int]], n_cells: int) -> NDArray[np.bool_]:
    """(n_cells,) True inside the spans [i, j)."""
    mask = np.zeros(n_cells, dtype=bool)
    for i, j in spans:
        mask[i:j] = True
    return mask


def _wall_runs(line: WallLine) -> list[tuple[int, int]]:
    """Spans [i, j) of cells where the line's own wall stands, at any height or only over an
    opening, whatever its evidence (the floor seen past a door hides the wall beside it:
    space behind it); gaps of two cells bridged."""
    if line.lintel is None:
        return _runs(line.high, _MAX_GAP_CELLS, 1)
    return _runs(
        line.occupied | line.lintel if line.occupied is not None else line.lintel,
        _MAX_GAP_CELLS,
        1,
    )


def _wall_between(
    far: WallLine, near: WallLine, lines: Sequence[WallLine], first: int, last: int
) -> bool:
    """Whether a wall facing the other way stands between two parallel walls facing the
    same way, along cells [first, last), farther than a wall's thickness from both (nearer,
    it is one of their own far faces)."""
    lo, hi = sorted((far.offset, near.offset))
    return any(
        line.axis == far.axis
        and line.travel == -far.travel
        and lo + MAX_WALL_THICKNESS < line.offset < hi - MAX_WALL_THICKNESS
        and line.origin == far.origin
        and np.count_nonzero(line.high[first:last]) >= _SEEN_OPENING_CELLS
        for line in lines
    )


def _interior_sign(line: WallLine) -> int:
    """+1 when the interior lies at higher offsets than the line, else -1."""
    return line.travel if line.axis == 0 else -line.travel


def _facing_cameras(
    lines: list[WallLine], views: Sequence[CameraView], params: LayoutParams
) -> list[WallLine]:
    """What an RGB-D frame's walls must satisfy: the camera stands on their interior side,
    and no nearer wall stands between it and them (a wall seen through a door or window of
    a nearer one is the next room's). Cells seen through a nearer line's wall points (at any
    height: a window leaves wall below and above it) or through a door in it
    (:func:`_doors_closed`) lose their evidence. A nearer line less than
    ``MAX_FURNITURE_DEPTH`` before the wall hides it only by its own points when within a
    wall's thickness of it (``MAX_WALL_THICKNESS``: an opening's far side), and not at all
    when deeper: it is a furniture front, and the wall seen over it, beside it or between
    two fronts (no doorway) is the room's. Cells in a nearer wall's shadow
    (:func:`_shadowed`) are not taken for open space, whatever lies in front of them."""
    centre = np.mean([view.centre[:2] for view in views], axis=0)
    facing = _turned_to_camera(lines, centre)
    closed: dict[tuple[int, float], NDArray[np.bool_]] = {}  # (near, away) -> doors closed
    kept = []
    for far in facing:
        c_off, c_run = centre[1 - far.axis], centre[far.axis]
        high = far.high.copy()
        run = far.origin + (np.arange(len(high)) + 0.5) * far.cell_size
        for n, near in enumerate(lines):  # any wall points occlude, whichever side they face
            if near.axis != far.axis or near.occupied is None:
                continue
            ratio = (near.offset - c_off) / (far.offset - c_off)
            if not 0.0 < ratio < 1.0 - _NEAR_STRIP:
                continue
            depth = abs(far.offset - near.offset)
            if depth < MAX_WALL_THICKNESS:
                occupied = near.occupied  # within the wall's thickness: its own points
            elif depth < MAX_FURNITURE_DEPTH:
                continue  # a furniture front: the wall was seen over or beside it
            else:
                away = float(np.sign(far.offset - near.offset))
                if (n, away) not in closed:
                    closed[n, away] = _doors_closed(near, lines, away)
                occupied = closed[n, away]
            cell = np.rint((c_run + (run - c_run) * ratio - near.origin) / near.cell_size)
            inside = (cell >= 0) & (cell < len(occupied))
            index = cell[inside].astype(np.int64)
            # The crossed cell only: a wall seen just past the end of a nearer line (its
            # neighbour cell) was seen beside it, not through it.
            high[np.flatnonzero(inside)[occupied[index]]] = False
        spans = _runs(high, _MAX_GAP_CELLS, params.min_wall_cells)
        if spans:
            segments = np.array(
                [[far.origin + a * far.cell_size, far.origin + b * far.cell_size] for a, b in spans]
            )
            unsupported = (
                None
                if far.unsupported is None
                else far.unsupported & ~_shadowed(far, facing, centre)
            )
            kept.append(
                dataclasses.replace(far, high=high, segments=segments, unsupported=unsupported)
            )
    return kept


def _shadowed(far: WallLine, lines: Sequence[WallLine], centre: FloatArray) -> NDArray[np.bool_]:
    """(C,) the cells of ``far`` hidden from the camera at ``centre`` (2,) by a nearer wall
    segment of another line. Nothing scanned in front of such a cell tells nothing: the
    camera could not see there, so the wall may run on behind the nearer one (a protruding
    corner's far side)."""
    run = far.origin + (np.arange(len(far.high)) + 0.5) * far.cell_size
    cells = np.column_stack([run, np.full(len(run), far.offset)])
    if far.axis == 1:
        cells = cells[:, ::-1]
    hidden = np.zeros(len(run), dtype=bool)
    for near in lines:
        if near.virtual or (
            near.axis == far.axis and abs(near.offset - far.offset) < _MERGE_DISTANCE
        ):
            continue
        across = cells[:, 1 - near.axis] - centre[1 - near.axis]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (near.offset - centre[1 - near.axis]) / across
        cross = centre[near.axis] + t * (cells[:, near.axis] - centre[near.axis])
        on = np.any(
            (cross[:, None] >= near.segments[None, :, 0])
            & (cross[:, None] <= near.segments[None, :, 1]),
            axis=1,
        )
        hidden |= (t > 0.0) & (t < 1.0 - _NEAR_STRIP / np.maximum(np.abs(across), _NEAR_STRIP)) & on
    return hidden


def _turned_to_camera(lines: Sequence[WallLine], centre: FloatArray) -> list[WallLine]:
    """The lines with the camera (``centre`` (2,), aligned frame) on their interior side.

    The camera stands inside the room, so every wall it sees faces it. A line whose boundary
    test put its interior on the far side is turned round, unless a line facing the camera
    lies there already: near the camera the floor in front of a wall is below the view, while
    floor beyond it shows through a door, and the wall was read as facing away.
    """
    toward = [(centre[1 - line.axis] - line.offset) * _interior_sign(line) > 0 for line in lines]
    facing = [line for line, ok in zip(lines, toward, strict=True) if ok]
    axes = np.array([line.axis for line in facing])
    offsets = np.array([line.offset for line in facing])

    def free(line: WallLine) -> bool:
        return not np.any((axes == line.axis) & (np.abs(offsets - line.offset) < _MERGE_DISTANCE))

    return facing + [
        dataclasses.replace(line, travel=-line.travel)
        for line, ok in zip(lines, toward, strict=True)
        if not ok and free(line)
    ]


def _doors_closed(near: WallLine, lines: Sequence[WallLine], away: float) -> NDArray[np.bool_]:
    """A line's occupied cells with its doorways filled in: gaps of at most ``MAX_DOORWAY``
    between runs of wall points of the line, unless a wall of the other axis leaves the line
    along a run or the gap, going away from the camera (``away``, the sign of the far side's
    offsets): that gap opens onto a recess or a wing of the room (its run may be furniture
    standing at the line), not onto the next room. A frame often sees a door's sides but not
    the wall over it (the top of its view is lower), and through it a wall of the next room
    with more evidence than the nearer wall's pieces.
    """
    assert near.occupied is not None
    occupied = near.occupied.copy()
    runs = np.array(_runs(occupied, _MAX_GAP_CELLS, 1)).reshape(-1, 2)  # [start, stop) cells
    width = (runs[1:, 0] - runs[:-1, 1]) * near.cell_size
    behind = near.offset + away * _RECESS_DEPTH
    sides = np.array(
        [
            other.offset
            for other in lines
            if not other.virtual
            and other.axis != near.axis
            and np.any((other.segments[:, 0] <= behind) & (other.segments[:, 1] >= behind))
        ]
    )
    reach = 2 * near.cell_size
    for k in np.flatnonzero(width <= MAX_DOORWAY):
        lo, hi = (
            near.origin + runs[k, 0] * near.cell_size,
            near.origin + runs[k + 1, 1] * near.cell_size,
        )
        if not np.any((sides >= lo - reach) & (sides <= hi + reach)):
            occupied[runs[k, 1] : runs[k + 1, 0]] = True
    return occupied
