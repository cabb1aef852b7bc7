"""Manhattan frame: up axis, wall yaw, floor and ceiling from tilted, cluttered fragments."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from schemas.params import ManhattanParams
from services import manhattan
from services.manhattan import (
    OrientedCloud,
    estimate_manhattan_frame,
    point_spacing,
    steep_floor_tilt,
    thin_with_normals,
    voxel_thin,
)
from tests.conftest import small_scene

pytestmark = pytest.mark.timeout(60)


def _rotation_error_deg(frame_rotation: np.ndarray, pose: np.ndarray) -> tuple[float, float]:
    """Tilt error of the estimated up and yaw error modulo 90 degrees."""
    up_local_true = pose[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    up_est = frame_rotation[2]
    tilt = np.degrees(np.arccos(np.clip(up_est @ up_local_true, -1, 1)))
    # Wall direction x of the aligned frame, mapped to the world, must be axis-parallel.
    x_world = pose[:3, :3] @ frame_rotation[0]
    yaw = np.degrees(np.arctan2(x_world[1], x_world[0])) % 90.0
    return float(tilt), float(min(yaw, 90.0 - yaw))


@pytest.mark.parametrize(("preset", "seed"), [("easy", 0), ("paper", 1), ("hard", 2)])
def test_frame_recovers_up_and_yaw(preset, seed):
    scene = small_scene(preset, seed)
    for fragment in scene.fragments:
        cloud = thin_with_normals(fragment.points, ManhattanParams())
        frame = estimate_manhattan_frame(cloud)
        tilt, yaw = _rotation_error_deg(frame.rotation, fragment.pose)
        assert tilt < 0.5, fragment.id
        assert yaw < 0.5, fragment.id
        assert np.allclose(frame.rotation @ frame.rotation.T, np.eye(3), atol=1e-9)
        assert np.linalg.det(frame.rotation) == pytest.approx(1.0)
        # Floor of the aligned frame equals the world floor (z = 0) mapped into it.
        floor_true = (frame.rotation @ np.linalg.inv(fragment.pose)[:3, 3])[2]
        assert frame.floor_z == pytest.approx(floor_true, abs=0.03)


def test_floor_only_fragment_keeps_a_valid_frame():
    rng = np.random.default_rng(0)
    floor = np.column_stack([rng.uniform(0, 4, 5000), rng.uniform(0, 3, 5000), np.zeros(5000)])
    floor += rng.normal(0, 0.01, floor.shape)
    frame = estimate_manhattan_frame(thin_with_normals(floor, ManhattanParams()))
    assert frame.rotation[2] @ np.array([0.0, 0.0, 1.0]) > np.cos(np.radians(1.0))
    assert frame.ceiling_z is None
    assert frame.floor_z == pytest.approx(0.0, abs=0.03)


def test_single_wall_without_floor_keeps_the_up_closest_to_the_start():
    # A frame facing one wall, pitched down 15 degrees, sees no floor: the wall fixes the
    # pitch, nothing fixes the roll about its normal, so up is the start (+z) projected
    # onto the wall plane rather than a direction in it picked by noise.
    rng = np.random.default_rng(3)
    pitch = np.radians(15.0)
    normal = np.array([np.cos(pitch), 0.0, np.sin(pitch)])
    up_true = np.array([-np.sin(pitch), 0.0, np.cos(pitch)])
    along, height = rng.uniform(-2.0, 2.0, 20_000), rng.uniform(-1.2, 1.2, 20_000)
    wall = 2.0 * normal + np.outer(along, [0.0, 1.0, 0.0]) + np.outer(height, up_true)
    wall += rng.normal(0.0, 0.005, wall.shape)
    frame = estimate_manhattan_frame(thin_with_normals(wall, ManhattanParams()))
    assert frame.rotation[2] @ up_true > np.cos(np.radians(1.0))
    # Seen obliquely, the roll about the wall's normal is open: a camera's x axis, known to
    # be about level, settles it (the level start alone would leave part of the pitch).
    yaw = np.radians(40.0)
    turn = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0, 0, 1]])
    pitch_down = np.array(
        [[1.0, 0, 0], [0, np.cos(pitch), np.sin(pitch)], [0, -np.sin(pitch), np.cos(pitch)]]
    )
    level = pitch_down @ turn  # world -> camera level frame (x right, y forward, z up)
    upright = np.array([0.0, 1.0, 0.0]) * 2.5  # a wall at y = 2.5 in the world, facing -y
    world = upright + np.column_stack([along, np.zeros_like(along), height])
    oblique = world @ level.T + rng.normal(0.0, 0.005, world.shape)
    cloud = thin_with_normals(oblique, ManhattanParams())
    hinted = estimate_manhattan_frame(cloud, ManhattanParams(), level_axis=np.array([1.0, 0, 0]))
    assert hinted.rotation[2] @ (level @ [0.0, 0.0, 1.0]) > np.cos(np.radians(1.0))


def test_empty_cloud_gives_identity():
    frame = estimate_manhattan_frame(thin_with_normals(np.zeros((0, 3)), ManhattanParams()))
    assert np.array_equal(frame.rotation, np.eye(3))


def test_same_fragment_same_frame():
    # The plane search is seeded and single-threaded: repeated runs agree to the bit.
    fragment = small_scene("paper", 5).fragments[0]
    frames = [
        estimate_manhattan_frame(thin_with_normals(fragment.points, ManhattanParams()))
        for _ in range(4)
    ]
    for frame in frames[1:]:
        assert np.array_equal(frame.rotation, frames[0].rotation)
        assert frame.floor_z == frames[0].floor_z


def test_voxel_thinning_keeps_open3ds_voxels_in_an_order_of_its_own():
    points = small_scene("paper", 5).fragments[0].points
    thinned = voxel_thin(points, 0.05)
    theirs = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)).voxel_down_sample(0.05)
    theirs_sorted = np.asarray(theirs.points)[np.lexsort(np.asarray(theirs.points).T)]
    assert np.allclose(thinned[np.lexsort(thinned.T)], theirs_sorted, atol=1e-12)
    shuffled = points[np.random.default_rng(0).permutation(len(points))]
    assert np.allclose(voxel_thin(shuffled, 0.05), thinned, atol=1e-12)  # same voxels, same order


@pytest.mark.parametrize(("n", "span"), [(300_000, 8.0), (2_000, 1.0), (3, 0.01), (1, 1.0)])
def test_voxels_counted_on_a_small_grid_are_the_sorted_ones(n, span, monkeypatch):
    # Grids about the size of the scan are thinned by counting, larger ones by sorting the
    # voxel keys: both give the same voxels in the same order, to the last bit.
    points = np.random.default_rng(n).uniform(0.0, span, (n, 3))
    counted = voxel_thin(points, 0.05)
    monkeypatch.setattr(manhattan, "_DENSE_GRID", 0)
    assert np.array_equal(voxel_thin(points, 0.05), counted)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_same_scan_in_another_point_order_gives_the_same_frame(seed):
    # The plane search samples thinned points by index: in open3d's voxel order, 105 of 287
    # fragments of the test split moved a keypoint over 1 mm when their points were shuffled.
    points = small_scene("paper", seed).fragments[0].points
    shuffled = points[np.random.default_rng(seed).permutation(len(points))]
    params = ManhattanParams()
    frame = estimate_manhattan_frame(thin_with_normals(points, params), params)
    other = estimate_manhattan_frame(thin_with_normals(shuffled, params), params)
    assert np.allclose(other.rotation, frame.rotation, atol=1e-12)
    assert other.floor_z == pytest.approx(frame.floor_z, abs=1e-12)


def test_a_voxel_cap_thins_a_wide_scan_coarser_and_keeps_its_normals():
    rng = np.random.default_rng(1)
    # A 6 x 6 m floor and a 6 x 2.5 m wall: about 21 000 voxels of 5 cm.
    floor = np.column_stack(
        [rng.uniform(0, 6, 200_000), rng.uniform(0, 6, 200_000), np.zeros(200_000)]
    )
    wall = np.column_stack(
        [rng.uniform(0, 6, 80_000), np.zeros(80_000), rng.uniform(0, 2.5, 80_000)]
    )
    points = np.vstack([floor, wall])
    whole = thin_with_normals(points, ManhattanParams())
    capped = thin_with_normals(points, ManhattanParams(), max_voxels=8_000)
    assert len(whole.points) > 15_000
    assert 6_000 < len(capped.points) <= 8_000
    # A cap the scan stays under changes nothing.
    same = thin_with_normals(points, ManhattanParams(), max_voxels=len(whole.points))
    np.testing.assert_array_equal(same.points, whole.points)
    # Away from the edge where they meet (the normals' neighbourhood grows with the voxel):
    on_floor = (capped.points[:, 2] < 0.01) & (capped.points[:, 1] > 0.5)
    assert np.all(np.abs(capped.normals[on_floor, 2]) > 0.99)
    on_wall = (capped.points[:, 1] < 0.01) & (capped.points[:, 2] > 0.5)
    assert np.all(np.abs(capped.normals[on_wall, 1]) > 0.99)


def test_points_of_a_sparse_scan_get_normals_of_their_own():
    # A 4 m x 2.5 m wall of 300 points, 8-9 cm apart (a thin scanner's cloud, or one
    # voxel-thinned before upload): with a radius of 3 voxels (15 cm) 42 % of its points had
    # fewer than two neighbours and were left pointing up, i.e. counted as floor.
    rng = np.random.default_rng(5)
    n = 300
    wall = np.column_stack([rng.uniform(0, 4, n), np.zeros(n), rng.uniform(0, 2.5, n)])
    wall[:, 1] += rng.normal(0.0, 0.005, n)
    cloud = thin_with_normals(wall, ManhattanParams())
    assert point_spacing(cloud.points) > 0.07
    facing_y = np.abs(cloud.normals[:, 1]) > np.cos(np.radians(25.0))
    assert facing_y.mean() > 0.85  # 55 % before
    # Poisson-scattered points: a few still stand alone in the radius, and are dropped
    # (16 % here; they were left pointing up, i.e. counted as floor).
    assert len(cloud.points) > 0.8 * n


def test_stray_points_are_dropped_not_read_as_floor():
    # A wall, its floor, and 2 % outliers scattered through the room's box: open3d left
    # the lone ones pointing up, so they read as floor seen behind the wall (a 1.8 m wall
    # of 60 000 points was then no wall at all) and voted for the frame's axes.
    rng = np.random.default_rng(3)
    wall = np.column_stack(
        [rng.uniform(0, 4, 40_000), np.zeros(40_000), rng.uniform(0, 2.6, 40_000)]
    )
    floor = np.column_stack(
        [rng.uniform(0, 4, 20_000), rng.uniform(0, 2, 20_000), np.zeros(20_000)]
    )
    strays = rng.uniform([0.0, -2.0, 0.0], [4.0, 2.0, 2.6], (1_200, 3))
    cloud = thin_with_normals(np.vstack([wall, floor, strays]), ManhattanParams())
    up = np.abs(cloud.normals[:, 2]) > 0.99
    behind = cloud.points[:, 1] < -0.1
    assert np.count_nonzero(up & behind) <= 3
    assert np.count_nonzero(behind) < 0.1 * len(strays)
    on_floor = (cloud.points[:, 2] < 0.02) & (cloud.points[:, 1] > 0.2)
    assert on_floor.sum() > 1_000 and np.all(up[on_floor])


def test_point_spacing_is_the_median_nearest_neighbour_distance():
    grid = np.stack(np.meshgrid(np.arange(30), np.arange(20), [0.0]), axis=-1).reshape(-1, 3)
    assert point_spacing(0.07 * grid) == pytest.approx(0.07)
    assert point_spacing(np.zeros((1, 3))) == 0.0


def _steep_view(floor_share: float, pitch_deg: float) -> OrientedCloud:
    """Normals of a camera's view (its level frame: x right, y forward, z up) pitched down
    by ``pitch_deg``: floor, the wall it faces and a side wall, with 2 degrees of noise."""
    pitch = np.radians(pitch_deg)
    floor = np.array([0.0, -np.sin(pitch), np.cos(pitch)])  # leans back, towards the camera
    facing = np.array([0.0, -np.cos(pitch), -np.sin(pitch)])  # faces the camera
    n = 2000
    counts = [int(floor_share * n), int(0.6 * n), n - int(floor_share * n) - int(0.6 * n)]
    rng = np.random.default_rng(1)
    directions = np.repeat([floor, facing, [1.0, 0.0, 0.0]], counts, axis=0)
    normals = directions + rng.normal(0.0, np.radians(2.0), directions.shape)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return OrientedCloud(rng.normal(0.0, 1.0, (n, 3)), normals)


@pytest.mark.parametrize("pitch", [35.0, 42.0])
def test_a_view_pitched_past_the_tilt_limit_is_levelled_on_its_floor(pitch):
    tilt = steep_floor_tilt(_steep_view(0.3, pitch), ManhattanParams(), 60.0)
    assert tilt is not None
    floor = np.array([0.0, -np.sin(np.radians(pitch)), np.cos(np.radians(pitch))])
    assert np.degrees(np.arccos((tilt @ floor)[2])) < 1.0


@pytest.mark.parametrize(("floor_share", "pitch"), [(0.3, 20.0), (0.05, 33.0), (0.3, 70.0)])
def test_other_views_are_left_to_the_usual_search(floor_share, pitch):
    # A floor within the tilt limit; a floor too small to find, where the wall the camera
    # faces (leaning forwards, 57 degrees from level up) must not be taken for it; a floor
    # past the steepest pitch levelled.
    assert steep_floor_tilt(_steep_view(floor_share, pitch), ManhattanParams(), 60.0) is None


def _corner_scan(wardrobe_top: bool, ceiling: bool) -> OrientedCloud:
    """Two walls 2.7 m high meeting at a corner, 1.5 m of floor before them, a 2 m high
    wardrobe's top 3 m long and a 2.7 m ceiling, each optional (the scan 2 cm noisy)."""
    rng = np.random.default_rng(4)

    def patch(n: int, lo: list[float], hi: list[float]) -> np.ndarray:
        return rng.uniform(lo, hi, (n, 3))

    parts = [
        patch(10000, [0.0, 1.5, 0.0], [4.0, 3.0, 0.0]),  # floor
        patch(15000, [0.0, 3.0, 0.0], [4.0, 3.0, 2.7]),  # wall along x
        patch(12000, [4.0, 0.0, 0.0], [4.0, 3.0, 2.7]),  # wall along y
    ]
    if wardrobe_top:
        parts.append(patch(5000, [0.5, 2.4, 2.0], [3.5, 3.0, 2.0]))
    if ceiling:
        parts.append(patch(8000, [0.0, 1.5, 2.7], [4.0, 3.0, 2.7]))
    points = np.vstack(parts) + rng.normal(0, 0.02 / 3, (sum(len(p) for p in parts), 3))
    return thin_with_normals(points, ManhattanParams())


@pytest.mark.parametrize(("wardrobe_top", "ceiling"), [(True, False), (True, True), (False, True)])
def test_a_ceiling_is_the_top_of_the_scan_not_a_surface_the_walls_rise_past(
    wardrobe_top: bool, ceiling: bool
) -> None:
    frame = estimate_manhattan_frame(_corner_scan(wardrobe_top, ceiling))
    if ceiling:
        assert frame.ceiling_z is not None
        assert frame.ceiling_z - frame.floor_z == pytest.approx(2.7, abs=0.05)
    else:
        # The wardrobe's top at 2 m with 0.7 m of wall above it all along: no ceiling.
        assert frame.ceiling_z is None
