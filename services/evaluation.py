"""The paper's evaluation metrics (section 4, "Evaluation metrics"), on numpy arrays.

Local metrics compare a fragment's estimated wall keypoints with the true ones in the
fragment's local frame. Global metrics first bring the estimated site frame (whose origin and
yaw are arbitrary) onto the world frame with a robust rigid alignment, then compare poses,
the room polygon and its area. "Diagonal" is always the XY bounding-box diagonal the paper
normalises by: the fragment's for local metrics, the room's for global ones.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from services.geometry import points_in_polygon
from services.types import FloatArray

__all__ = [
    "PoseError",
    "SceneReport",
    "acc_global",
    "acc_local",
    "align_to_ground_truth",
    "evaluate_result",
    "global_layout_correct",
    "keypoint_error",
    "layout_error",
    "local_layout_correct",
    "polygon_keypoint_error",
    "pose_errors",
    "room_iou",
    "transform_polygon",
]

# --------------------------------------------------------------------------------------------
# Local metrics
# --------------------------------------------------------------------------------------------


def keypoint_error(estimated: ArrayLike, truth: ArrayLike, *, ordered: bool = True) -> float:
    """Mean distance between estimated and true keypoints, meters.

    estimated: (K1, 2 or 3); truth: (K2, 2 or 3), same frame. When one is 2-D and the other
    3-D only x, y are compared. With equal counts and ``ordered`` (keypoints run source to
    target, so index i matches index i) it is the mean of the pairwise distances. Otherwise
    it is the symmetric mean nearest-neighbour distance: the average of "each estimate to
    its nearest truth" and "each truth to its nearest estimate", so both missing and extra
    keypoints cost. An empty estimate gives inf.

    >>> keypoint_error([[0.0, 0.0], [1.0, 0.0]], [[0.0, 0.0], [1.0, 1.0]])
    0.5
    >>> keypoint_error(np.zeros((0, 2)), [[0.0, 0.0]])
    inf
    """
    est, true = _as_points(estimated), _as_points(truth)
    if len(true) == 0:
        raise ValueError("the true keypoints are empty")
    if len(est) == 0:
        return math.inf
    dims = min(est.shape[1], true.shape[1])
    est, true = est[:, :dims], true[:, :dims]
    if ordered and len(est) == len(true):
        return float(np.mean(np.linalg.norm(est - true, axis=1)))
    distances = np.linalg.norm(est[:, None, :] - true[None, :, :], axis=2)
    return 0.5 * float(distances.min(axis=1).mean() + distances.min(axis=0).mean())


def local_layout_correct(
    est_keypoints_local: ArrayLike,
    true_keypoints_local: ArrayLike,
    diagonal: float,
    threshold: float = 0.05,
) -> bool:
    """Paper: a local layout is correct when its mean keypoint error is below 5 % of the
    fragment's bounding-box diagonal."""
    return keypoint_error(est_keypoints_local, true_keypoints_local) < threshold * diagonal


def acc_local(correct: Sequence[bool]) -> float:
    """ACC_local: fraction (0..1) of correct local layouts; nan for no fragments."""
    return float(np.mean(correct)) if len(correct) else math.nan


def acc_global(correct: Sequence[bool]) -> float:
    """ACC_global: fraction (0..1) of scenes with a correct global placement; nan for none."""
    return float(np.mean(correct)) if len(correct) else math.nan


# --------------------------------------------------------------------------------------------
# Global metrics
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PoseError:
    """One fragment's pose error after alignment: rotation angle in degrees (3-D, so tilt
    counts), translation in percent of the room diagonal."""

    rotation_deg: float
    translation_pct: float


