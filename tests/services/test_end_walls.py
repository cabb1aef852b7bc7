from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from services.end_walls import flattened_end_step, without_end_wall
from services.types import LocalLayout, ManhattanFrame

FRAME = ManhattanFrame(rotation=np.eye(3), floor_z=0.0, ceiling_z=2.5)
REGION = np.array([[0.1, 0.2, 0.3], [0.2, 0.3, 1.0]])


def _frame_layout(keypoints: list[list[float]]) -> LocalLayout:
    return LocalLayout(
        keypoints=np.array(keypoints, dtype=np.float64),
        frame=FRAME,
        source_boundary=REGION,
        target_boundary=REGION,
        evidence="frame",
        view_angle=1.5,
    )


# A wardrobe's side (0.6 m) at the chain's end, turning left off a 3 m wall.
SIDE_LAST = [[0.0, 0.0], [3.0, 0.0], [3.0, 3.0], [0.0, 3.0], [0.0, 2.4]]


def test_a_short_convex_last_wall_is_dropped_with_its_end_region():
    variant = without_end_wall(_frame_layout(SIDE_LAST), "last", 1.3)
    assert variant is not None
    assert variant.keypoints.tolist() == SIDE_LAST[:-1]
    assert len(variant.target_boundary) == 0
    assert np.array_equal(variant.source_boundary, REGION)


def test_a_short_convex_first_wall_is_dropped_with_its_end_region():
    side_first = [[0.5, -0.6], [0.5, 0.0], [-3.0, 0.0]]
    variant = without_end_wall(_frame_layout(side_first), "first", 1.3)
    assert variant is not None
    assert variant.keypoints.tolist() == side_first[1:]
    assert len(variant.source_boundary) == 0
    assert np.array_equal(variant.target_boundary, REGION)


@pytest.mark.parametrize(
    ("keypoints", "end", "longest"),
    [
        (SIDE_LAST, "first", 1.3),  # the first wall is 3 m: a wall
        (SIDE_LAST, "last", 0.5),  # longer than allowed
        (SIDE_LAST, "last", 0.0),  # switched off
        ([[0.0, 0.0], [3.0, 0.0], [3.0, -0.6]], "last", 1.3),  # a right turn: a notch
        ([[0.0, 0.0], [1.0, 0.0], [1.0, 0.6]], "last", 1.3),  # beside a wall under 1.5 m
        ([[0.0, 0.0], [2.0, 0.0], [2.0, 1.2]], "last", 1.3),  # beside one under twice it
        ([[0.0, 0.0], [0.6, 0.0]], "last", 1.3),  # a single wall stays
    ],
)
def test_other_end_walls_are_kept(keypoints: list[list[float]], end: str, longest: float):
    assert without_end_wall(_frame_layout(keypoints), end, longest) is None


def test_a_narrow_view_keeps_its_end_walls():
    narrow = dataclasses.replace(_frame_layout(SIDE_LAST), view_angle=1.09)
    assert without_end_wall(narrow, "last", 1.3, least_view=1.2) is None
    assert without_end_wall(_frame_layout(SIDE_LAST), "last", 1.3, least_view=1.2) is not None


def test_a_cloud_chain_is_never_cut():
    cloud = dataclasses.replace(_frame_layout(SIDE_LAST), evidence="cloud")
    assert without_end_wall(cloud, "last", 1.3) is None


# A wardrobe 1.9 m wide and 0.6 m deep in the corner at the chain's end: the chain turns off
# the 3 m wall onto its front, then back onto its side down to the wall behind (y = 0).
STEP_LAST = [[-2.0, 3.0], [0.0, 3.0], [0.0, 0.6], [1.9, 0.6], [1.9, 0.0]]


def test_a_wardrobe_step_at_the_last_end_is_flattened_onto_the_wall_behind():
    variant = flattened_end_step(_frame_layout(STEP_LAST), "last", 0.8)
    assert variant is not None
    assert np.allclose(variant.keypoints, [[-2.0, 3.0], [0.0, 3.0], [0.0, 0.0], [1.9, 0.0]])
    assert len(variant.target_boundary) == 0
    assert np.array_equal(variant.source_boundary, REGION)


def test_a_wardrobe_step_at_the_first_end_is_flattened_onto_the_wall_behind():
    # The same corner walked the other way round: the chain starts at the wall's foot.
    step_first = [[0.0, 0.0], [0.0, 0.6], [1.9, 0.6], [1.9, 3.0], [-2.0, 3.0]]
    variant = flattened_end_step(_frame_layout(step_first), "first", 0.8)
    assert variant is not None
    assert np.allclose(variant.keypoints, [[0.0, 0.0], [1.9, 0.0], [1.9, 3.0], [-2.0, 3.0]])
    assert len(variant.source_boundary) == 0
    assert np.array_equal(variant.target_boundary, REGION)


@pytest.mark.parametrize(
    ("keypoints", "end", "deepest", "least_view"),
    [
        (STEP_LAST, "first", 0.8, 0.0),  # no step at the first end
        (STEP_LAST, "last", 0.5, 0.0),  # a side deeper than allowed: a jog of the room
        (STEP_LAST, "last", 0.0, 0.0),  # switched off
        (STEP_LAST, "last", 0.8, 2.0),  # a view narrower than asked for
        ([[0.0, 3.0], [0.0, 0.6], [1.9, 0.6], [1.9, 1.2]], "last", 0.8, 0.0),  # turns back
        ([[0.0, 0.6], [1.9, 0.6], [1.9, 0.0]], "last", 0.8, 0.0),  # two walls: no wall beside
    ],
)
def test_other_chain_ends_are_not_flattened(
    keypoints: list[list[float]], end: str, deepest: float, least_view: float
):
    layout = _frame_layout(keypoints)
    assert flattened_end_step(layout, end, deepest, least_view) is None


def test_clouds_are_not_flattened():
    layout = dataclasses.replace(_frame_layout(STEP_LAST), evidence="cloud")
    assert flattened_end_step(layout, "last", 0.8) is None
