"""Manhattan frame of one fragment: up axis, wall directions, floor and ceiling heights.

Paper section 3.1, preprocessing. Local planar patches (normals of a thinned cloud) vote
for the dominant orientations: horizontal surfaces (floor, ceiling, table tops) for the up
axis and vertical ones (walls, furniture sides) for the wall directions. Voting on normals
is a Hough-style plane search that keeps every plane, large or small, so clutter, a tilted
sensor and floor-only regions are handled the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from schemas.params import ManhattanParams
from services.types import FloatArray, ManhattanFrame

__all__ = ["OrientedCloud", "estimate_manhattan_frame", "thin_with_normals"]

_NORMAL_RADIUS = 3.0  # neighbourhood radius for normals, in voxel sizes
_MIN_CEILING_CLEARANCE = 1.8  # m; a horizontal surface lower than this over the floor is furniture


@dataclass(frozen=True)
class OrientedCloud:
    """A thinned cloud with unit normals.

    points, normals: (M, 3) float64, fragment-local frame.
    """

    points: FloatArray
    normals: FloatArray


def thin_with_normals(points: FloatArray, params: ManhattanParams) -> OrientedCloud:
    """Thin to one point per voxel and estimate a normal for each.

    Parameters
    ----------
    points : (N, 3) float64, fragment-local, meters.
    params : voxel size and the rest of the plane-search settings.
    """
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud = cloud.voxel_down_sample(params.voxel_size)
    if len(cloud.points) < 3:
        thin = np.asarray(cloud.points, dtype=np.float64).reshape(-1, 3)
        return OrientedCloud(thin, np.tile([0.0, 0.0, 1.0], (len(thin), 1)))
    cloud.estimate_normals(
        o3d.geometry.KDTreeSearchParamHybrid(radius=_NORMAL_RADIUS * params.voxel_size, max_nn=24)
    )
    return OrientedCloud(
        np.asarray(cloud.points, dtype=np.float64), np.asarray(cloud.normals, dtype=np.float64)
    )


def _estimate_up(normals: FloatArray, max_tilt_deg: float) -> FloatArray:
    """Up axis: aligned with horizontal-surface normals, orthogonal to wall normals."""
    up = np.array([0.0, 0.0, 1.0])
    # Each pass narrows the cones around the current estimate, so clutter drops out.
    for cone_deg in (max_tilt_deg, 15.0, 8.0):
        cos_n = np.abs(normals @ up)
        horizontal = normals[cos_n > np.cos(np.radians(cone_deg))]
        vertical = normals[cos_n < np.sin(np.radians(cone_deg))]
        scatter = np.zeros((3, 3))
        if len(horizontal) >= 10:
            scatter += horizontal.T @ horizontal / len(horizontal)
        if len(vertical) >= 10:
            scatter -= vertical.T @ vertical / len(vertical)
        if not scatter.any():
            break
        _, vectors = np.linalg.eigh(scatter)
        candidate = vectors[:, -1]
        candidate = candidate if candidate[2] >= 0 else -candidate
        if np.degrees(np.arccos(np.clip(candidate[2], -1.0, 1.0))) > max_tilt_deg:
            break
        up = candidate
    unit: FloatArray = up / np.linalg.norm(up)
    return unit


def _minimal_tilt_rotation(up: FloatArray) -> FloatArray:
    """The smallest rotation taking ``up`` to +z (Rodrigues)."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(up, z)
    sin_a = float(np.linalg.norm(axis))
    cos_a = float(up @ z)
    if sin_a < 1e-12:
        return np.eye(3)
    k = axis / sin_a
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    rotation: FloatArray = np.eye(3) + sin_a * kx + (1.0 - cos_a) * (kx @ kx)
    return rotation