def align_to_ground_truth(
    est_poses: Mapping[str, FloatArray],
    true_poses: Mapping[str, FloatArray],
    reference_points: Mapping[str, FloatArray] | None = None,
    *,
    distance_tolerance: float = 0.5,
    angle_tolerance_deg: float = 10.0,
) -> FloatArray:
    """The (4, 4) site -> world transform (yaw about z plus x, y shift) that best maps the
    estimated poses onto the true ones: ``true ~ T @ est``.

    est_poses, true_poses: fragment id -> (4, 4) local -> site / world; only shared ids
    count. reference_points: id -> (3,) fragment-local point whose two placements are
    compared (default the local origin; the centroid of the fragment's points is better).
    Each fragment proposes the transform that aligns it exactly; the proposal that the most
    fragments agree with (reference point within ``distance_tolerance`` m and yaw within
    ``angle_tolerance_deg``; ties broken by the lower median distance) wins and is refined
    on its agreeing fragments, so one badly placed fragment cannot drag the others.
    """
    ids = sorted(set(est_poses) & set(true_poses))
    if not ids:
        raise ValueError("no fragment has both an estimated and a true pose")
    refs = [np.append(_reference(reference_points, i), 1.0) for i in ids]
    est_xy = np.array([(est_poses[i] @ r)[:2] for i, r in zip(ids, refs, strict=True)])
    true_xy = np.array([(true_poses[i] @ r)[:2] for i, r in zip(ids, refs, strict=True)])
    yaws = np.array([_yaw(true_poses[i][:3, :3] @ est_poses[i][:3, :3].T) for i in ids])
    best = (-1, -math.inf)  # (agreeing fragments, -median distance): larger is better
    inliers = np.zeros(len(ids), dtype=bool)
    for k in range(len(ids)):
        shift = true_xy[k] - _rot2(yaws[k]) @ est_xy[k]
        distance = np.linalg.norm(est_xy @ _rot2(yaws[k]).T + shift - true_xy, axis=1)
        angle = np.abs(_wrap(yaws - yaws[k]))
        agree = (distance < distance_tolerance) & (angle < math.radians(angle_tolerance_deg))
        score = (int(agree.sum()), -float(np.median(distance)))
        if score > best:
            best, inliers = score, agree
    yaw = float(np.angle(np.mean(np.exp(1j * yaws[inliers]))))  # circular mean
    shift = np.mean(true_xy[inliers] - est_xy[inliers] @ _rot2(yaw).T, axis=0)
    transform = np.eye(4)
    transform[:2, :2], transform[:2, 3] = _rot2(yaw), shift
    return transform


def pose_errors(
    est_poses: Mapping[str, FloatArray],
    true_poses: Mapping[str, FloatArray],
    alignment: FloatArray,
    diagonal: float,
    reference_points: Mapping[str, FloatArray] | None = None,
) -> dict[str, PoseError]:
    """Per-fragment rotation and translation error of ``alignment @ est`` against the truth.

    The translation error is the distance between the two placements of the fragment's
    reference point (default the local origin; pass the centroid of the fragment's true
    points, ``SyntheticFragment.centroid_local``, as the paper's "translation" of a
    fragment), in percent of ``diagonal``. Only ids in both mappings are reported.
    """
    errors = {}
    for i in sorted(set(est_poses) & set(true_poses)):
        placed, true = alignment @ est_poses[i], true_poses[i]
        ref = np.append(_reference(reference_points, i), 1.0)
        gap = float(np.linalg.norm((placed @ ref - true @ ref)[:3]))
        errors[i] = PoseError(
            rotation_deg=math.degrees(_angle(true[:3, :3].T @ placed[:3, :3])),
            translation_pct=100.0 * gap / diagonal,
        )
    return errors


def transform_polygon(polygon: ArrayLike, transform: FloatArray) -> FloatArray:
    """Apply a (4, 4) transform's x, y part to a (V, 2) polygon."""
    points = _as_points(polygon)[:, :2]
    return points @ transform[:2, :2].T + transform[:2, 3]


