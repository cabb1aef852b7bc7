"""A frame's chain end that stops inside its view is open; one at the view's edge is not."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np

from services.open_ends import open_ends
from services.types import LocalLayout, ManhattanFrame

FRAME = ManhattanFrame(np.eye(3), 0.0, None)
TEN_DEGREES = math.radians(10.0)
REALSENSE_VIEW = math.radians(79.0)


def _frame_view(chain: list[tuple[float, float]], ranges: np.ndarray) -> LocalLayout:
    """A single frame's layout, its camera at the origin, seeing ``ranges`` (azimuth, m)."""
    return LocalLayout(
        np.asarray(chain, dtype=np.float64),
        FRAME,
        evidence="frame",
        view_angle=REALSENSE_VIEW,
        cameras=np.zeros((1, 2)),
        view_ranges=ranges,
    )


def _view(lo_deg: float, hi_deg: float, distance: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    azimuth = np.radians(np.arange(lo_deg, hi_deg, 0.5))
    return np.column_stack([azimuth, np.broadcast_to(distance(azimuth), azimuth.shape)])


def _wall_at_x(x: float) -> Callable[[np.ndarray], np.ndarray]:
    """Horizontal range of the wall x = const, by azimuth."""
    return lambda azimuth: x / np.cos(azimuth)


def test_a_chain_from_edge_to_edge_of_its_view_has_no_open_end():
    # The wall x = 2 seen across a 79 degree view: the chain spans it all.
    half = math.radians(39.5)
    chain = [(2.0, -2.0 * math.tan(half)), (2.0, 2.0 * math.tan(half))]
    layout = _frame_view(chain, _view(-39.5, 39.5, _wall_at_x(2.0)))
    assert open_ends(layout, TEN_DEGREES) == (False, False)


def test_a_wall_lost_past_a_protruding_corner_leaves_the_end_open():
    # The chain stops at y = 0 where the wall turns away; past it the view meets a wall
    # 4 m off (the room beyond the corner), over 39 degrees of azimuth.
    def ranges(azimuth: np.ndarray) -> np.ndarray:
        return np.where(azimuth > 0.0, 4.0 / np.cos(azimuth), 2.0 / np.cos(azimuth))

    layout = _frame_view([(2.0, -1.6), (2.0, 0.0)], _view(-39.5, 39.5, ranges))
    assert open_ends(layout, TEN_DEGREES) == (False, True)
    # A chain reversed in the view (its target at the low azimuth) opens its source there.
    mirrored = _frame_view([(2.0, 0.0), (2.0, 1.6)], _view(-39.5, 39.5, lambda a: ranges(-a)))
    assert open_ends(mirrored, TEN_DEGREES) == (True, False)


def test_a_chain_stopping_short_on_a_wall_that_goes_on_is_not_open():
    # The view goes on past the end on the same wall at the same distance: the chain
    # stopped short (a door, clutter), the wall did not turn away.
    layout = _frame_view([(2.0, -1.6), (2.0, 0.0)], _view(-39.5, 39.5, _wall_at_x(2.0)))
    assert open_ends(layout, TEN_DEGREES) == (False, False)


def test_an_end_a_few_degrees_inside_the_view_is_not_open():
    def ranges(azimuth: np.ndarray) -> np.ndarray:
        return np.where(azimuth > 0.0, 4.0, 2.0)

    layout = _frame_view([(2.0, -1.6), (2.0, 0.0)], _view(-39.5, 8.0, ranges))
    assert open_ends(layout, TEN_DEGREES) == (False, False)
    assert open_ends(layout, math.radians(5.0)) == (False, True)


def test_a_view_narrower_than_the_least_has_no_open_end():
    def ranges(azimuth: np.ndarray) -> np.ndarray:
        return np.where(azimuth > 0.0, 4.0, 2.0)

    layout = _frame_view([(2.0, -1.6), (2.0, 0.0)], _view(-39.5, 39.5, ranges))
    assert open_ends(layout, TEN_DEGREES, least_view=1.2) == (False, True)
    kinect = dataclasses.replace(layout, view_angle=math.radians(63.0))
    assert open_ends(kinect, TEN_DEGREES, least_view=1.2) == (False, False)


def test_clouds_merged_frames_and_a_zero_angle_have_no_open_end():
    def ranges(azimuth: np.ndarray) -> np.ndarray:
        return np.where(azimuth > 0.0, 4.0, 2.0)

    layout = _frame_view([(2.0, -1.6), (2.0, 0.0)], _view(-39.5, 39.5, ranges))
    assert open_ends(layout, 0.0) == (False, False)
    cloud = LocalLayout(layout.keypoints, FRAME)
    assert open_ends(cloud, TEN_DEGREES) == (False, False)
    merged = LocalLayout(
        layout.keypoints, FRAME, evidence="frame", cameras=np.zeros((2, 2)),
        view_ranges=layout.view_ranges,
    )  # fmt: skip
    assert open_ends(merged, TEN_DEGREES) == (False, False)
