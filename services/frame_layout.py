"""Local layout of an RGB-D frame, or of frames merged into one (paper supplement).

As for a point cloud (:mod:`services.local_layout`) with three changes:

- the optical frame (x right, y down, z forward) is first turned to the camera's level frame
  (z up), so levelling starts from the right up axis; that turn is folded into the reported
  Manhattan rotation, so poses still map the frame's own (optical) points;
- a wall column must show the height its camera saw of it, not the whole floor-to-ceiling
  band (:class:`services.frustum.CameraView`);
- the chain's source and target are the widest pair of keypoints seen from the camera.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from schemas.frames import IntrinsicsModel
from schemas.params import PipelineParams
from services.frustum import CameraView
from services.local_layout import boundary_points, footprint_cells
from services.manhattan import estimate_manhattan_frame, thin_with_normals
from services.rgbd import OPTICAL_TO_LEVEL, RgbdFrame, backproject
from services.types import FloatArray, LocalLayout, ManhattanFrame, ProgressFn
from services.wall_graph import find_wall_chain
from services.wall_lines import find_wall_lines

_FLAT_COS = float(np.cos(np.radians(10.0)))  # a normal this close to +z: horizontal surface
_SPACING = 0.03  # m, largest spacing of a frame's points at 4 m (sets the pixel stride)
_FLOOR_BAND = 0.05  # m, points this close to the floor height lie on the floor
_MIN_FLOOR_POINTS = 50
_MIN_HEIGHT, _MAX_HEIGHT = 0.2, 2.5  # m, camera heights over a floor that can be one

__all__ = ["FrameCamera", "estimate_frame_layout", "estimate_rgbd_layout", "frame_points"]


@dataclass(frozen=True)
class FrameCamera:
    """A camera that took (part of) a fragment.

    intrinsics: its pinhole model. pose: (4, 4) its optical frame -> the fragment's local
    frame (identity for a single frame; for merged frames, the anchor frame's optical frame).
    """

    intrinsics: IntrinsicsModel
    pose: FloatArray = field(default_factory=lambda: np.eye(4))


def frame_points(frame: RgbdFrame, params: PipelineParams = PipelineParams()) -> FloatArray:
    """(N, 3) float64 points of a frame for its layout: every k-th pixel in the depth range,
    optical frame, meters; k is at most ``stride`` and keeps neighbouring points at most
    about 3 cm apart at 4 m (a wide-angle or small image is used whole)."""
    k = frame.intrinsics
    step = int(np.clip(min(k.fx, k.fy) * _SPACING / 4.0, 1, params.layout.frame.stride))
    points, _ = backproject(frame, params.layout.frame, step)
    return points


def _unit(v: FloatArray) -> FloatArray:
    norm = float(np.linalg.norm(v))
    return v / norm if norm > 0 else v


def _floor(
    aligned: FloatArray, normals: FloatArray, floor_z: float, params: PipelineParams
) -> float:
    """The measured floor height (aligned frame, camera at 0) when the frame shows enough
    floor below the camera, else the assumed camera height below it."""
    frame = params.layout.frame
    on_floor = (normals[:, 2] > _FLAT_COS) & (np.abs(aligned[:, 2] - floor_z) < _FLOOR_BAND)
    least = max(_MIN_FLOOR_POINTS, frame.min_floor_share * len(aligned))
    if np.count_nonzero(on_floor) >= least and -_MAX_HEIGHT < floor_z < -_MIN_HEIGHT:
        return floor_z
    return -frame.camera_height


def estimate_frame_layout(
    points: FloatArray,
    cameras: Sequence[FrameCamera],
    params: PipelineParams = PipelineParams(),
    progress: ProgressFn | None = None,
) -> LocalLayout:
    """Estimate the wall chain seen by one or more RGB-D cameras.

    Parameters
    ----------
    points : (N, 3) float64, the fragment's local frame (the optical frame of its first
        camera), meters, finite.
    cameras : the cameras that saw them (at least one), posed in the local frame.
    params : all algorithm parameters (Manhattan and layout sections are used).
    progress : optional callback ``(stage, fraction)``.

    Returns
    -------
    LocalLayout
        As :func:`services.local_layout.estimate_local_layout`; ``frame.rotation`` maps the
        local (optical) frame to the aligned one.
    """
    if not cameras:
        raise ValueError("a frame layout needs at least one camera")
    report = progress or (lambda stage, fraction: None)
    report("manhattan", 0.0)
    cloud = thin_with_normals(points @ OPTICAL_TO_LEVEL.T, params.manhattan)
    levelled = estimate_manhattan_frame(cloud, params.manhattan)
    aligned = cloud.points @ levelled.rotation.T
    normals = cloud.normals @ levelled.rotation.T
    frame = ManhattanFrame(
        rotation=levelled.rotation @ OPTICAL_TO_LEVEL,
        floor_z=_floor(aligned, normals, levelled.floor_z, params),
        ceiling_z=levelled.ceiling_z,
        n_planes=levelled.n_planes,
        wall_support=levelled.wall_support,
    )
    views = [
        CameraView.from_intrinsics(
            camera.intrinsics,
            frame.rotation @ camera.pose[:3, :3],
            frame.rotation @ camera.pose[:3, 3],
        )
        for camera in cameras
    ]
    report("walls", 0.4)
    lines = find_wall_lines(aligned, normals, frame.floor_z, frame.ceiling_z, params.layout, views)
    report("chain", 0.7)
    chain = find_wall_chain(lines, params.layout, views)
    footprint = footprint_cells(aligned)
    if chain is None or len(chain.keypoints) < 2:
        report("done", 1.0)
        return LocalLayout(keypoints=np.zeros((0, 2)), frame=frame, footprint=footprint)
    kp = chain.keypoints
    band, depth = params.layout.end_region_beyond, params.layout.end_region_depth
    report("done", 1.0)
    return LocalLayout(
        keypoints=kp,
        frame=frame,
        source_boundary=boundary_points(aligned, kp[0], _unit(kp[1] - kp[0]), band, depth),
        target_boundary=boundary_points(aligned, kp[-1], _unit(kp[-2] - kp[-1]), band, depth),
        footprint=footprint,
    )


def estimate_rgbd_layout(
    frame: RgbdFrame,
    params: PipelineParams = PipelineParams(),
    progress: ProgressFn | None = None,
) -> LocalLayout:
    """Local layout of one RGB-D frame (its local frame is its optical frame)."""
    return estimate_frame_layout(
        frame_points(frame, params), [FrameCamera(frame.intrinsics)], params, progress
    )
