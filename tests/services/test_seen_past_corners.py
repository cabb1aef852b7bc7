from __future__ import annotations

import numpy as np
import pytest

from bench.scoring import chain_samples
from services.frame_layout import estimate_rgbd_layout
from services.geometry import distance_to_polygon
from services.seen_past_corners import seen_past, without_corners_seen_past
from services.synthetic.furniture import Furnishing
from services.synthetic.render import CAMERAS
from services.synthetic.room import Room
from services.wall_lines import WallLine
from tests.frame_fixtures import render_views


def _line(axis: int, offset: float, travel: int, seen: list[tuple[float, float]]) -> WallLine:
    """A line of 0.1 m cells from run -10 m whose wall was seen over the ``seen`` spans."""
    run = -10.0 + 0.1 * (np.arange(200) + 0.5)
    high = np.zeros(200, dtype=bool)
    for lo, hi in seen:
        high |= (run > lo) & (run < hi)
    return WallLine(axis, offset, travel, -10.0, 0.1, high, np.array(seen, dtype=np.float64))


def test_seen_past_measures_a_wall_running_on_from_its_corner() -> None:
    wall = _line(1, 0.0, 1, [(-3.0, 1.2)])  # x = 0, seen from y = -3 to 1.2
    corner = np.array([0.0, 0.0])
    assert seen_past(wall, corner, 1) == pytest.approx(1.2, abs=0.11)
    assert seen_past(wall, corner, -1) == pytest.approx(3.0, abs=0.11)
    # Seen only from 1 m past the corner on: another wall, not this one running on.
    assert seen_past(_line(1, 0.0, 1, [(1.0, 3.0)]), corner, 1) == 0.0


def test_an_inner_corner_with_its_next_wall_seen_behind_the_last_is_cut() -> None:
    # Walking +x along y = 0 (room at y > 0), the chain turns left at (4, 0) onto x = 4; but
    # x = 4 is seen on from y = -1 (behind y = 0), and y = 0 was seen only up to x = 2.5.
    chain = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 1.0]])
    lines = [_line(0, 0.0, 1, [(0.0, 2.5)]), _line(1, 4.0, 1, [(-1.0, 1.0)])]
    np.testing.assert_allclose(without_corners_seen_past(chain, lines), [[0.0, 0.0], [2.5, 0.0]])
    # Its next wall seen longer: that part is kept, from where it was seen first.
    lines[1] = _line(1, 4.0, 1, [(-2.0, 4.0)])
    chain[2] = [4.0, 4.0]
    np.testing.assert_allclose(without_corners_seen_past(chain, lines), [[4.0, -2.0], [4.0, 4.0]])
    # Seen only up to the corner: a corner, kept.
    lines[1] = _line(1, 4.0, 1, [(0.0, 4.0)])
    np.testing.assert_allclose(without_corners_seen_past(chain, lines), chain)


def test_an_inner_corner_neither_wall_shows_is_cut_on_a_shorter_run_past() -> None:
    # A block's face y = 0 seen only up to x = 2 (its corner), then the chain turns left at
    # (4, 0) onto the leg's far wall x = 4, seen on 0.4 m behind y = 0 (past the block's
    # corner the camera sees into the leg): no corner stands at (4, 0).
    chain = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 5.0]])
    lines = [_line(0, 0.0, 1, [(0.0, 2.0)]), _line(1, 4.0, 1, [(-0.4, 5.0)])]
    np.testing.assert_allclose(without_corners_seen_past(chain, lines), [[4.0, -0.4], [4.0, 5.0]])
    # The face seen up to the corner: a true corner (the far wall's run past is noise), kept.
    lines[0] = _line(0, 0.0, 1, [(0.0, 3.9)])
    np.testing.assert_allclose(without_corners_seen_past(chain, lines), chain)
    # Not seen at the corner, but the far wall seen on only 0.2 m: kept.
    lines = [_line(0, 0.0, 1, [(0.0, 2.0)]), _line(1, 4.0, 1, [(-0.2, 5.0)])]
    np.testing.assert_allclose(without_corners_seen_past(chain, lines), chain)


def test_an_end_at_a_wall_seen_behind_it_goes_back_to_where_its_own_wall_was_seen() -> None:
    chain = np.array([[0.0, 1.0], [0.0, 0.0], [4.0, 0.0]])  # ends on x = 4, room at y > 0
    lines = [
        _line(1, 0.0, -1, [(0.0, 1.0)]),
        _line(0, 0.0, 1, [(0.0, 2.5)]),
        _line(1, 4.0, 1, [(-2.0, -0.1)]),  # seen behind y = 0 only
    ]
    np.testing.assert_allclose(
        without_corners_seen_past(chain, lines), [[0.0, 1.0], [0.0, 0.0], [2.5, 0.0]]
    )
    # Its own wall seen up to the end: the end stays (a corner turning away).
    lines[1] = _line(0, 0.0, 1, [(0.0, 4.0)])
    np.testing.assert_allclose(without_corners_seen_past(chain, lines), chain)


