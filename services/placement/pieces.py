"""Pieces: fragments' wall chains prepared for placement, and their plane geometry.

A piece is one fragment's chain in its aligned frame, shifted so its source is at the
origin. Rotating a piece by quarter turns and shifting it places it in the site frame.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.ndimage import binary_erosion, distance_transform_edt

from services.types import Evidence, FloatArray, LocalLayout

__all__ = [
    "SAMPLE_SPACING",
    "UNIT",
    "Box",
    "FreeSpace",
    "Piece",
    "box_of",
    "direction_index",
    "evidence_share",
    "make_piece",
    "open_end_count",
    "rot90",
    "shift_walls",
    "wall_samples",
    "walls_of",
]

UNIT = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])  # by direction index
_FREE_CELL = 0.25  # m, cell of the free-space grid
_OWN_WALL_CLEARANCE = 0.35  # m, seen space this close to the piece's own walls is not "free"
_BEHIND_WALL = 0.3  # m, footprint cells further behind the piece's own wall are dropped
SAMPLE_SPACING = 0.1  # m, wall samples for the free-space test


def rot90(quarter_turns: int) -> FloatArray:
    """2x2 rotation by ``quarter_turns`` * 90 degrees counter-clockwise.

    >>> rot90(1) @ np.array([1.0, 0.0])
    array([0., 1.])
    """
    c, s = [(1, 0), (0, 1), (-1, 0), (0, -1)][quarter_turns % 4]
    return np.array([[c, -s], [s, c]], dtype=np.float64)


def direction_index(v: FloatArray) -> int:
    """0: +x, 1: +y, 2: -x, 3: -y for an axis-parallel vector."""
    if abs(v[0]) >= abs(v[1]):
        return 0 if v[0] > 0 else 2
    return 1 if v[1] > 0 else 3


Box = tuple[float, float, float, float]  # (x_lo, y_lo, x_hi, y_hi)


def box_of(points: FloatArray) -> Box:
    """The bounds of (M, 2) points; an empty box (lo > hi) for none."""
    if len(points) == 0:
        return (np.inf, np.inf, -np.inf, -np.inf)
    (x0, y0), (x1, y1) = points.min(axis=0).tolist(), points.max(axis=0).tolist()
    return (x0, y0, x1, y1)


def walls_of(points: FloatArray) -> FloatArray:
    """(W, 4) rows (axis, offset, lo, hi) of an axis-parallel chain's walls."""
    a, b = points[:-1], points[1:]
    along_x = np.abs(b[:, 0] - a[:, 0]) >= np.abs(b[:, 1] - a[:, 1])
    offset = np.where(along_x, a[:, 1], a[:, 0])
    lo = np.where(along_x, np.minimum(a[:, 0], b[:, 0]), np.minimum(a[:, 1], b[:, 1]))
    hi = np.where(along_x, np.maximum(a[:, 0], b[:, 0]), np.maximum(a[:, 1], b[:, 1]))
    return np.column_stack([np.where(along_x, 0.0, 1.0), offset, lo, hi])


def shift_walls(walls: FloatArray, shift: FloatArray) -> FloatArray:
    """Walls (axis, offset, lo, hi) translated by ``shift`` (2,)."""
    sx, sy = float(shift[0]), float(shift[1])
    # Row by axis: a wall along x moves its offset by y and its run by x; along y, reversed.
    by_axis = np.array([[0.0, sy, sx, sx], [0.0, sx, sy, sy]])
    shifted: FloatArray = walls + by_axis[walls[:, 0].astype(np.intp)]
    return shifted


def wall_samples(points: FloatArray, spacing: float = SAMPLE_SPACING) -> FloatArray:
    """(S, 2) points every ``spacing`` along a chain, its ends excluded (they touch the
    neighbours' walls by construction)."""
    parts = []
    for a, b in itertools.pairwise(points):
        length = float(np.abs(b - a).sum())
        steps = np.arange(spacing, length - spacing / 2, spacing) / max(length, 1e-9)
        parts.append(a + steps[:, None] * (b - a))
    return np.vstack(parts) if parts else np.zeros((0, 2))


