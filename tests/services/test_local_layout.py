"""Local layout end to end on generated scenes, and its degenerate inputs."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from schemas.params import LayoutParams, PipelineParams
from services.evaluation import acc_local, local_layout_correct
from services.local_layout import (
    boundary_points,
    estimate_local_layout,
    footprint_cells,
    unchained_walls,
)
from services.synthetic.scene import SceneSpec, generate_scene
from services.wall_lines import WallLine
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


def test_a_thin_cloud_of_a_large_room_is_read_on_cells_as_wide_as_its_points_lie_apart():
    # 8 600 points over a 17 m room, 8 cm apart, so an 8 cm column of a wall holds a
    # few points at most and its run broke into short pieces (the chain was 3.0 m off; 5 %
    # of the fragment's diagonal is 0.85 m, and the wider cells leave it 0.28 m off).
    spec = dataclasses.replace(
        SceneSpec.world(),
        n_fragments_range=(2, 3),
        points_per_fragment=(8_000, 15_000),
        size_range=((2.0, 5.0), (18.0, 20.0)),  # the preset's rooms until 2026-12-05
        no_ceiling_share=0.0,
    )
    fragment = generate_scene(spec, 7018).fragments[1]
    layout = estimate_local_layout(fragment.points)
    assert layout.evidence == "thin_cloud"
    assert local_layout_correct(
        layout.keypoints_local(), fragment.keypoints_local, fragment.diagonal
    )


def _high_line(axis: int, offset: float, start: float, stop: float) -> WallLine:
    """A line whose cells (0.08 m) are high from run ``start`` to ``stop``."""
    high = np.zeros(100, dtype=bool)
    high[round(start / 0.08) : round(stop / 0.08)] = True
    return WallLine(axis, offset, 1, 0.0, 0.08, high, np.array([[start, stop]]))


def test_unchained_walls_are_the_wall_cells_off_the_chain():
    chain = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]])
    lines = [
        _high_line(0, 0.05, 0.0, 4.0),  # the chain's bottom wall (5 cm off: the same wall)
        _high_line(1, 4.0, 0.0, 3.0),  # its right wall
        _high_line(1, 2.0, 0.8, 1.6),  # a fin's face standing in the room: off the chain
    ]
    tops = np.column_stack([np.full(200, 2.02), np.linspace(0.0, 3.0, 200)])  # walls' tops
    cells = unchained_walls(lines, chain, tops, LayoutParams())
    assert len(cells) == 10
    assert np.all(cells[:, 0] == 2.0)
    assert cells[:, 1].min() == pytest.approx(0.84) and cells[:, 1].max() == pytest.approx(1.56)
    assert len(unchained_walls(lines[:2], chain, tops, LayoutParams())) == 0
    # Without wall points just under the ceiling there, it is tall furniture, not a wall;
    # a stray point or two there (an outlier, a noisy normal) does not make it one.
    beside = tops[tops[:, 1] < 0.7]
    assert len(unchained_walls(lines, chain, beside, LayoutParams())) == 0
    strays = np.vstack([beside, [[2.0, 1.2], [2.01, 1.21]]])
    assert len(unchained_walls(lines, chain, strays, LayoutParams())) == 0


def _corner_with_shaft_and_wardrobe(rng: np.random.Generator) -> np.ndarray:
    """A scan of a room's corner (walls y = 0 and x = 0, 2.6 m high) with a 1.2 m square
    shaft standing in the room (full height) and a 2.3 m wardrobe against the wall y = 0."""
    height = 2.6

    def box(n: int, lo: tuple[float, ...], hi: tuple[float, ...]) -> np.ndarray:
        return rng.uniform(lo, hi, size=(n, 3))

    points = np.vstack(
        [
            box(12000, (0, 0, 0), (6, 0, height)),
            box(10000, (0, 0, 0), (0, 5, height)),
            box(20000, (0, 0, 0), (6, 5, 0)),
            box(20000, (0, 0, height), (6, 5, height)),
            box(3000, (3, 2.5, 0), (4.2, 2.5, height)),
            box(3000, (3, 3.7, 0), (4.2, 3.7, height)),
            box(3000, (3, 2.5, 0), (3, 3.7, height)),
            box(3000, (4.2, 2.5, 0), (4.2, 3.7, height)),
            box(2500, (4.5, 0.6, 0), (5.5, 0.6, 2.3)),
        ]
    )
    x, y, z = points.T
    in_shaft = (x > 3.0) & (x < 4.2) & (y > 2.5) & (y < 3.7) & ((z < 0.01) | (z > height - 0.01))
    behind_wardrobe = (x > 4.5) & (x < 5.5) & (y < 0.6) & (z < 2.25)
    kept = points[~in_shaft & ~behind_wardrobe]
    return kept + rng.normal(0.0, 0.005, size=kept.shape)


def test_a_layout_keeps_the_walls_off_its_chain_that_rise_to_the_ceiling():
    layout = estimate_local_layout(_corner_with_shaft_and_wardrobe(np.random.default_rng(0)))
    assert len(layout.keypoints) == 3  # the corner
    cells = layout.unchained_walls
    assert len(cells) > 40
    # The shaft's four faces (1.2 m each) and nothing else: the wardrobe's front passes
    # the wall tests but stops 0.3 m under the ceiling.
    shaft = (cells[:, 0] > 2.9) & (cells[:, 0] < 4.3) & (cells[:, 1] > 2.4) & (cells[:, 1] < 3.8)
    assert shaft.all()
    on_faces = np.minimum(
        np.abs(cells[:, 0] - [[3.0], [4.2]]).min(0), np.abs(cells[:, 1] - [[2.5], [3.7]]).min(0)
    )
    assert on_faces.max() < 0.05
