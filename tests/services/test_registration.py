"""Tests for services.registration (FPFH + RANSAC + ICP, pre-merge, FPFH chain baseline).

The clouds are small self-made box rooms with furniture boxes (no dependency on the scene
generator), about 10-25k points each, so each pairwise registration takes a second or two.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from schemas.params import RegistrationParams
from services.registration import (
    PairRegistration,
    chain_baseline,
    premerge,
    register_all,
    register_pair,
)

pytestmark = pytest.mark.timeout(120)

PARAMS = RegistrationParams()


def _rect(rng, origin, u, v, density):
    n = max(int(np.linalg.norm(u) * np.linalg.norm(v) * density), 1)
    st = rng.random((n, 2))
    return np.asarray(origin, float) + st[:, :1] * u + st[:, 1:] * v


def _room(size, height, seed, density=200.0, n_boxes=6):
    """Floor, four walls and furniture boxes of an axis-aligned room, world frame, 5 mm noise."""
    rng = np.random.default_rng(seed)
    ex, ey, ez = np.diag([size[0], size[1], height])
    faces = [(0, ex, ey), (0, ex, ez), (ey, ex, ez), (0, ey, ez), (ex, ey, ez)]
    for _ in range(n_boxes):
        s = rng.uniform([0.4, 0.4, 0.4], [1.5, 1.2, 1.6])
        lo = np.array([*rng.uniform([0.2, 0.2], [size[0] - s[0] - 0.2, size[1] - s[1] - 0.2]), 0])
        bx, by, bz = np.diag(s)
        faces += [
            (lo + bz, bx, by),
            (lo, bx, bz),
            (lo + by, bx, bz),
            (lo, by, bz),
            (lo + bx, by, bz),
        ]
    pts = np.concatenate([_rect(rng, o + np.zeros(3), u, v, density) for o, u, v in faces])
    return pts + rng.normal(0.0, 0.005, pts.shape)


def _rigid(deg, t, axis=(0.0, 0.0, 1.0)):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    th = np.radians(deg)
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K
    T[:3, 3] = t
    return T


def _apply(T, p):
    return p @ T[:3, :3].T + T[:3, 3]


def _errors(T, truth):
    D = np.linalg.inv(truth) @ T
    angle = np.degrees(np.arccos(np.clip((np.trace(D[:3, :3]) - 1) / 2, -1, 1)))
    return angle, float(np.linalg.norm(T[:3, 3] - truth[:3, 3]))


G_A2 = _rigid(35.0, [1.0, -2.0, 0.3], axis=(0.1, 0.05, 1.0))  # room-1 world -> A2-local


@pytest.fixture(scope="module")
def clouds():
    """A: room 1, x < 6 (local = world). A2: room 1, x > 0.5, moved by G_A2 (A2 is larger).
    B: a different room, seen from its own frame; no overlap with A or A2."""
    room1 = _room((8.0, 5.0), 2.5, seed=1)
    room2 = _room((5.0, 3.5), 2.8, seed=101)
    return {
        "A": room1[room1[:, 0] < 6.0],
        "A2": _apply(G_A2, room1[room1[:, 0] > 0.5]),
        "B": _apply(_rigid(-70.0, [3.0, 1.0, 0.0]), room2[room2[:, 0] > 1.5]),
    }


@pytest.fixture(scope="module")
def pairs(clouds):
    return register_all(clouds, PARAMS)


def test_register_pair_recovers_known_transform(clouds):
    reg = register_pair(clouds["A2"], clouds["A"], PARAMS)
    angle, shift = _errors(reg.transform, np.linalg.inv(G_A2))  # A2-local -> A-local
    assert angle < 2.0
    assert shift < 0.05
    assert reg.inlier_ratio > 0.6
    assert 0.0 < reg.rmse < PARAMS.icp_distance_factor * PARAMS.voxel_size


def test_register_all_keys_follow_input_order_and_agree(clouds, pairs):
    assert list(pairs) == [("A", "A2"), ("A", "B"), ("A2", "B")]
    angle, shift = _errors(pairs[("A", "A2")].transform, G_A2)  # A-local -> A2-local
    assert angle < 2.0
    assert shift < 0.05


def test_disjoint_crops_have_low_inlier_ratio(pairs):
    assert pairs[("A", "B")].inlier_ratio < PARAMS.merge_inlier_ratio
    assert pairs[("A2", "B")].inlier_ratio < PARAMS.merge_inlier_ratio


def test_premerge_groups_overlapping_and_keeps_disjoint_apart(clouds, pairs):
    result = premerge(clouds, PARAMS, pairs=pairs)
    assert [(g.anchor_id, g.member_ids) for g in result.groups] == [
        ("A2", ("A", "A2")),
        ("B", ("B",)),
    ]
    merged, single = result.groups
    assert list(merged.transforms) == ["A", "A2"]
    np.testing.assert_array_equal(merged.transforms["A2"], np.eye(4))
    angle, shift = _errors(merged.transforms["A"], G_A2)  # A-local -> A2-local (anchor)
    assert angle < 2.0
    assert shift < 0.05
    np.testing.assert_array_equal(single.transforms["B"], np.eye(4))
    np.testing.assert_array_equal(single.points, clouds["B"])
    # merged cloud: anchor frame, covers both members, not denser than the originals
    gap, _ = cKDTree(merged.points).query(_apply(G_A2, clouds["A"]))
    assert np.median(gap) < 0.02
    assert len(merged.points) > 0.9 * max(len(clouds["A"]), len(clouds["A2"]))
    world = _apply(np.linalg.inv(G_A2), merged.points)
    in_overlap = [np.sum((p[:, 0] > 2.0) & (p[:, 0] < 4.0)) for p in (world, clouds["A"])]
    assert in_overlap[0] <= in_overlap[1]


def test_chain_baseline_first_id_is_identity(clouds, pairs):
    poses = chain_baseline(clouds, PARAMS, pairs=pairs)
    assert list(poses) == ["A", "A2", "B"]
    np.testing.assert_array_equal(poses["A"], np.eye(4))
    assert all(T.shape == (4, 4) for T in poses.values())
    angle, shift = _errors(poses["A2"], np.linalg.inv(G_A2))  # A2-local -> A-local (site)
    assert angle < 2.0
    assert shift < 0.05


def test_chain_baseline_without_pairs_is_deterministic(clouds, pairs):
    first = chain_baseline({k: clouds[k] for k in ("A", "A2")}, PARAMS)
    # equal up to round-off: Open3D's parallel ICP reductions are not bitwise reproducible
    expected = np.linalg.inv(pairs[("A", "A2")].transform)
    np.testing.assert_allclose(first["A2"], expected, rtol=0, atol=1e-9)


# --- fast tests on precomputed pairs (no registration) ------------------------------------


def _fake(T, ratio):
    return PairRegistration(T, ratio, 0.01)


def test_chain_baseline_composes_along_max_spanning_tree_and_splits_components():
    ids = ["p", "q", "r", "s"]
    clouds = {i: np.zeros((100, 3)) for i in ids}
    T_pq, T_qr, T_pr = _rigid(10, [1, 0, 0]), _rigid(20, [0, 1, 0]), _rigid(90, [5, 5, 5])
    pairs = {
        ("p", "q"): _fake(T_pq, 0.9),
        ("p", "r"): _fake(T_pr, 0.2),  # weaker than p-q-r: not in the tree
        ("q", "r"): _fake(T_qr, 0.8),
        ("p", "s"): _fake(np.eye(4), 0.0),  # failed: s is its own component
        ("q", "s"): _fake(np.eye(4), 0.0),
        ("r", "s"): _fake(np.eye(4), 0.0),
    }
    poses = chain_baseline(clouds, pairs=pairs)
    np.testing.assert_allclose(poses["q"], np.linalg.inv(T_pq))
    np.testing.assert_allclose(poses["r"], np.linalg.inv(T_pq) @ np.linalg.inv(T_qr))
    np.testing.assert_array_equal(poses["s"], np.eye(4))


def test_premerge_anchor_is_largest_and_threshold_is_strict():
    rng = np.random.default_rng(0)
    clouds = {"x": rng.random((50, 3)), "y": rng.random((80, 3)), "z": rng.random((60, 3))}
    T_xy = _rigid(30, [1, 2, 3])
    pairs = {
        ("x", "y"): _fake(T_xy, 0.61),
        ("x", "z"): _fake(np.eye(4), 0.6),  # not above the threshold
        ("y", "z"): _fake(np.eye(4), 0.1),
    }
    groups = premerge(clouds, RegistrationParams(merge_voxel_size=1e-4), pairs=pairs).groups
    assert [(g.anchor_id, g.member_ids) for g in groups] == [("y", ("x", "y")), ("z", ("z",))]
    np.testing.assert_allclose(groups[0].transforms["x"], T_xy)
    assert len(groups[0].points) == 130


def test_register_pair_too_few_points_fails_softly():
    reg = register_pair(np.zeros((3, 3)), np.random.default_rng(0).random((500, 3)))
    np.testing.assert_array_equal(reg.transform, np.eye(4))
    assert reg.inlier_ratio == 0.0
    assert reg.rmse == float("inf")