@dataclass(frozen=True)
class FreeSpace:
    """Where a scan saw open space, as a boolean grid in the piece's frame.

    grid: (I, J) bool, True for a cell whose floor or ceiling the scan saw and which lies
    more than a clearance away from the piece's own walls, in front of them.
    origin: (2,) position of cell (0, 0)'s corner; cell: cell size, m.
    lo, hi: (2,) bounds of the True cells (lo > hi when there are none).
    """

    grid: np.ndarray
    origin: FloatArray
    cell: float
    lo: FloatArray
    hi: FloatArray

    def rotated(self, quarter_turns: int) -> FreeSpace:
        """The same space seen in a frame turned by ``quarter_turns`` (exact on the grid)."""
        r = quarter_turns % 4
        if r == 0 or not self.grid.any():
            return self  # nothing to turn: an empty space is the same in every frame
        corners = (
            np.array([self.origin, self.origin + np.array(self.grid.shape) * self.cell])
            @ rot90(r).T
        )
        grid = np.rot90(self.grid, k=r)
        bounds = np.array([self.lo, self.hi]) @ rot90(r).T
        return FreeSpace(
            np.ascontiguousarray(grid),
            corners.min(axis=0),
            self.cell,
            bounds.min(axis=0) - self.cell,
            bounds.max(axis=0) + self.cell,
        )

    @cached_property
    def centres(self) -> FloatArray:
        """(M, 2) centres of the free cells, this grid's frame."""
        cells: FloatArray = (np.argwhere(self.grid) + 0.5) * self.cell + self.origin
        return cells.reshape(-1, 2)

    @cached_property
    def box(self) -> tuple[float, float, float, float]:
        """(x_lo, y_lo, x_hi, y_hi) of the free cells, as floats for quick tests."""
        return (float(self.lo[0]), float(self.lo[1]), float(self.hi[0]), float(self.hi[1]))

    @cached_property
    def depth(self) -> FloatArray:
        """(I, J) how far each free cell's centre lies inside the free space (from the
        nearest cell not free, centre to centre), m; 0 outside it."""
        depth: FloatArray = distance_transform_edt(self.grid) * self.cell
        return depth

    def hits(self, xy: FloatArray, margin: float | FloatArray = 0.0) -> int:
        """How many of the (M, 2) points (this grid's frame) fall in free cells more than
        ``margin`` (m, one or (M,)) inside the free space."""
        if len(xy) == 0 or self.grid.size == 0:
            return 0
        ij = ((xy - self.origin) * (1.0 / self.cell)).astype(np.int64)
        # Points outside the grid clip onto its border rows and columns, which are never
        # free (the footprint has a cell margin and erosion clears the border).
        flat = np.ravel_multi_index((ij[:, 0], ij[:, 1]), self.grid.shape, mode="clip")
        if isinstance(margin, float) and margin <= 0.0:
            return int(np.count_nonzero(self.grid.ravel().take(flat)))
        return int(np.count_nonzero(self.depth.ravel().take(flat) > margin))