def test_a_reflex_corner_onto_a_wall_seen_only_beyond_the_last_is_cut() -> None:
    # Walking -x along y = 0 (room at y < 0), the chain turns right at (0, 0) onto x = 0,
    # going out past y = 0. But y = 0 is seen on past the corner (a window's sill), and
    # x = 0 only from 0.3 m behind y = 0: a wall outside, seen through the window.
    chain = np.array([[4.0, 0.0], [0.0, 0.0], [0.0, 2.0]])
    lines = [_line(0, 0.0, -1, [(-1.5, 4.0)]), _line(1, 0.0, 1, [(0.3, 2.0)])]
    np.testing.assert_allclose(without_corners_seen_past(chain, lines), [[4.0, 0.0], [-1.5, 0.0]])
    # The wall turned onto seen from the corner on: a reflex corner, kept.
    lines[1] = _line(1, 0.0, 1, [(0.0, 2.0)])
    np.testing.assert_allclose(without_corners_seen_past(chain, lines), chain)
    # The last wall seen on past the corner only 0.5 m (low clutter in line with it, in the
    # room), or not at all: kept as well.
    for seen in (-0.5, 0.0):
        lines = [_line(0, 0.0, -1, [(seen, 4.0)]), _line(1, 0.0, 1, [(0.3, 2.0)])]
        np.testing.assert_allclose(without_corners_seen_past(chain, lines), chain)


def test_a_reflex_corner_coming_from_a_wall_seen_only_beyond_the_next_is_cut() -> None:
    # The outside wall first: y = 0 walked -x, seen only from 0.3 m beyond x = 0, which is
    # seen on past the corner (under a window): the part along x = 0 is kept, from where
    # it was seen.
    chain = np.array([[2.0, 0.0], [0.0, 0.0], [0.0, 3.0]])
    lines = [_line(0, 0.0, -1, [(0.3, 2.0)]), _line(1, 0.0, 1, [(-1.5, 3.0)])]
    np.testing.assert_allclose(without_corners_seen_past(chain, lines), [[0.0, -1.5], [0.0, 3.0]])


# Three U rooms of the outside frame benchmark (seed 19), each seen from before its block:
# the chain used to join the block's face to the far wall across a leg.
_U_ROOMS = [
    (
        [[-6.15, -5.42], [-3.31, -5.42], [-3.31, -2.49], [-1.74, -2.49], [-1.74, -5.42],
         [0.1, -5.42], [0.1, 2.21], [-6.15, 2.21]],
        2.66, ((-4.78, 1.07, 1.1), -71.5, -10.7), "wide",
    ),
    (
        [[-5.9, -2.09], [1.64, -2.09], [1.64, 3.49], [-0.66, 3.49], [-0.66, 0.42],
         [-3.95, 0.42], [-3.95, 3.49], [-5.9, 3.49]],
        2.65, ((0.65, -1.16, 1.43), 163.4, -13.2), "realsense",
    ),
    (
        [[0.17, -1.66], [5.74, -1.66], [5.74, 5.41], [3.91, 5.41], [3.91, 2.19], [1.48, 2.19],
         [1.48, 5.41], [0.17, 5.41]],
        2.85, ((4.33, -0.34, 1.59), 115.9, -21.7), "kinect",
    ),
]  # fmt: skip


@pytest.mark.parametrize(("outline", "height", "stance", "camera"), _U_ROOMS)
def test_a_block_face_is_not_joined_across_a_leg_to_the_far_wall(
    outline: list[list[float]],
    height: float,
    stance: tuple[tuple[float, float, float], float, float],
    camera: str,
) -> None:
    polygon = np.array(outline, dtype=np.float64)
    room = Room.from_polygon(polygon, height)
    frame, pose = render_views(room, Furnishing(), {"f": stance}, CAMERAS[camera])["f"]
    layout = estimate_rgbd_layout(frame)
    world = (layout.keypoints_local() @ pose[:3, :3].T + pose[:3, 3])[:, :2]
    # Every wall of the chain on the outline (none across the leg's open floor).
    assert distance_to_polygon(chain_samples(world, 20), polygon).max() < 0.15, np.round(
        world, 2
    ).tolist()
    assert np.linalg.norm(np.diff(world, axis=0), axis=1).sum() > 4.0