def layout_error(
    est_polygon: ArrayLike, true_polygon: ArrayLike, diagonal: float, spacing: float = 0.02
) -> tuple[float, float]:
    """Layout reconstruction error (paper Table 3): mean and max distance, in percent of
    ``diagonal``, from points sampled every ``spacing`` m on the true walls to the nearest
    estimated wall. Both polygons (V, 2) in the same frame; (inf, inf) without an estimate.

    >>> square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
    >>> layout_error(square, square, 10.0)
    (0.0, 0.0)
    """
    est, true = _as_points(est_polygon)[:, :2], _as_points(true_polygon)[:, :2]
    if len(est) < 2:
        return math.inf, math.inf
    samples = _sample_boundary(true, spacing)
    distance = _distance_to_boundary(samples, est)
    return 100.0 * float(distance.mean()) / diagonal, 100.0 * float(distance.max()) / diagonal


def room_iou(est_polygon: ArrayLike, true_polygon: ArrayLike, cell: float = 0.02) -> float:
    """Intersection over union of two polygons' areas, rasterised on a ``cell`` grid.

    >>> a = [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]]
    >>> round(room_iou(a, [[1.0, 0.0], [3.0, 0.0], [3.0, 2.0], [1.0, 2.0]]), 3)
    0.333
    """
    est, true = _as_points(est_polygon)[:, :2], _as_points(true_polygon)[:, :2]
    if len(est) < 3 or len(true) < 3:
        return 0.0
    both = np.vstack([est, true])
    lo, hi = both.min(axis=0), both.max(axis=0)
    xs = np.arange(lo[0] + cell / 2, hi[0], cell)
    intersection = union = 0
    for y in np.arange(lo[1] + cell / 2, hi[1], cell * 256):  # bands of rows bound memory
        rows = np.arange(y, min(y + cell * 256, hi[1]), cell)
        gx, gy = np.meshgrid(xs, rows)
        centres = np.column_stack([gx.ravel(), gy.ravel()])
        in_est, in_true = points_in_polygon(centres, est), points_in_polygon(centres, true)
        intersection += int(np.count_nonzero(in_est & in_true))
        union += int(np.count_nonzero(in_est | in_true))
    return intersection / union if union else 0.0


def polygon_keypoint_error(est_polygon: ArrayLike, true_polygon: ArrayLike) -> float:
    """Keypoint error between two closed polygons (same frame), meters.

    Polygons have no natural first vertex: with equal vertex counts it is the smallest mean
    pairwise distance over cyclic shifts, otherwise the symmetric nearest-neighbour error
    of :func:`keypoint_error`.
    """
    est, true = _as_points(est_polygon)[:, :2], _as_points(true_polygon)[:, :2]
    if len(est) != len(true) or len(est) == 0:
        return keypoint_error(est, true, ordered=False)
    return min(keypoint_error(np.roll(est, k, axis=0), true) for k in range(len(est)))


def global_layout_correct(
    est_polygon_world: ArrayLike,
    true_polygon: ArrayLike,
    diagonal: float,
    threshold: float = 0.05,
) -> bool:
    """Paper: a global layout (and so the placement behind it) is correct when its mean
    keypoint error is below 5 % of the room diagonal. The estimate must already be in the
    world frame (see :func:`align_to_ground_truth`, :func:`transform_polygon`)."""
    return polygon_keypoint_error(est_polygon_world, true_polygon) < threshold * diagonal


# --------------------------------------------------------------------------------------------
# Whole result against ground truth (both as JSON-able dicts)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SceneReport:
    """Every metric for one scene. Global fields are None when nothing was placed / closed.

    local_errors: id -> mean keypoint error, m (inf when the estimate is empty).
    layout_error_pct: (mean, max) in percent of the room diagonal.
    """

    local_correct: dict[str, bool]
    local_errors: dict[str, float]
    global_correct: bool
    alignment: FloatArray | None
    pose_errors: dict[str, PoseError]
    layout_error_pct: tuple[float, float] | None
    iou: float | None