@dataclass(frozen=True)
class Piece:
    """One fragment's chain prepared for placement, aligned frame with the source at 0.

    keypoints: (K, 2) float64, source first (at the origin), interior on the left.
    directions: (K-1,) direction index of each wall.
    source_region, target_region: (M, 3) float64, the end regions' points in the end's
    travel frame: x along the chain's direction of travel at that end (beyond a target end
    is x > 0, before a source end is x < 0), y towards the interior (from the wall line),
    z above the floor.
    footprint: (F, 2) float64, scanned floor-plan cells relative to the source.
    free: the seen open space, piece frame.
    ceiling: ceiling height above the floor, or None when the scan saw no ceiling.
    evidence: what the chain rests on (see LocalLayout).
    view_angle: frames only, the horizontal angle their cameras see across (see LocalLayout).
    view_top: frames only, how high the top of the view reaches (see LocalLayout).
    cameras: (C, 2) float64, frames only: the cameras' optical centres relative to the
    source (empty for clouds; see LocalLayout).
    station_mates: frames only: (id, r) for each other piece whose frame shares this one's
    camera, r the quarter turns taking its aligned frame onto this one's
    (:func:`services.view_ranges.station_mates`).
    open_ends: (source, target): frames only, whether the view continues well past that
    end, so its junction may hide metres of wall (:func:`services.open_ends.open_ends`).
    """

    id: str
    keypoints: FloatArray
    directions: tuple[int, ...]
    source_region: FloatArray
    target_region: FloatArray
    footprint: FloatArray
    free: FreeSpace
    ceiling: float | None = None
    evidence: Evidence = "cloud"
    view_angle: float | None = None
    view_top: float | None = None
    cameras: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    station_mates: tuple[tuple[str, int], ...] = ()
    open_ends: tuple[bool, bool] = (False, False)

    @cached_property
    def turning(self) -> int:
        """Signed quarter turns inside the chain (left +1, right -1)."""
        return sum(self.turns)

    @cached_property
    def corners(self) -> int:
        """Corners inside the chain."""
        return len(self.keypoints) - 2

    @cached_property
    def length(self) -> float:
        """Total wall length, m."""
        return float(self.wall_lengths.sum())

    @cached_property
    def wall_lengths(self) -> FloatArray:
        """(K-1,) length of each wall, m."""
        lengths: FloatArray = np.abs(np.diff(self.keypoints, axis=0)).sum(axis=1)
        return lengths

    @cached_property
    def turns(self) -> tuple[int, ...]:
        """Each corner of the chain in order: +1 turning left, -1 right (0 where two walls
        run the same way or back, which no chain has)."""
        steps = np.diff(np.asarray(self.directions)) % 4
        return tuple(int(t) for t in np.select([steps == 1, steps == 3], [1, -1], 0))

    @cached_property
    def rotated(self) -> tuple[tuple[FloatArray, FloatArray, FloatArray], ...]:
        """Per quarter turn r: rotated keypoints, their walls, their wall samples."""
        out = []
        for r in range(4):
            pts = self.keypoints @ rot90(r).T
            out.append((pts, walls_of(pts), wall_samples(pts)))
        return tuple(out)

    @cached_property
    def sample_boxes(self) -> tuple[Box, ...]:
        """Per quarter turn r: the box of the wall samples turned by r (see :func:`box_of`)."""
        return tuple(box_of(samples) for _, _, samples in self.rotated)

    @cached_property
    def rotated_free(self) -> tuple[FreeSpace, ...]:
        """Per quarter turn r: the free space turned by r."""
        return tuple(self.free.rotated(r) for r in range(4))

    @cached_property
    def rotated_free_centres(self) -> tuple[FloatArray, ...]:
        """Per quarter turn r: the free cells' centres turned by r (exact on the grid)."""
        return tuple(self.free.centres @ rot90(r).T for r in range(4))


def make_piece(fragment_id: str, layout: LocalLayout) -> Piece:
    """Prepare a local layout (with at least one wall) for placement."""
    keypoints = layout.keypoints
    kp = keypoints - keypoints[0]
    dirs = tuple(direction_index(d) for d in np.diff(kp, axis=0))
    floor = layout.frame.floor_z
    source = _travel_frame(layout.source_boundary, keypoints[0], UNIT[dirs[0]], floor)
    target = _travel_frame(layout.target_boundary, keypoints[-1], UNIT[dirs[-1]], floor)
    footprint = _in_front_of_walls(layout.footprint, keypoints) - keypoints[0]
    ceiling = layout.frame.ceiling_z
    return Piece(
        id=fragment_id,
        keypoints=kp,
        directions=dirs,
        source_region=source,
        target_region=target,
        footprint=footprint,
        free=_free_space(footprint, kp),
        ceiling=None if ceiling is None else float(ceiling - floor),
        evidence=layout.evidence,
        view_angle=layout.view_angle,
        view_top=layout.view_top,
        cameras=layout.cameras - keypoints[0],
    )


