"""The paper's metrics: keypoint error, accuracies, robust alignment, layout error, IoU."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from services.evaluation import (
    acc_global,
    acc_local,
    align_to_ground_truth,
    evaluate_result,
    global_layout_correct,
    keypoint_error,
    layout_error,
    local_layout_correct,
    polygon_keypoint_error,
    pose_errors,
    room_iou,
    transform_polygon,
)
from services.synthetic import SceneSpec, generate_scene, ground_truth_json

pytestmark = pytest.mark.timeout(120)

SQUARE = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
L_SHAPE = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 3.0], [3.0, 3.0], [3.0, 5.0], [0.0, 5.0]])


def pose(yaw_deg: float, x: float, y: float, z: float = 0.0, tilt_deg: float = 0.0) -> np.ndarray:
    yaw, tilt = math.radians(yaw_deg), math.radians(tilt_deg)
    c, s = math.cos(yaw), math.sin(yaw)
    tilt_x = np.array(
        [[1, 0, 0], [0, math.cos(tilt), -math.sin(tilt)], [0, math.sin(tilt), math.cos(tilt)]]
    )
    result = np.eye(4)
    result[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ tilt_x
    result[:3, 3] = [x, y, z]
    return result


# ---------------------------------------------------------------- local metrics


def test_keypoint_error_exact_match_is_zero():
    k = np.array([[0.0, 0.0, 1.0], [2.0, 0.0, 1.0], [2.0, 3.0, 1.0]])
    assert keypoint_error(k, k) == 0.0
    assert keypoint_error(k[:, :2], k) == 0.0  # 2-D against 3-D compares x, y


def test_keypoint_error_pairs_in_order_when_counts_match():
    truth = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    shifted = truth + np.array([0.3, 0.4])
    assert keypoint_error(shifted, truth) == pytest.approx(0.5)
    reversed_chain = truth[::-1]
    assert keypoint_error(reversed_chain, truth) > 1.0  # source/target swapped is an error
    assert keypoint_error(reversed_chain, truth, ordered=False) == 0.0


def test_keypoint_error_unequal_counts_is_symmetric_nearest_neighbour():
    truth = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    extra = np.vstack([truth, [[2.0, 3.0]]])  # one spurious keypoint 1 m from the nearest
    assert keypoint_error(extra, truth) == pytest.approx(0.5 * (1.0 / 4 + 0.0))
    missing = truth[:2]  # the corner at (2, 2) is 2 m from the nearest estimate
    assert keypoint_error(missing, truth) == pytest.approx(0.5 * (0.0 + 2.0 / 3))
    rng = np.random.default_rng(0)
    for _ in range(5):
        assert keypoint_error(rng.permutation(extra), truth) == pytest.approx(0.125)


def test_keypoint_error_empty():
    assert keypoint_error(np.zeros((0, 3)), [[0.0, 0.0, 0.0]]) == math.inf
    assert keypoint_error([], [[0.0, 0.0]]) == math.inf
    with pytest.raises(ValueError):
        keypoint_error([[0.0, 0.0]], np.zeros((0, 2)))


def test_local_layout_correct_uses_five_percent_of_the_diagonal():
    truth = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [3.0, 4.0, 0.0]])
    assert local_layout_correct(
        truth + np.array([0.2, 0.0, 0.0]), truth, diagonal=5.0
    )  # 0.2 < 0.25
    assert not local_layout_correct(truth + np.array([0.3, 0.0, 0.0]), truth, diagonal=5.0)
    assert local_layout_correct(
        truth + np.array([0.3, 0.0, 0.0]), truth, diagonal=5.0, threshold=0.1
    )
    assert not local_layout_correct(np.zeros((0, 3)), truth, diagonal=5.0)


def test_accuracies():
    assert acc_local([True, True, False, True]) == 0.75
    assert acc_global([False]) == 0.0
    assert math.isnan(acc_local([]))


# ---------------------------------------------------------------- alignment and poses


def random_site(seed: int, n: int = 6):
    """True poses, the same fragments in an arbitrary site frame, and that frame."""
    rng = np.random.default_rng(seed)
    true = {
        f"f{k}": pose(
            rng.uniform(0, 360), rng.uniform(-8, 8), rng.uniform(-8, 8), 0.0, rng.uniform(0, 3)
        )
        for k in range(n)
    }
    site_to_world = pose(rng.uniform(0, 360), *rng.uniform(-20, 20, 2))
    est = {i: np.linalg.inv(site_to_world) @ p for i, p in true.items()}
    refs = {i: rng.uniform(-3, 3, 3) for i in true}
    return true, est, site_to_world, refs


@pytest.mark.parametrize("seed", range(5))
def test_alignment_recovers_the_site_frame(seed):
    true, est, site_to_world, refs = random_site(seed)
    alignment = align_to_ground_truth(est, true, refs)
    assert np.allclose(alignment, site_to_world, atol=1e-9)
    errors = pose_errors(est, true, alignment, diagonal=10.0, reference_points=refs)
    assert set(errors) == set(true)
    assert all(e.rotation_deg < 1e-6 and e.translation_pct < 1e-6 for e in errors.values())


@pytest.mark.parametrize("seed", range(5))
def test_alignment_ignores_one_badly_placed_fragment(seed):
    true, est, site_to_world, refs = random_site(seed)
    est["f0"] = pose(90.0, 3.0, 0.0) @ est["f0"]  # rotated and shifted in the site frame
    alignment = align_to_ground_truth(est, true, refs)
    assert np.allclose(alignment, site_to_world, atol=1e-9)
    errors = pose_errors(est, true, alignment, diagonal=10.0, reference_points=refs)
    assert errors["f0"].rotation_deg == pytest.approx(90.0, abs=1e-6)
    assert errors["f0"].translation_pct > 1.0
    assert all(errors[i].translation_pct < 1e-6 for i in true if i != "f0")


def test_alignment_is_robust_to_noise_and_uses_only_shared_ids():
    true, est, site_to_world, refs = random_site(1, n=8)
    rng = np.random.default_rng(3)
    noisy = {i: pose(rng.normal(0, 0.5), *rng.normal(0, 0.02, 2)) @ p for i, p in est.items()}
    noisy["only_estimated"] = np.eye(4)
    alignment = align_to_ground_truth(noisy, true, refs)
    assert (
        abs(
            math.degrees(math.atan2(alignment[1, 0], alignment[0, 0]))
            - math.degrees(math.atan2(site_to_world[1, 0], site_to_world[0, 0]))
        )
        < 1.0
    )
    with pytest.raises(ValueError):
        align_to_ground_truth({"a": np.eye(4)}, {"b": np.eye(4)})


def test_pose_errors_measure_tilt_and_reference_point():
    true = {"a": pose(0.0, 0.0, 0.0)}
    est = {"a": pose(0.0, 0.0, 0.0, tilt_deg=4.0)}
    errors = pose_errors(
        est, true, np.eye(4), diagonal=10.0, reference_points={"a": np.array([0.0, 0.0, 1.0])}
    )
    assert errors["a"].rotation_deg == pytest.approx(4.0)
    # The reference point 1 m above the origin moves by 2 sin(2 deg) m.
    expected = 100 * 2 * math.sin(math.radians(2.0)) / 10.0
    assert errors["a"].translation_pct == pytest.approx(expected)


# ---------------------------------------------------------------- layout metrics


def test_layout_error_zero_for_identical_and_known_for_shift():
    assert layout_error(L_SHAPE, L_SHAPE, 10.0) == pytest.approx((0.0, 0.0), abs=1e-9)
    assert layout_error(np.roll(L_SHAPE, 2, axis=0), L_SHAPE, 10.0) == pytest.approx(
        (0.0, 0.0), abs=1e-9
    )
    mean, worst = layout_error(SQUARE + np.array([0.1, 0.0]), SQUARE, diagonal=10.0)
    # Left and right walls are 0.1 m off; the first 0.1 m of the top and bottom walls are
    # (0.1 - x) off: the mean is (0.8 + 0.01) / 16 m.
    assert mean == pytest.approx(100 * (0.81 / 16) / 10.0, rel=0.02)
    assert worst == pytest.approx(1.0)
    assert layout_error(np.zeros((0, 2)), SQUARE, 10.0) == (math.inf, math.inf)


def test_room_iou():
    assert room_iou(L_SHAPE, L_SHAPE) == 1.0
    assert room_iou(SQUARE, SQUARE + np.array([2.0, 0.0])) == pytest.approx(1 / 3, abs=0.005)
    assert room_iou(SQUARE, SQUARE + np.array([10.0, 0.0])) == 0.0
    assert room_iou(SQUARE, SQUARE * 0.5) == pytest.approx(0.25, abs=0.005)
    assert room_iou(np.zeros((0, 2)), SQUARE) == 0.0


def test_polygon_keypoint_error_and_global_correctness():
    assert polygon_keypoint_error(np.roll(L_SHAPE, 3, axis=0), L_SHAPE) == 0.0
    assert global_layout_correct(np.roll(L_SHAPE, 1, axis=0), L_SHAPE, diagonal=7.8)
    assert not global_layout_correct(L_SHAPE + np.array([1.0, 0.0]), L_SHAPE, diagonal=7.8)
    simpler = L_SHAPE[[0, 1, 2, 5]].copy()  # the notch missed: a 6 x 5 rectangle
    simpler[2] = [6.0, 5.0]
    assert polygon_keypoint_error(simpler, L_SHAPE) > 0.5


def test_transform_polygon():
    moved = transform_polygon(SQUARE, pose(90.0, 1.0, 2.0))
    assert np.allclose(moved[1], [1.0, 6.0])


# ---------------------------------------------------------------- whole result


def perfect_result(scene, site_to_world: np.ndarray) -> dict[str, Any]:
    to_site = np.linalg.inv(site_to_world)
    return {
        "schema_version": 1,
        "status": "closed",
        "fragments": [
            {
                "id": f.id,
                "placed": True,
                "pose": (to_site @ f.pose).tolist(),
                "loop_index": f.loop_index,
                "local_layout": {"keypoints": f.keypoints_local.tolist()},
            }
            for f in scene.fragments
        ],
        "floorplan": {
            "rooms": [
                {"id": "room_0", "polygon": transform_polygon(scene.polygon, to_site).tolist()}
            ]
        },
    }


def test_evaluate_result_perfect_and_broken():
    scene = generate_scene(replace(SceneSpec.easy(), points_per_fragment=(2_000, 2_000)), 3)
    truth = ground_truth_json(scene)
    site = pose(37.0, -4.0, 11.0)
    report = evaluate_result(perfect_result(scene, site), truth)
    assert all(report.local_correct.values())
    assert report.global_correct
    assert report.alignment is not None and np.allclose(report.alignment, site)
    assert max(e.translation_pct for e in report.pose_errors.values()) < 1e-6
    assert report.layout_error_pct is not None and report.layout_error_pct[1] < 1e-6
    assert report.iou == pytest.approx(1.0)

    broken = perfect_result(scene, site)
    broken["fragments"][0]["local_layout"]["keypoints"] = []
    broken["floorplan"]["rooms"] = []
    report = evaluate_result(broken, truth)
    assert not report.local_correct[scene.fragments[0].id]
    assert not report.global_correct and report.iou is None

    unplaced = {"status": "failed", "fragments": []}
    report = evaluate_result(unplaced, truth)
    assert not any(report.local_correct.values()) and report.alignment is None
