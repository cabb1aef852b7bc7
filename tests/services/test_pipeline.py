"""The orchestrator: place_site on generated scenes, poses against ground truth, edge cases."""

from __future__ import annotations

import numpy as np
import pytest

from schemas.layout import LocalLayoutWire
from schemas.params import PipelineParams, RegistrationParams
from schemas.result import ResultModel
from services.evaluation import evaluate_result
from services.pipeline import align_clouds, estimate_layout, place_site
from services.synthetic import ground_truth_json
from tests.conftest import small_scene

pytestmark = pytest.mark.timeout(300)


def _layouts(scene):
    return {f.id: estimate_layout(f.points) for f in scene.fragments}


def test_easy_scene_closes_with_accurate_poses():
    scene = small_scene("easy", 2, 40_000)
    result = place_site(_layouts(scene))
    ResultModel.model_validate(result.model_dump())
    assert result.status == "closed"
    report = evaluate_result(result.model_dump(mode="json"), ground_truth_json(scene))
    assert report.global_correct
    for fragment in result.fragments:
        pose = np.array(fragment.pose)
        assert np.allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3), atol=1e-9)
        assert np.linalg.det(pose[:3, :3]) == pytest.approx(1.0)
        assert pose[3].tolist() == [0, 0, 0, 1]
    polygon = np.array(result.floorplan.rooms[0].polygon)
    x, y = polygon[:, 0], polygon[:, 1]
    assert 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0  # counter-clockwise


def test_floor_is_at_zero_in_the_site_frame():
    scene = small_scene("easy", 2, 40_000)
    result = place_site(_layouts(scene))
    for fragment, truth in zip(result.fragments, scene.fragments, strict=True):
        pose = np.array(fragment.pose)
        floor_world = truth.pose @ np.array([0, 0, 0, 1.0])
        # A point on the true floor maps to z ~ 0 in the site frame.
        local_floor = np.linalg.inv(truth.pose) @ np.array([*floor_world[:2], 0.0, 1.0])
        assert (pose @ local_floor)[2] == pytest.approx(0.0, abs=0.05)


def test_single_fragment_is_open_and_placed():
    scene = small_scene("easy", 0)
    fragment = scene.fragments[0]
    result = place_site({fragment.id: estimate_layout(fragment.points)})
    assert result.status == "open"
    assert result.fragments[0].placed
    assert result.floorplan.rooms == []


def test_fragment_without_walls_is_reported_unplaced():
    scene = small_scene("easy", 0)
    rng = np.random.default_rng(0)
    floor = np.column_stack([rng.uniform(0, 3, 8000), rng.uniform(0, 3, 8000), np.zeros(8000)])
    layouts = _layouts(scene)
    layouts["floor_only"] = estimate_layout(floor)
    result = place_site(layouts)
    assert result.status == "open"
    by_id = {f.id: f for f in result.fragments}
    assert not by_id["floor_only"].placed
    assert by_id["floor_only"].loop_index is None
    assert by_id["floor_only"].local_layout.keypoints == []


def test_nothing_usable_fails_cleanly():
    rng = np.random.default_rng(0)
    floor = np.column_stack([rng.uniform(0, 3, 8000), rng.uniform(0, 3, 8000), np.zeros(8000)])
    result = place_site({"a": estimate_layout(floor)})
    assert result.status == "failed"
    assert result.fragments[0].placed is False


def test_layout_survives_the_wire_format():
    scene = small_scene("easy", 0)
    layout = estimate_layout(scene.fragments[0].points)
    back = LocalLayoutWire.model_validate_json(
        LocalLayoutWire.from_layout(layout).model_dump_json()
    ).to_layout()
    assert np.array_equal(back.keypoints, layout.keypoints)
    assert np.array_equal(back.source_boundary, layout.source_boundary)
    assert np.array_equal(back.footprint, layout.footprint)
    assert np.array_equal(back.frame.rotation, layout.frame.rotation)


def test_two_identical_fragments_give_a_defined_status():
    scene = small_scene("easy", 0)
    fragment = scene.fragments[0]
    layout = estimate_layout(fragment.points)
    result = place_site({"a": layout, "b": layout})
    assert result.status in ("open", "closed")
    assert {f.id for f in result.fragments} == {"a", "b"}
    ResultModel.model_validate(result.model_dump())


def test_non_manhattan_room_gives_a_defined_status():
    # A hexagonal room: walls at 60 degrees to each other.
    rng = np.random.default_rng(5)
    angles = np.radians(np.arange(0, 360, 60))
    corners = 4.0 * np.column_stack([np.cos(angles), np.sin(angles)])
    walls = []
    for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True):
        t = rng.uniform(0, 1, 6000)[:, None]
        walls.append(np.column_stack([a + t * (b - a), rng.uniform(0, 2.7, 6000)]))
    floor = rng.uniform(-3, 3, (20_000, 2))
    points = np.vstack([*walls, np.column_stack([floor, np.zeros(len(floor))])])
    halves = {"left": points[points[:, 0] < 0.2], "right": points[points[:, 0] > -0.2]}
    result = place_site({fid: estimate_layout(p) for fid, p in halves.items()})
    assert result.status in ("open", "closed", "failed")
    ResultModel.model_validate(result.model_dump())


def test_premerge_gives_every_input_fragment_a_pose():
    scene = small_scene("easy", 2, 40_000)
    first = scene.fragments[0]
    rng = np.random.default_rng(7)
    angle = 0.4
    moved = np.eye(4)
    moved[:3, :3] = [
        [np.cos(angle), -np.sin(angle), 0],
        [np.sin(angle), np.cos(angle), 0],
        [0, 0, 1],
    ]
    moved[:3, 3] = [1.5, -0.7, 0.2]
    subset = first.points[rng.random(len(first.points)) < 0.8]
    copy = subset @ moved[:3, :3].T + moved[:3, 3]  # the same scan, seen in another frame
    clouds = {f.id: f.points for f in scene.fragments}
    clouds["copy"] = copy
    params = PipelineParams(registration=RegistrationParams(voxel_size=0.1))
    result = align_clouds(clouds, params, premerge_overlapping=True)
    by_id = {f.id: f for f in result.fragments}
    assert set(by_id) == set(clouds)
    assert by_id["copy"].placed and by_id["copy"].pose is not None
    # copy-local -> first-local is inv(moved); both poses must agree on that.
    expected = np.array(by_id[first.id].pose) @ np.linalg.inv(moved)
    assert np.allclose(np.array(by_id["copy"].pose), expected, atol=0.05)
