"""Typed, frozen records passed between pipeline stages.

Frames: *local* is the fragment file's own frame; *aligned* is the fragment's Manhattan
frame (z up, walls along x or y, same origin as local); *site* is the common output frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

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
    """

    keypoints: FloatArray
    frame: ManhattanFrame
    source_boundary: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    target_boundary: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    footprint: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    evidence: Evidence = "cloud"
    unchained_walls: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    view_angle: float | None = None

    @property
    def ok(self) -> bool:
        """True when at least one wall was found."""
        return len(self.keypoints) >= 2

    def keypoints_local(self) -> FloatArray:
        """(K, 3) keypoints in the fragment-local frame, at floor height."""
        return self.floor_points_local(self.keypoints)

    def floor_points_local(self, xy: FloatArray) -> FloatArray:
        """(M, 3) fragment-local positions of (M, 2) aligned-frame points at floor height."""
        aligned = np.column_stack([xy, np.full(len(xy), self.frame.floor_z)])
        local: FloatArray = aligned @ self.frame.rotation  # orthonormal: R^T row-wise
        return local