def evidence_share(pieces: Sequence[Piece], kind: Evidence) -> float:
    """The share of ``pieces`` whose chain rests on evidence of ``kind`` (0 without pieces)."""
    return sum(piece.evidence == kind for piece in pieces) / max(len(pieces), 1)


def open_end_count(pieces: Sequence[Piece]) -> int:
    """How many chain ends of ``pieces`` are open (:func:`services.open_ends.open_ends`)."""
    return sum(sum(piece.open_ends) for piece in pieces)


def _travel_frame(
    points: FloatArray, end: FloatArray, travel: FloatArray, floor_z: float
) -> FloatArray:
    """(M, 3) aligned points -> (x along ``travel``, y to the interior, z above floor)."""
    left = np.array([-travel[1], travel[0]])
    rel = points[:, :2] - end
    return np.column_stack([rel @ travel, rel @ left, points[:, 2] - floor_z])


def _in_front_of_walls(cells: FloatArray, keypoints: FloatArray) -> FloatArray:
    """The cells not behind one of the chain's own walls.

    Space a scan saw behind its own walls (through a door or window) is outside the room by
    the scan's own evidence: it cannot tell one placement from another, so it is left out.
    """
    if len(cells) == 0 or len(keypoints) < 2:
        return cells
    start, end = keypoints[:-1], keypoints[1:]
    along = end - start
    length = np.linalg.norm(along, axis=1)
    unit = along / np.maximum(length, 1e-9)[:, None]
    rel = cells[:, None, :] - start[None]
    t = (rel * unit[None]).sum(-1)
    left = unit[None, :, 0] * rel[..., 1] - unit[None, :, 1] * rel[..., 0]
    behind = (t > 0) & (t < length[None]) & (left < -_BEHIND_WALL)
    kept: FloatArray = cells[~behind.any(axis=1)]
    return kept


def _free_space(footprint: FloatArray, keypoints: FloatArray) -> FreeSpace:
    """Grid of the footprint cells clear of the piece's own walls (piece frame)."""
    if len(footprint) == 0:
        empty = np.zeros((0, 0), dtype=bool)
        return FreeSpace(empty, np.zeros(2), _FREE_CELL, np.full(2, np.inf), np.full(2, -np.inf))
    samples = np.vstack([keypoints, wall_samples(keypoints, 0.05)])
    gaps = np.min(np.linalg.norm(footprint[:, None, :] - samples[None], axis=2), axis=1)
    clear = footprint[gaps > _OWN_WALL_CLEARANCE]
    origin = footprint.min(axis=0) - _FREE_CELL
    shape = np.floor((footprint.max(axis=0) - origin) / _FREE_CELL).astype(np.int64) + 2
    grid = np.zeros(tuple(shape), dtype=bool)
    ij = np.floor((clear - origin) / _FREE_CELL).astype(np.int64)
    grid[ij[:, 0], ij[:, 1]] = True
    # Only space seen all around counts: the rim of what a scan saw is where walls (its
    # neighbours' too) stand, and noise or clutter blurs it by a cell.
    grid = binary_erosion(grid, np.ones((3, 3), dtype=bool))
    clear = (np.argwhere(grid) + 0.5) * _FREE_CELL + origin
    if len(clear) == 0:
        return FreeSpace(grid, origin, _FREE_CELL, np.full(2, np.inf), np.full(2, -np.inf))
    lo = np.floor((clear.min(axis=0) - origin) / _FREE_CELL) * _FREE_CELL + origin
    hi = np.floor((clear.max(axis=0) - origin) / _FREE_CELL + 1) * _FREE_CELL + origin
    return FreeSpace(grid, origin, _FREE_CELL, lo, hi)
