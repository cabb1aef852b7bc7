"""Frames turned on the spot: their view ranges tell that they share a camera."""

from __future__ import annotations

import math

import numpy as np
import pytest

from schemas.params import PlacementParams
from services.frame_layout import estimate_rgbd_layout
from services.synthetic.furniture import Box, Furnishing
from services.synthetic.room import Room
from services.types import LocalLayout
from services.view_ranges import (
    BIN,
    shared_turn,
    station_mates,
    view_ranges,
    without_odd_triangles,
)
from tests.frame_fixtures import render_views

# A 6.4 x 5.1 m room with a notch in one corner and a wardrobe against the wall y = 0.
_ROOM = Room.from_polygon(
    np.array([[0.0, 0], [6.4, 0], [6.4, 3.9], [5.2, 3.9], [5.2, 5.1], [0, 5.1]]), 2.6
)
_FURNISHING = Furnishing(boxes=(Box(np.array([3.6, 0.02, 0.0]), np.array([4.8, 0.6, 2.0])),))


def _layouts(
    stances: dict[str, tuple[tuple[float, float, float], float, float]],
) -> tuple[dict[str, LocalLayout], dict[str, np.ndarray]]:
    views = render_views(_ROOM, _FURNISHING, stances)
    layouts = {name: estimate_rgbd_layout(frame) for name, (frame, _) in views.items()}
    return layouts, {name: pose for name, (_, pose) in views.items()}


def _true_turn(
    layouts: dict[str, LocalLayout], poses: dict[str, np.ndarray], a: str, b: str
) -> int:
    """Quarter turns taking b's aligned frame onto a's, from the rendered poses."""
    relative = (
        layouts[a].frame.rotation
        @ poses[a][:3, :3].T
        @ poses[b][:3, :3]
        @ layouts[b].frame.rotation.T
    )
    return round(math.degrees(math.atan2(relative[1, 0], relative[0, 0])) / 90.0) % 4


def test_frames_turned_on_the_spot_share_their_camera_and_say_how_they_turn():
    # Two frames from one station, 40 degrees apart (their 63-degree views overlap by 23),
    # and a third from a station 0.9 m away looking over the same walls.
    layouts, poses = _layouts(
        {
            "a": ((2.4, 2.3, 1.3), -60.0, -10.0),
            "b": ((2.4, 2.3, 1.35), -20.0, -5.0),
            "c": ((3.2, 2.7, 1.3), -30.0, -10.0),
        }
    )
    assert all(layout.ok and len(layout.view_ranges) for layout in layouts.values())
    mates = station_mates(layouts)
    assert mates["a"] == {"b": _true_turn(layouts, poses, "a", "b")}
    assert mates["b"] == {"a": _true_turn(layouts, poses, "b", "a")}
    assert mates["c"] == {}
    assert station_mates(layouts, PlacementParams(station_view_overlap=0.0))["a"] == {}


def test_a_frames_view_ranges_are_its_walls_distances_not_its_floors():
    # Looking straight at the wall y = 0 from 2.3 m: the ranges around the view's middle
    # are 2.3 m, the wardrobe's front 0.6 m nearer where it stands; none is the floor's.
    layouts, _ = _layouts({"a": ((2.4, 2.3, 1.3), -90.0, -15.0)})
    layout = layouts["a"]
    ranges = view_ranges(np.zeros((0, 3)), np.zeros(2), 0.0, 2.6)
    assert ranges.shape == (0, 2)
    azimuth, distance = layout.view_ranges.T
    assert np.all(np.diff(azimuth) > 0) and np.all(np.diff(azimuth) >= BIN * 0.99)
    facing = distance[np.argsort(np.abs(distance - 2.3))[:20]]
    assert facing == pytest.approx(2.3, abs=0.05)
    assert distance.min() > 1.5  # the wardrobe's front at 1.7 m, no floor nearer


def test_ranges_that_overlap_too_little_or_disagree_share_no_camera():
    azimuth = (np.arange(100) + 0.5) * BIN - math.pi
    first = np.column_stack([azimuth, np.full(100, 3.0)])
    turned = np.column_stack([azimuth + math.pi / 2, np.full(100, 3.0)])
    # Views that look the same turned by any quarter (a round room): nothing told.
    around = np.column_stack([(np.arange(720) + 0.5) * BIN - math.pi, np.full(720, 3.0)])
    assert shared_turn(around, around) is None
    # Walls of one distance over a stretch, another elsewhere: only the right turn agrees.
    first[:50, 1] = 2.0
    turned[:50, 1] = 2.0
    assert shared_turn(first, turned) == 3
    assert shared_turn(turned, first) == 1
    off = turned.copy()
    off[:, 1] += 0.3
    assert shared_turn(first, off) is None
    assert shared_turn(first[:10], turned[:10]) is None  # 5 degrees: too little overlap
    assert shared_turn(first, np.zeros((0, 2))) is None


def test_a_triangle_of_pairs_whose_turns_do_not_add_up_is_not_trusted():
    # d shares the camera of a and b consistently (a -> b 1, b -> d 2, a -> d 3); c looked
    # like b turned 0 and like a turned 0, which a -> b 1 contradicts: the triangle a, b, c
    # is dropped, and with it a -> b, which the triangle a, b, d alone would have kept.
    turns = {("a", "b"): 1, ("b", "c"): 0, ("a", "c"): 0, ("b", "d"): 2, ("a", "d"): 3}
    mates: dict[str, dict[str, int]] = {fid: {} for fid in "abcd"}
    for (first, second), turn in turns.items():
        mates[first][second], mates[second][first] = turn, (-turn) % 4
    kept = without_odd_triangles(mates)
    assert kept == {"a": {"d": 3}, "b": {"d": 2}, "c": {}, "d": {"a": 1, "b": 2}}