def evaluate_result(result: Mapping[str, Any], truth: Mapping[str, Any]) -> SceneReport:
    """Score a result JSON (contract section 3) against a ground-truth JSON (as written by
    :func:`services.synthetic.ground_truth_json`). Pure: takes already-parsed dicts."""
    true_frags = {f["id"]: f for f in truth["fragments"]}
    est_frags = {f["id"]: f for f in result.get("fragments", []) if f["id"] in true_frags}
    local_errors = {
        i: keypoint_error(
            np.asarray(est_frags[i]["local_layout"]["keypoints"]) if i in est_frags else [],
            np.asarray(true_frags[i]["keypoints_local"]),
        )
        for i in true_frags
    }
    local_correct = {i: e < 0.05 * true_frags[i]["diagonal"] for i, e in local_errors.items()}
    est_poses = {
        i: np.asarray(f["pose"], dtype=np.float64)
        for i, f in est_frags.items()
        if f.get("placed") and f.get("pose") is not None
    }
    if not est_poses:
        return SceneReport(local_correct, local_errors, False, None, {}, None, None)
    true_poses = {i: np.asarray(f["pose"], dtype=np.float64) for i, f in true_frags.items()}
    refs = {i: np.asarray(f["centroid_local"], dtype=np.float64) for i, f in true_frags.items()}
    alignment = align_to_ground_truth(est_poses, true_poses, refs)
    diagonal = float(truth["diagonal"])
    errors = pose_errors(est_poses, true_poses, alignment, diagonal, refs)
    rooms = result.get("floorplan", {}).get("rooms", [])
    true_polygon = np.asarray(truth["room"]["polygon"], dtype=np.float64)
    if not rooms or len(rooms[0].get("polygon", [])) < 3:
        return SceneReport(local_correct, local_errors, False, alignment, errors, None, None)
    polygon = transform_polygon(rooms[0]["polygon"], alignment)
    return SceneReport(
        local_correct=local_correct,
        local_errors=local_errors,
        global_correct=global_layout_correct(polygon, true_polygon, diagonal),
        alignment=alignment,
        pose_errors=errors,
        layout_error_pct=layout_error(polygon, true_polygon, diagonal),
        iou=room_iou(polygon, true_polygon),
    )


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------


def _as_points(points: ArrayLike) -> FloatArray:
    array = np.asarray(points, dtype=np.float64)
    return array.reshape(0, 2) if array.size == 0 else array.reshape(len(array), -1)


def _reference(points: Mapping[str, FloatArray] | None, fragment_id: str) -> FloatArray:
    if points is None or fragment_id not in points:
        return np.zeros(3)
    return np.asarray(points[fragment_id], dtype=np.float64)[:3]


def _yaw(rotation: FloatArray) -> float:
    """Angle of the 2-D rotation closest to the x, y block of a 3x3 rotation."""
    return math.atan2(rotation[1, 0] - rotation[0, 1], rotation[0, 0] + rotation[1, 1])


def _angle(rotation: FloatArray) -> float:
    """Rotation angle of a 3x3 rotation, radians; atan2 keeps small angles accurate."""
    r = rotation
    sine = 0.5 * math.hypot(r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1])
    return math.atan2(sine, (np.trace(r) - 1.0) / 2.0)


def _rot2(angle: float) -> FloatArray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def _wrap(angle: FloatArray) -> FloatArray:
    return np.mod(angle + np.pi, 2 * np.pi) - np.pi


def _sample_boundary(polygon: FloatArray, spacing: float) -> FloatArray:
    """Points every ``spacing`` along the closed polygon (each edge from its start)."""
    parts = []
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
        length = float(np.linalg.norm(b - a))
        t = np.arange(0.0, length, spacing) / max(length, 1e-12)
        parts.append(a + t[:, None] * (b - a))
    return np.vstack(parts)


def _distance_to_boundary(points: FloatArray, polygon: FloatArray) -> FloatArray:
    """Distance from (M, 2) points to the nearest edge of a closed polygon."""
    best = np.full(len(points), np.inf)
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
        d = b - a
        squared_length = float(d @ d)
        t = np.zeros(len(points))
        if squared_length > 0.0:  # repeated vertices give zero-length edges
            t = np.clip((points - a) @ d / squared_length, 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(points - a - t[:, None] * d, axis=1))
    return best
