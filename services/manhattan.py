"""Manhattan frame of one fragment: up axis, wall directions, floor and ceiling heights.

Paper section 3.1, preprocessing, in three steps:

1. Planes by sequential RANSAC give the first up axis (the largest near-horizontal plane:
   floor or ceiling).
2. Local planar patches (normals of a thinned cloud) vote for the dominant orientations:
   horizontal surfaces refine the up axis, vertical ones (walls, furniture sides) give the
   wall directions modulo 90 degrees. Voting keeps every plane, large or small, so clutter,
   a tilted sensor and floor-only regions are handled alike.
3. Fine tilt and yaw: the small rotation that makes floor heights and wall offsets pile up
   most sharply (the whole scan is the lever arm, not a 15 cm normal neighbourhood).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from schemas.params import ManhattanParams
from services.geometry import column_max, column_min
from services.types import FloatArray, ManhattanFrame

__all__ = [
    "OrientedCloud",
    "estimate_manhattan_frame",
    "point_spacing",
    "steep_floor_tilt",
    "thin_with_normals",
    "voxel_thin",
]

_NORMAL_RADIUS = 3.0  # neighbourhood radius for normals, in voxel sizes
# ... and at least this many times the thinned cloud's point spacing: a sparse scanner's
# points lie further apart than the voxels, and a point with fewer than two neighbours in
# the radius gets no normal of its own (open3d leaves it pointing up, i.e. floor).
_SPACING_RADIUS = 2.5
# A point with fewer than this many points (itself included) within the normal radius has
# no surface around it (an outlier, a reflection): open3d leaves its normal pointing up, and
# up reads as floor, i.e. as space the scanner saw, and votes for the frame's axes.
_NORMAL_NEIGHBOURS = 3
_SPACING_SAMPLE = 2_000  # points whose nearest neighbour measures the spacing
_DENSE_GRID = 1 << 22  # voxel grids up to this size are thinned by counting (32 MB)
_DENSE_RATIO = 16  # ... when they hold at most this many voxels per point
# Thinning that kept more than this share of the points left most voxels with one point:
# only then can the points lie further apart than the voxels (a dense scan or an RGB-D
# frame keeps a third or less, and skips the measurement).
_SPARSE_SHARE = 0.5
_RANSAC_CHUNK = 64  # candidate planes scored per matrix product (bounds memory)
# A frame with fewer normals than this share within the tilt limit of up is searched for a
# steeper floor, which must hold as many (a steep frame's floor holds a third or more)
_STEEP_SHARE = 0.1
_STEEP_CANDIDATES = 200  # normals tried as the floor's direction
_STEEP_CONE_DEG = 10.0  # normals this close to a candidate support it
_SHARPEN_POINTS = 12_000  # points used by the fine tilt and yaw search
_DEGENERATE_GAP = 0.05  # up is ambiguous when its scatter eigenvalue leads by less than this
_MIN_CEILING_CLEARANCE = 1.8  # m; a horizontal surface lower than this over the floor is furniture
# A ceiling is the top of what a scan sees: with more than this share of the points over it
# by the margin, the walls go on above it, and it is a door's or window's head or a wardrobe
# top in a scan that never saw its ceiling (outside clouds: 10 of 325 fragments, at 1.9-2.2 m
# in rooms 2.5-3 m high; none of the scans that saw their ceiling).
_MAX_ABOVE_CEILING = 0.03
_ABOVE_CEILING_MARGIN = 0.15  # m


@dataclass(frozen=True)
class OrientedCloud:
    """A thinned cloud with unit normals.

    points, normals: (M, 3) float64, fragment-local frame.
    spacing: median distance between neighbouring points, meters, where the scan may be
    sparser than the voxels (0 where it was not measured: a dense scan).
    """

    points: FloatArray
    normals: FloatArray
    spacing: float = 0.0


def thin_with_normals(
    points: FloatArray, params: ManhattanParams, max_voxels: int | None = None
) -> OrientedCloud:
    """Thin to one point per voxel, estimate a normal for each from its neighbours within
    three voxels, or within 2.5 point spacings where the scan is sparser than that, and
    drop the points with no surface around them (fewer than two others within that radius:
    outliers, reflections).

    Parameters
    ----------
    points : (N, 3) float64, fragment-local, meters.
    params : voxel size and the rest of the plane-search settings.
    max_voxels : when the voxels are more than this, the thinned cloud is thinned again with
        voxels grown by the square root of the excess (a scan is a surface: its voxel count
        falls with the voxel's area), so what follows costs about as much as that many.
    """
    size = params.voxel_size
    thinned = voxel_thin(points, size)
    if max_voxels is not None and len(thinned) > max_voxels:
        size *= float(np.sqrt(len(thinned) / max_voxels))
        thinned = voxel_thin(thinned, size)
    if len(thinned) < _NORMAL_NEIGHBOURS:
        return OrientedCloud(thinned, np.tile([0.0, 0.0, 1.0], (len(thinned), 1)))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(thinned))
    spacing = point_spacing(thinned) if len(thinned) > _SPARSE_SHARE * len(points) else 0.0
    radius = max(_NORMAL_RADIUS * size, _SPACING_RADIUS * spacing)
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=24))
    normals = np.asarray(cloud.normals, dtype=np.float64)
    # Only a point open3d left pointing up can be stray: the others had neighbours enough.
    up = np.flatnonzero((normals[:, 0] == 0.0) & (normals[:, 1] == 0.0) & (normals[:, 2] == 1.0))
    if len(up):
        distances, _ = cKDTree(thinned, balanced_tree=False, compact_nodes=False).query(
            thinned[up], k=_NORMAL_NEIGHBOURS, distance_upper_bound=radius
        )
        kept = np.ones(len(thinned), dtype=bool)
        kept[up[np.isinf(distances[:, -1])]] = False
        thinned, normals = thinned[kept], normals[kept]
    return OrientedCloud(thinned, normals, spacing)


def voxel_thin(points: FloatArray, size: float) -> FloatArray:
    """The mean of the points in each occupied voxel of a ``size`` grid, in the voxels' order.

    The order is the grid's, not the input's: the plane search samples the thinned points by
    index, so the same scan in another point order (another file format, another driver)
    gives the same frame. Voxels as open3d's ``voxel_down_sample`` draws them.
    """
    if len(points) == 0:
        return np.zeros((0, 3))
    origin = column_min(points) - 0.5 * size
    scaled = points - origin
    scaled /= size
    cells = np.floor(scaled, out=scaled).astype(np.int64)
    extent = column_max(cells) + 1
    keys = (cells[:, 0] * extent[1] + cells[:, 1]) * extent[2] + cells[:, 2]
    grid = int(extent[0]) * int(extent[1]) * int(extent[2])
    if grid <= min(_DENSE_GRID, _DENSE_RATIO * len(points)):
        # A grid about the size of the scan: counting per voxel is cheaper than sorting the
        # keys, and gives the same voxels in the same (key) order.
        per_voxel = np.bincount(keys, minlength=grid)
        occupied = per_voxel > 0
        voxel = np.cumsum(occupied, dtype=np.int32)[keys] - 1  # the grid fits in int32
        counts = per_voxel[occupied]
    else:
        _, voxel, counts = np.unique(keys, return_inverse=True, return_counts=True)
    sums = np.column_stack(
        [np.bincount(voxel, weights=points[:, axis], minlength=len(counts)) for axis in range(3)]
    )
    thinned: FloatArray = sums / counts[:, None]
    return thinned


def point_spacing(points: FloatArray) -> float:
    """Median distance from a point to its nearest neighbour, over an even sample of at
    most ``_SPACING_SAMPLE`` points (0 for fewer than two points)."""
    if len(points) < 2:
        return 0.0
    sample = points[:: max(1, len(points) // _SPACING_SAMPLE)]
    distances, _ = cKDTree(points).query(sample, k=2)
    return float(np.median(distances[:, 1]))


def _floor_plane_normal(cloud: OrientedCloud, params: ManhattanParams) -> FloatArray | None:
    """Normal of the largest near-horizontal plane found by sequential RANSAC, or None.

    Planes are peeled off largest first (walls, floor, ceiling, table tops); the first one
    within the tilt limit of +z that holds enough points is taken as floor or ceiling.
    """
    if len(cloud.points) < 100:
        return None
    rng = np.random.default_rng(0)  # same input, same planes
    rest = cloud.points
    needed = params.min_plane_fraction * len(cloud.points)
    for _ in range(params.max_planes):
        if len(rest) < max(needed, 3):
            return None
        normal, inliers = _ransac_plane(rest, params.ransac_distance, params.ransac_iterations, rng)
        if np.count_nonzero(inliers) < needed:
            return None
        if abs(normal[2]) > np.cos(np.radians(params.max_tilt_deg)):
            found: FloatArray = normal if normal[2] > 0 else -normal
            return found
        rest = rest[~inliers]
    return None


def steep_floor_tilt(
    cloud: OrientedCloud, params: ManhattanParams, max_pitch_deg: float
) -> FloatArray | None:
    """The smallest rotation taking the floor to +z, for a camera looking down more steeply
    than ``params.max_tilt_deg`` (in its level frame); None for any other view.

    A camera held over a desk or a floor pitches 30-45 degrees: up then lies outside the
    plane search's tilt limit, and the frame would be levelled on whatever lies inside it.
    When few normals lie within the limit (under ``_STEEP_SHARE``), the normals within
    ``max_pitch_deg`` of +z that lean back (a camera looking down sees the floor's normal
    lean towards it, the facing wall's away) are clustered (10 degree cones around a sample
    of them): of the directions that hold that share, the one closest to +z is up. A
    direction within the limit leaves the view to the usual search, exactly as before. The
    level frame is the camera's (x right, y forward, z up); a camera looking steeply up is
    not handled.
    """
    normals = cloud.normals
    if len(normals) < 100:
        return None
    needed = _STEEP_SHARE * len(normals)
    if np.count_nonzero(np.abs(normals[:, 2]) > np.cos(np.radians(params.max_tilt_deg))) >= needed:
        return None
    oriented = normals * np.where(normals[:, 2:3] < 0, -1.0, 1.0)
    # Looking down tilts the floor's normal back (-y), the facing wall's forwards (+y).
    cap = oriented[(oriented[:, 2] > np.cos(np.radians(max_pitch_deg))) & (oriented[:, 1] < 0)]
    if len(cap) < needed:
        return None
    candidates = cap[:: max(1, len(cap) // _STEEP_CANDIDATES)]
    cone = np.cos(np.radians(_STEEP_CONE_DEG))
    support = np.count_nonzero(candidates @ cap.T > cone, axis=1)
    strong = candidates[support >= needed]
    if not len(strong):
        return None
    seed = strong[int(np.argmax(strong[:, 2]))]
    direction: FloatArray = cap[cap @ seed > cone].mean(axis=0)
    direction /= np.linalg.norm(direction)
    if direction[2] > np.cos(np.radians(params.max_tilt_deg)):
        return None
    return _minimal_tilt_rotation(direction)


def _ransac_plane(
    points: FloatArray, distance: float, iterations: int, rng: np.random.Generator
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """The plane with most inliers among ``iterations`` random triples, refitted to its
    inliers by least squares: (unit normal, inlier mask).

    Our own seeded RANSAC rather than Open3D's, whose threads draw samples in a varying
    order: the same fragment must give the same frame on every run.
    """
    triples = points[rng.integers(0, len(points), size=(iterations, 3))]
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    length = np.linalg.norm(normals, axis=1)
    normals, triples = normals[length > 1e-12], triples[length > 1e-12]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    offsets = -np.einsum("ij,ij->i", normals, triples[:, 0])
    # Candidates are only ranked here, so single precision (twice the speed) is enough;
    # the winner's inliers are counted again in double precision below.
    homogeneous = np.column_stack([points, np.ones(len(points))]).astype(np.float32)
    planes = np.column_stack([normals, offsets]).astype(np.float32)
    counts = np.zeros(len(normals), dtype=np.int64)
    for lo in range(0, len(normals), _RANSAC_CHUNK):
        distances = homogeneous @ planes[lo : lo + _RANSAC_CHUNK].T
        counts[lo : lo + _RANSAC_CHUNK] = np.count_nonzero(np.abs(distances) < distance, axis=0)
    if len(counts) == 0:
        return np.array([0.0, 0.0, 1.0]), np.zeros(len(points), dtype=bool)
    best = int(np.argmax(counts))
    inliers = np.abs(points @ normals[best] + offsets[best]) < distance
    centre, normal = _fit_plane(points[inliers])
    return normal, np.abs((points - centre) @ normal) < distance


def _fit_plane(points: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Least-squares plane through (M, 3) points: (centre, unit normal, sign arbitrary)."""
    centre: FloatArray = points.mean(axis=0)
    normal: FloatArray = np.linalg.svd(points - centre, full_matrices=False)[2][-1]
    return centre, normal


def _estimate_up(
    normals: FloatArray,
    max_tilt_deg: float,
    start: FloatArray,
    level_axis: FloatArray | None = None,
) -> FloatArray:
    """Up axis: aligned with horizontal-surface normals, orthogonal to wall normals.

    When these leave up ambiguous within a plane (one wall family, no floor), it is the
    direction in that plane orthogonal to ``level_axis`` if given, else the closest to the
    current estimate.
    """
    up = start
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
        values, vectors = np.linalg.eigh(scatter)
        candidate = vectors[:, -1]
        if values[-1] - values[-2] < _DEGENERATE_GAP:
            # One wall family and no floor (a frame facing a single wall): any direction in
            # the wall plane fits, and eigh would pick one by noise.
            candidate = _in_plane(vectors[:, -2:], up, level_axis, candidate)
        candidate = candidate if candidate[2] >= 0 else -candidate
        if np.degrees(np.arccos(np.clip(candidate[2], -1.0, 1.0))) > max_tilt_deg:
            break
        up = candidate
    unit: FloatArray = up / np.linalg.norm(up)
    return unit


def _in_plane(
    plane: FloatArray, up: FloatArray, level_axis: FloatArray | None, fallback: FloatArray
) -> FloatArray:
    """The unit direction in the span of ``plane``'s two columns orthogonal to
    ``level_axis`` (a camera's x axis: its roll is small, its pitch is not), else the one
    closest to ``up``; ``fallback`` when neither is defined."""
    if level_axis is not None:
        coefficients = np.array([plane[:, 1] @ level_axis, -(plane[:, 0] @ level_axis)])
        if np.linalg.norm(coefficients) > 0.1:  # the plane does not hold the hint
            direction: FloatArray = plane @ coefficients
            direction /= np.linalg.norm(direction)
            return direction if direction @ up >= 0 else -direction
    projected: FloatArray = plane @ (plane.T @ up)
    length = float(np.linalg.norm(projected))
    return projected / length if length > 1e-6 else fallback


def _refine_up_on_floor(cloud: OrientedCloud, up: FloatArray) -> FloatArray:
    """Up as the normal of a least-squares plane through the floor, when enough is seen.

    Per-point normals are noisy; a plane through thousands of floor points is not. The
    band around the floor narrows as the plane fit improves (a tilted first guess would
    cut a wide floor off at its far side).
    """
    heights = cloud.points @ up
    flat = np.abs(cloud.normals @ up) > np.cos(np.radians(10.0))
    if flat.sum() < 200:
        return up
    floor, _ = _horizontal_levels(heights[flat], float(np.percentile(heights, 1.0)))
    normal, level = up, floor
    for band in (0.12, 0.05, 0.03):
        near = flat & (np.abs(cloud.points @ normal - level) < band)
        on_floor = cloud.points[near]
        if len(on_floor) < 1000 or np.linalg.eigvalsh(np.cov(on_floor.T))[1] < 0.5:
            return up  # too little floor, or a strip: a plane fit would not fix the tilt
        centre, fitted = _fit_plane(on_floor)
        normal = fitted if fitted @ up > 0 else -fitted
        level = float(centre @ normal)
    if np.degrees(np.arccos(np.clip(normal @ up, -1.0, 1.0))) > 5.0:
        return up  # the plane is not the floor the normals voted for
    refined: FloatArray = normal
    return refined


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
    support = 0.0
    # Narrowing windows: clutter at other angles stops pulling the mean.
    for window_deg in (20.0, 8.0, 4.0):
        near = np.abs(np.angle(np.exp(1j * (quad - peak)))) < np.radians(window_deg * 4.0)
        if near.sum() < 10:
            break
        peak = float(np.angle(np.exp(1j * quad[near]).mean()))
        support = support or float(near.mean())
    yaw = peak / 4.0
    yaw = (yaw + np.pi / 4) % (np.pi / 2) - np.pi / 4
    return yaw, support


def _sharpness(values: FloatArray, bin_size: float = 0.02) -> FloatArray:
    """Sum of squared histogram counts per column: large when the values pile up on few levels.

    values: (P, C) float64, one column per candidate rotation (all scored in one bincount
    rather than a Python loop over candidates). Two histograms half a bin apart are summed,
    so a level sitting on a bin edge scores like one in a bin's middle (no aliasing between
    nearby candidate rotations). Returns (C,) float64; zeros for no values.
    """
    n_cols = values.shape[1]
    total = np.zeros(n_cols)
    if len(values) == 0:
        return total
    scaled = values / bin_size
    for shift in (0.0, 0.5):
        idx = np.floor(scaled + shift).astype(np.int32)
        # One offset for all columns: the sum of squares does not depend on it.
        low = int(idx.min())
        width = int(idx.max()) - low + 1
        idx += (width * np.arange(n_cols, dtype=np.int32) - low)[None, :]
        counts = np.bincount(idx.ravel(), minlength=width * n_cols).reshape(n_cols, width)
        total += np.einsum("ij,ij->i", counts, counts).astype(np.float64)
    return total


def _sharpen_tilt(aligned: FloatArray, normals: FloatArray) -> FloatArray:
    """Small correction of the up axis that makes floor, ceiling and walls thinnest.

    A tilt about x smears horizontal surfaces along z as y grows and walls of constant y
    as z grows (likewise about y); both sharpen at the true up axis, and the lever is the
    whole extent of the scan rather than a normal's 15 cm neighbourhood.
    Returns a (3, 3) rotation to apply on the left of the current one.
    """
    pts = _subsample(aligned - aligned.mean(axis=0), _SHARPEN_POINTS)
    nrm = _subsample(normals, _SHARPEN_POINTS)
    flat = pts[np.abs(nrm[:, 2]) > np.cos(np.radians(10.0))]
    wall_x = pts[np.abs(nrm[:, 0]) > np.cos(np.radians(15.0))]
    wall_y = pts[np.abs(nrm[:, 1]) > np.cos(np.radians(15.0))]
    if len(flat) + len(wall_x) + len(wall_y) < 100:
        return np.eye(3)

    def best(alphas: FloatArray, betas: FloatArray, steps: FloatArray) -> float:
        """The step to the sharpest of the candidate (alpha, beta) pairs; of equals the
        smallest (a tilt the points do not see, as about a lone wall's normal, stays put)."""
        rot = _small_rotations(alphas, betas)  # (C, 3, 3)
        score = _sharpness(flat @ rot[:, 2].T) + _sharpness(wall_x @ rot[:, 0].T)
        score += _sharpness(wall_y @ rot[:, 1].T)
        ties = np.flatnonzero(score == score.max())
        return float(steps[ties[np.argmin(np.abs(steps[ties]))]])

    alpha = beta = 0.0
    # Coarse to fine: 0.1 degree steps over +-1 degree, then 0.01 over +-0.1.
    for steps in (
        np.radians(np.arange(-1.0, 1.0001, 0.1)),
        np.radians(np.arange(-0.1, 0.1001, 0.01)),
    ):
        fixed = np.ones_like(steps)
        for _ in range(2):
            alpha += best(alpha + steps, beta * fixed, steps)
            beta += best(alpha * fixed, beta + steps, steps)
    return _small_rotation(alpha, beta)


def _subsample(values: FloatArray, limit: int) -> FloatArray:
    """Every k-th row so at most about ``limit`` rows remain (deterministic)."""
    stride = max(1, len(values) // limit)
    sub: FloatArray = values[::stride]
    return sub


def _small_rotations(alpha: FloatArray, beta: FloatArray) -> FloatArray:
    """(C, 3, 3) rotations about x by alpha, then about y by beta (both (C,))."""
    ca, sa, cb, sb = np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta)
    zero, one = np.zeros_like(alpha), np.ones_like(alpha)
    rx = np.stack([one, zero, zero, zero, ca, -sa, zero, sa, ca], axis=1).reshape(-1, 3, 3)
    ry = np.stack([cb, zero, sb, zero, one, zero, -sb, zero, cb], axis=1).reshape(-1, 3, 3)
    out: FloatArray = ry @ rx
    return out


def _small_rotation(alpha: float, beta: float) -> FloatArray:
    """Rotation about x by alpha, then about y by beta."""
    out: FloatArray = _small_rotations(np.array([alpha]), np.array([beta]))[0]
    return out


def _sharpen_yaw(
    levelled_points: FloatArray, levelled_normals: FloatArray, yaw: float, span_deg: float = 1.5
) -> float:
    """Fine yaw: the angle at which wall points pile up in the sharpest x and y histograms.

    Walls project to thin lines only when the axes are exactly right, so the sum of squared
    histogram counts peaks there; it uses every wall point, not just their noisy normals.
    """
    walls = levelled_points[np.abs(levelled_normals[:, 2]) < np.sin(np.radians(15.0))][:, :2]
    if len(walls) < 50:
        return yaw
    walls = _subsample(walls - walls.mean(axis=0), _SHARPEN_POINTS)

    def score(angles: FloatArray) -> FloatArray:
        c, s = np.cos(angles), np.sin(angles)
        return _sharpness(walls @ np.stack([c, s])) + _sharpness(walls @ np.stack([-s, c]))

    best = yaw
    for step in (0.25, 0.025):
        span = span_deg if step > 0.1 else 0.35
        candidates = best + np.radians(np.arange(-span, span + 1e-9, step))
        best = float(candidates[int(np.argmax(score(candidates)))])
    return best


def _horizontal_levels(heights: FloatArray, floor_guess: float) -> tuple[float, float | None]:
    """Floor and ceiling heights from the heights of horizontal-surface points.

    The floor is the lowest strong peak of the height histogram, the ceiling the highest
    one well above it. Each is taken at the peak itself, not where the histogram first
    rises: with 2 cm noise the first strong bin lies a few centimetres low.
    """
    if len(heights) < 10:
        return floor_guess, None
    bin_size = 0.02
    lo, hi = float(heights.min()), float(heights.max())
    n_bins = max(1, int(np.ceil((hi - lo) / bin_size)) + 1)
    hist, edges = np.histogram(heights, bins=n_bins, range=(lo, lo + n_bins * bin_size))
    smooth = np.convolve(np.pad(hist, 1), np.ones(3), mode="valid")  # same length as hist
    strong = np.flatnonzero(smooth >= 0.15 * smooth.max())
    floor_bin = _climb(smooth, int(strong[0]), +1)
    floor = _refine_level(heights, float(edges[floor_bin] + bin_size / 2))
    high = strong[edges[strong] > floor + _MIN_CEILING_CLEARANCE]
    if not len(high):
        return floor, None
    ceiling_bin = _climb(smooth, int(high[-1]), -1)
    return floor, _refine_level(heights, float(edges[ceiling_bin] + bin_size / 2))


def _climb(values: FloatArray, index: int, step: int) -> int:
    """Walk from ``index`` in direction ``step`` while the values keep rising."""
    while 0 <= index + step < len(values) and values[index + step] >= values[index]:
        index += step
    return index


def _refine_level(heights: FloatArray, level: float) -> float:
    near = heights[np.abs(heights - level) < 0.04]
    return float(np.median(near)) if len(near) else level


def estimate_manhattan_frame(
    cloud: OrientedCloud,
    params: ManhattanParams = ManhattanParams(),
    level_axis: FloatArray | None = None,
) -> ManhattanFrame:
    """Estimate the rotation aligning a fragment to its Manhattan axes.

    Parameters
    ----------
    cloud : thinned fragment with normals (see :func:`thin_with_normals`), local frame.
    params : plane-search settings; ``max_tilt_deg`` bounds how far up may be from +z.
    level_axis : (3,) optional local direction known to be about level (an RGB-D camera's x
        axis); it settles the up axis when the walls alone leave it open (one wall, no floor).

    Returns
    -------
    ManhattanFrame
        ``rotation`` maps local to aligned coordinates: up becomes +z and the walls run
        along x and y. Of the four equivalent wall assignments the one closest to the
        local frame is chosen (yaw in [-45, 45) degrees), the minimal rotation.
    """
    if len(cloud.points) == 0:
        return ManhattanFrame(rotation=np.eye(3), floor_z=0.0, ceiling_z=None)
    plane = _floor_plane_normal(cloud, params)
    start = plane if plane is not None else np.array([0.0, 0.0, 1.0])
    up = _estimate_up(cloud.normals, params.max_tilt_deg, start, level_axis)
    up = _refine_up_on_floor(cloud, up)
    tilt = _minimal_tilt_rotation(up)
    levelled = cloud.normals @ tilt.T
    yaw, support = _estimate_yaw(levelled)
    yaw = _sharpen_yaw(cloud.points @ tilt.T, levelled, yaw)
    c, s = np.cos(-yaw), np.sin(-yaw)
    spin = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    rotation = spin @ tilt
    rotation = _sharpen_tilt(cloud.points @ rotation.T, cloud.normals @ rotation.T) @ rotation
    yaw_fix = _sharpen_yaw(cloud.points @ rotation.T, cloud.normals @ rotation.T, 0.0, 0.3)
    c, s = np.cos(-yaw_fix), np.sin(-yaw_fix)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ rotation
    aligned_z = cloud.points @ rotation[2]
    normal_z = np.abs(cloud.normals @ up)
    flat = aligned_z[normal_z > np.cos(np.radians(10.0))]
    floor, ceiling = _horizontal_levels(flat, float(np.percentile(aligned_z, 1.0)))
    if ceiling is not None and (
        np.mean(aligned_z > ceiling + _ABOVE_CEILING_MARGIN) > _MAX_ABOVE_CEILING
    ):
        ceiling = None
    return ManhattanFrame(rotation=rotation, floor_z=floor, ceiling_z=ceiling, wall_support=support)
