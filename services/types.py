"""Typed, frozen records passed between pipeline stages.

Frames: *local* is the fragment file's own frame; *aligned* is the fragment's Manhattan
frame (z up, walls along x or y, same origin as local); *site* is the common output frame.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from schemas.layout import Evidence

__all__ = [
    "Evidence",
    "FloatArray",
    "LocalLayout",
    "ManhattanFrame",
    "ParsedFragment",
    "ProgressFn",
]

FloatArray = NDArray[np.float64]
ProgressFn = Callable[[str, float], None]  # (stage, fraction done) for long work

# Grids a layout is snapped to before placement, in decimal places: 1 um for lengths, 1e-9
# for rotation entries and angles. Far below any sensor's noise, far above the last bits in
# which two machines' BLAS kernels (AVX-512 or not) compute the same layout.
_LENGTH_DECIMALS = 6
_UNIT_DECIMALS = 9


def _snap(value: FloatArray, decimals: int = _LENGTH_DECIMALS) -> FloatArray:
    return np.asarray(np.round(np.asarray(value, dtype=np.float64), decimals), dtype=np.float64)


def _snap_scalar(value: float | None, decimals: int = _LENGTH_DECIMALS) -> float | None:
    return None if value is None else round(float(value), decimals)


def _snap_rotation(rotation: FloatArray) -> FloatArray:
    """``rotation`` snapped, then made orthonormal again (up row kept, first wall row made
    square to it, second their cross product) in plain float arithmetic: no BLAS, so the
    same bits on any machine."""
    (ax, ay, az), _, (ux, uy, uz) = _snap(rotation, _UNIT_DECIMALS).tolist()
    norm = math.sqrt(ux * ux + uy * uy + uz * uz)
    ux, uy, uz = ux / norm, uy / norm, uz / norm
    along = ax * ux + ay * uy + az * uz
    ax, ay, az = ax - along * ux, ay - along * uy, az - along * uz
    norm = math.sqrt(ax * ax + ay * ay + az * az)
    ax, ay, az = ax / norm, ay / norm, az / norm
    across = [uy * az - uz * ay, uz * ax - ux * az, ux * ay - uy * ax]
    return np.array([[ax, ay, az], across, [ux, uy, uz]])


@dataclass(frozen=True)
class ParsedFragment:
    """A decoded fragment file.

    points: (N, 3) float64, fragment-local, meters, all finite.
    """

    points: FloatArray
    format: str
    dropped_nonfinite: int = 0


@dataclass(frozen=True)
class ManhattanFrame:
    """The rotation that aligns a fragment to its Manhattan axes.

    rotation: (3, 3) float64; ``aligned = rotation @ local``. Row 2 is the up axis in the
    local frame; rows 0 and 1 are the two wall directions.
    floor_z, ceiling_z: heights in the aligned frame (ceiling None when never seen).
    """

    rotation: FloatArray
    floor_z: float
    ceiling_z: float | None
    n_planes: int = 0
    wall_support: float = 0.0

    def snapped(self) -> ManhattanFrame:
        """The frame with its rotation and heights on fixed grids (see ``LocalLayout.snapped``)."""
        return replace(
            self,
            rotation=_snap_rotation(self.rotation),
            floor_z=round(float(self.floor_z), _LENGTH_DECIMALS),
            ceiling_z=_snap_scalar(self.ceiling_z),
            wall_support=round(float(self.wall_support), _UNIT_DECIMALS),
        )


@dataclass(frozen=True)
class ChainVariant:
    """Another chain a fragment's walls allow, aligned frame, as :class:`LocalLayout` holds
    its own: keypoints (K, 2) and the boundary points (M, 3) around its source and target."""

    keypoints: FloatArray
    source_boundary: FloatArray
    target_boundary: FloatArray

    def snapped(self) -> ChainVariant:
        """The variant on the fixed grid (see ``LocalLayout.snapped``)."""
        return ChainVariant(
            _snap(self.keypoints), _snap(self.source_boundary), _snap(self.target_boundary)
        )


@dataclass(frozen=True)
class LocalLayout:
    """The chain of walls one fragment sees (paper 3.1).

    keypoints: (K, 2) float64, aligned frame (x, y), meters, ordered source -> target so the
    room interior lies on the LEFT of every wall (counter-clockwise room loop). K == 0 when no
    wall chain was found.
    frame: the fragment's Manhattan frame.
    source_boundary, target_boundary: (M, 3) float64, aligned frame: points within the
    boundary band of the cutting planes through the source and target.
    footprint: (F, 2) float64, aligned frame: centres of the coarse floor-plan cells the
    scan covers (where the scanner saw space); they must end up inside the room.
    unchained_walls: (W, 2) float64, aligned frame: centres of the wall cells with high
    evidence (:meth:`services.wall_lines.WallLine.high_cells`) that no wall of the chain runs
    through: a notch or fin the chain cut across, a wall it skipped, the next room's wall
    seen through a door. Inside the room, only a wall of the floorplan explains them.
    evidence: what the chain rests on: ``"cloud"``, ``"thin_cloud"`` (fewer points than any
    cloud the confidence was fitted on) or ``"frame"`` (RGB-D frames). The last two are
    wrong more often in ways no placement term sees, so rooms of them are calibrated apart.
    view_angle: frames only: the horizontal angle the cameras see across, radians, summed
    over merged frames (None for clouds). A wider view sees more walls, so its chains are
    right more often and its rooms are calibrated by it.
    view_top: frames only: how high the top of the view reaches at its middle, radians above
    level (the highest of merged frames; None for clouds). A view whose top lies below
    level sees only its walls' feet, which furniture shows too.
    cameras: (C, 2) float64, aligned frame: frames only, where each camera's optical centre
    stands (one per merged frame; empty for clouds). Frames taken from one station (a robot
    turning on the spot, a camera on a tripod) share it, which pins how far apart the
    placement may put their walls.
    view_ranges: (B, 2) float64: single frames only, per half degree of azimuth around the
    camera (aligned frame, radians), how far the walls seen there stand, m
    (:func:`services.view_ranges.view_ranges`; empty for clouds and merged frames). Two
    frames whose ranges agree once turned share their camera.
    runner_up: frames only: the chain the wall graph ranked second where its two candidate
    chains differ (:attr:`services.wall_graph.WallChain.runner_up`), after the same steps as
    the chain; None otherwise. The placement tries it (:meth:`with_runner_up`).
    """

    keypoints: FloatArray
    frame: ManhattanFrame
    source_boundary: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    target_boundary: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    footprint: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    evidence: Evidence = "cloud"
    unchained_walls: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    view_angle: float | None = None
    view_top: float | None = None
    cameras: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    view_ranges: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    runner_up: ChainVariant | None = None

    @property
    def ok(self) -> bool:
        """True when at least one wall was found."""
        return len(self.keypoints) >= 2

    def snapped(self) -> LocalLayout:
        """The layout with every coordinate on a 1 um grid and its rotation on a 1e-9 grid.

        Two machines estimate the same scan's layout alike up to the last bits (their BLAS
        kernels sum in other orders), and the placement search breaks near-ties on such bits.
        Placed snapped, the same layouts give the same room on any machine.
        """
        return replace(
            self,
            keypoints=_snap(self.keypoints),
            frame=self.frame.snapped(),
            source_boundary=_snap(self.source_boundary),
            target_boundary=_snap(self.target_boundary),
            footprint=_snap(self.footprint),
            unchained_walls=_snap(self.unchained_walls),
            view_angle=_snap_scalar(self.view_angle, _UNIT_DECIMALS),
            view_top=_snap_scalar(self.view_top, _UNIT_DECIMALS),
            cameras=_snap(self.cameras),
            view_ranges=_snap(self.view_ranges),
            runner_up=None if self.runner_up is None else self.runner_up.snapped(),
        )

    def with_runner_up(self) -> LocalLayout | None:
        """The layout with its runner-up chain in place of its chain (and no runner-up);
        None without one."""
        if self.runner_up is None:
            return None
        return replace(
            self,
            keypoints=self.runner_up.keypoints,
            source_boundary=self.runner_up.source_boundary,
            target_boundary=self.runner_up.target_boundary,
            runner_up=None,
        )

    def keypoints_local(self) -> FloatArray:
        """(K, 3) keypoints in the fragment-local frame, at floor height."""
        return self.floor_points_local(self.keypoints)

    def floor_points_local(self, xy: FloatArray) -> FloatArray:
        """(M, 3) fragment-local positions of (M, 2) aligned-frame points at floor height."""
        aligned = np.column_stack([xy, np.full(len(xy), self.frame.floor_z)])
        local: FloatArray = aligned @ self.frame.rotation  # orthonormal: R^T row-wise
        return local
