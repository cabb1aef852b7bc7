"""Local layout end to end on generated scenes, and its degenerate inputs."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from schemas.params import LayoutParams, PipelineParams
from services.evaluation import acc_local, local_layout_correct
from services.local_layout import boundary_points, estimate_local_layout, footprint_cells
from tests.conftest import small_scene

pytestmark = pytest.mark.timeout(300)


def _accuracy(preset: str, seeds: range, params: PipelineParams = PipelineParams()) -> float:
    correct = []
    for seed in seeds:
        for fragment in small_scene(preset, seed, 60_000).fragments:
            layout = estimate_local_layout(fragment.points, params)
            correct.append(
                local_layout_correct(
                    layout.keypoints_local(), fragment.keypoints_local, fragment.diagonal
                )
            )
    return acc_local(correct)


def test_acc_local_on_easy_scenes():
    assert _accuracy("easy", range(4)) == 1.0


def test_acc_local_on_paper_like_scenes():
    assert _accuracy("paper", range(4)) >= 0.9


def test_papers_spanning_forest_rule_for_chain_ends_also_works():
    params = PipelineParams(layout=LayoutParams(source_target="spanning_forest"))
    assert _accuracy("paper", range(2), params) >= 0.85


def test_keypoints_run_with_the_interior_on_the_left():
    scene = small_scene("easy", 1)
    for fragment in scene.fragments:
        layout = estimate_local_layout(fragment.points)
        assert layout.ok
        kp = layout.keypoints
        # Each wall's left side must hold the fragment's footprint (scanned space).
        for a, b in itertools.pairwise(kp):
            direction = (b - a) / np.linalg.norm(b - a)
            left = np.array([-direction[1], direction[0]])
            middle = (a + b) / 2
            rel = layout.footprint - middle
            along, across = rel @ direction, rel @ left
            beside = np.abs(along) < 0.5 * np.linalg.norm(b - a)
            inside = np.sum(beside & (across > 0.3) & (across < 1.5))
            outside = np.sum(beside & (across < -0.3) & (across > -1.5))
            assert inside > 3 * outside


def test_floor_only_fragment_has_no_walls():
    rng = np.random.default_rng(3)
    floor = np.column_stack(
        [rng.uniform(0, 5, 20_000), rng.uniform(0, 4, 20_000), np.zeros(20_000)]
    )
    layout = estimate_local_layout(floor + rng.normal(0, 0.01, floor.shape))
    assert not layout.ok
    assert layout.keypoints.shape == (0, 2)
    assert layout.keypoints_local().shape == (0, 3)
    assert len(layout.footprint) > 0


def test_end_region_reaches_past_the_end_and_into_the_chain_and_is_capped():
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-2, 2, 50_000), rng.uniform(0, 3, 50_000), np.zeros(50_000)])
    # The chain runs towards +x from the end at the origin: 0.2 m past it, 0.5 m into it.
    region = boundary_points(pts, np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.2, 0.5)
    assert np.all((region[:, 0] > -0.2) & (region[:, 0] < 0.5))
    assert region[:, 0].min() < -0.15 and region[:, 0].max() > 0.45
    assert 0 < len(region) <= 4000


def test_footprint_ignores_isolated_outliers():
    rng = np.random.default_rng(1)
    dense = np.column_stack([rng.uniform(0, 1, 5000), rng.uniform(0, 1, 5000), np.zeros(5000)])
    outliers = np.array([[10.0, 10.0, 0.0], [-7.0, 3.0, 0.0]])
    cells = footprint_cells(np.vstack([dense, outliers]))
    assert np.all(cells < 1.5) and np.all(cells > -0.5)


def test_a_cloud_thinner_than_the_calibrations_is_a_thin_cloud():
    points = small_scene("easy", 0).fragments[0].points  # 30 000 or more
    assert estimate_local_layout(points).evidence == "cloud"
    thin = points[:: int(np.ceil(len(points) / 10_000))]
    assert estimate_local_layout(thin).evidence == "thin_cloud"
    trusting = PipelineParams(layout=LayoutParams(min_calibrated_points=0))
    assert estimate_local_layout(thin, trusting).evidence == "cloud"