def _estimate_yaw(levelled_normals: FloatArray) -> tuple[float, float]:
    """Wall yaw modulo 90 degrees from the horizontal normals of vertical surfaces.

    Angles are multiplied by four so the four wall directions vote for one peak; the peak
    of a smoothed histogram is refined by a circular mean of the votes near it.
    Returns (yaw in radians in [-pi/4, pi/4), fraction of vertical normals that agree).
    """
    horizontal = levelled_normals[np.abs(levelled_normals[:, 2]) < np.sin(np.radians(15.0))]
    if len(horizontal) < 10:
        return 0.0, 0.0
    quad = 4.0 * np.arctan2(horizontal[:, 1], horizontal[:, 0])
    bins = 360
    hist, edges = np.histogram(np.mod(quad, 2 * np.pi), bins=bins, range=(0.0, 2 * np.pi))
    kernel = np.exp(-0.5 * (np.arange(-6, 7) / 2.0) ** 2)
    smooth = np.convolve(np.concatenate([hist[-6:], hist, hist[:6]]), kernel, mode="valid")
    peak = (edges[int(np.argmax(smooth))] + np.pi / bins) % (2 * np.pi)
    near = np.abs(np.angle(np.exp(1j * (quad - peak)))) < np.radians(20.0)
    mean = float(np.angle(np.exp(1j * quad[near]).mean()))
    yaw = mean / 4.0
    yaw = (yaw + np.pi / 4) % (np.pi / 2) - np.pi / 4
    return yaw, float(near.mean())


def _horizontal_levels(heights: FloatArray, floor_guess: float) -> tuple[float, float | None]:
    """Floor and ceiling heights from the heights of horizontal-surface points."""
    if len(heights) < 10:
        return floor_guess, None
    bin_size = 0.02
    lo, hi = float(heights.min()), float(heights.max())
    n_bins = max(1, int(np.ceil((hi - lo) / bin_size)) + 1)
    hist, edges = np.histogram(heights, bins=n_bins, range=(lo, lo + n_bins * bin_size))
    smooth = np.convolve(hist, np.ones(3), mode="same")
    strong = np.flatnonzero(smooth >= 0.15 * smooth.max())
    floor = float(edges[strong[0]] + bin_size / 2)
    floor = _refine_level(heights, floor)
    high = strong[edges[strong] > floor + _MIN_CEILING_CLEARANCE]
    ceiling = _refine_level(heights, float(edges[high[-1]] + bin_size / 2)) if len(high) else None
    return floor, ceiling


def _refine_level(heights: FloatArray, level: float) -> float:
    near = heights[np.abs(heights - level) < 0.04]
    return float(np.median(near)) if len(near) else level


def estimate_manhattan_frame(
    cloud: OrientedCloud, params: ManhattanParams = ManhattanParams()
) -> ManhattanFrame:
    """Estimate the rotation aligning a fragment to its Manhattan axes.

    Parameters
    ----------
    cloud : thinned fragment with normals (see :func:`thin_with_normals`), local frame.
    params : plane-search settings; ``max_tilt_deg`` bounds how far up may be from +z.

    Returns
    -------
    ManhattanFrame
        ``rotation`` maps local to aligned coordinates: up becomes +z and the walls run
        along x and y. Of the four equivalent wall assignments the one closest to the
        local frame is chosen (yaw in [-45, 45) degrees), the minimal rotation.
    """
    if len(cloud.points) == 0:
        return ManhattanFrame(rotation=np.eye(3), floor_z=0.0, ceiling_z=None)
    up = _estimate_up(cloud.normals, params.max_tilt_deg)
    tilt = _minimal_tilt_rotation(up)
    levelled = cloud.normals @ tilt.T
    yaw, support = _estimate_yaw(levelled)
    c, s = np.cos(-yaw), np.sin(-yaw)
    spin = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    rotation = spin @ tilt
    aligned_z = cloud.points @ rotation[2]
    normal_z = np.abs(cloud.normals @ up)
    flat = aligned_z[normal_z > np.cos(np.radians(10.0))]
    floor, ceiling = _horizontal_levels(flat, float(np.percentile(aligned_z, 1.0)))
    return ManhattanFrame(rotation=rotation, floor_z=floor, ceiling_z=ceiling, wall_support=support)
