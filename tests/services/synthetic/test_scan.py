"""What one scan sees: its own walls, parts of openings across its ends, floor beyond them."""

from __future__ import annotations

import numpy as np
import pytest

from services.synthetic.furniture import Furnishing, Opening
from services.synthetic.room import Room, nearest_boundary
from services.synthetic.scan import ScanStyle, Stretch, sample_scan

pytestmark = pytest.mark.timeout(60)

ROOM = Room.from_polygon(np.array([[0.0, 0.0], [12.0, 0.0], [12.0, 8.0], [0.0, 8.0]]), 2.5)
STYLE = ScanStyle(
    reach=2.0,
    ceiling_reach=0.0,
    falloff=0.0,
    scanner_spacing=6.0,
    patch_gain=1.0,
    see_through=False,
    oversample=1.0,
)
# Two neighbours on the 12 m bottom wall with a 0.3 m gap between them (arc 5.0 to 5.3).
LEFT, RIGHT = Stretch(1.0, 4.0), Stretch(5.3, 4.0)


def scan(stretch: Stretch, style: ScanStyle, furnishing: Furnishing | None = None) -> np.ndarray:
    rng = np.random.default_rng(0)
    return sample_scan(rng, ROOM, furnishing or Furnishing(), stretch, style, 20_000)


def floor_arcs(points: np.ndarray) -> np.ndarray:
    """Arc positions of the wall nearest to the floor points more than 5 cm from walls."""
    distance, arc = nearest_boundary(points[:, :2], ROOM)
    return arc[(np.abs(points[:, 2]) < 1e-9) & (distance > 0.05)]


def wall_arcs(points: np.ndarray) -> np.ndarray:
    distance, arc = nearest_boundary(points[:, :2], ROOM)
    return arc[(distance < 1e-9) & (points[:, 2] > 0.1)]


def test_floor_stops_at_the_stretch_ends_without_reach_beyond():
    left, right = floor_arcs(scan(LEFT, STYLE)), floor_arcs(scan(RIGHT, STYLE))
    assert left.max() <= 5.0 + 1e-9 and right.min() >= 5.3 - 1e-9


def test_reach_beyond_shares_floor_across_a_gap_but_not_walls():
    style = ScanStyle(**{**STYLE.__dict__, "beyond": 1.0})
    left_points, right_points = scan(LEFT, style), scan(RIGHT, style)
    left, right = floor_arcs(left_points), floor_arcs(right_points)
    assert 5.9 <= left.max() <= 6.0 + 1e-9 and 4.3 - 1e-9 <= right.min() <= 4.4
    in_gap = (5.0, 5.3)
    for arcs in (left, right):
        assert np.count_nonzero((arcs > in_gap[0]) & (arcs < in_gap[1])) > 50
    assert wall_arcs(left_points).max() <= 5.0 + 1e-9
    assert wall_arcs(right_points).min() >= 5.3 - 1e-9


def test_an_opening_across_a_stretch_end_is_seen_in_part_from_each_side():
    # A window from t = 4.5 to 5.8 m on the bottom wall (thickness 0.2 m, outward is -y).
    window = Opening(edge=0, t0=4.5, t1=5.8, z0=0.9, z1=2.0)
    furnishing = Furnishing(openings=(window,), wall_thickness=0.2)
    left, right = scan(LEFT, STYLE, furnishing), scan(RIGHT, STYLE, furnishing)
    for points, own, other, span in ((left, 4.5, 5.8, (4.5, 5.0)), (right, 5.8, 4.5, (5.3, 5.8))):
        reveal = points[points[:, 1] < -0.01]  # inside the wall's thickness
        assert len(reveal) > 100
        jamb = np.abs(reveal[:, 0] - own) < 1e-9
        assert np.count_nonzero(jamb) > 10
        assert not np.any(np.abs(reveal[:, 0] - other) < 1e-9), "the far jamb is not seen"
        across = reveal[~jamb]
        assert across[:, 0].min() >= span[0] - 1e-9 and across[:, 0].max() <= span[1] + 1e-9
        # No wall inside the window's hole.
        wall = points[(np.abs(points[:, 1]) < 1e-9) & (points[:, 2] > 0.95) & (points[:, 2] < 1.95)]
        assert not np.any((wall[:, 0] > 4.5) & (wall[:, 0] < 5.8))


def test_through_a_door_a_scan_may_see_the_next_rooms_far_wall():
    # A door from t = 2.0 to 2.9 m on the bottom wall (outward is -y), on the left stretch.
    door = Opening(edge=0, t0=2.0, t1=2.9, z0=0.0, z1=2.0)
    furnishing = Furnishing(openings=(door,), wall_thickness=0.2)
    seeing = ScanStyle(**{**STYLE.__dict__, "see_through": True})
    without = scan(LEFT, seeing, furnishing)
    assert np.all(without[:, 1] >= -2.2 - 1e-9), "only the floor 0.5-2 m past the door"
    points = scan(LEFT, ScanStyle(**{**seeing.__dict__, "far_walls": 1.0}), furnishing)
    far = points[points[:, 1] < -1.2 + 1e-9]  # 1-3 m past the door's outer face
    wall = far[far[:, 2] > 1e-9]
    assert len(wall) > 200
    depth = np.unique(np.round(wall[:, 1], 9))
    assert len(depth) == 1 and -3.2 - 1e-9 <= depth[0] <= -1.2 + 1e-9, "one plane"
    assert wall[:, 2].max() > 2.3, "the whole height, not the door's"
    assert wall[:, 0].min() < 2.0 and wall[:, 0].max() > 2.9, "wider than the door"
    # The next room's floor is seen up to that wall, in a view that widens past the jambs.
    floor = points[(np.abs(points[:, 2]) < 1e-9) & (points[:, 1] < -0.2 - 1e-9)]
    assert floor[:, 1].min() < depth[0] + 0.2, "the floor reaches the far wall"
    deep = floor[floor[:, 1] < depth[0] + 0.5]
    assert len(deep) > 20 and (deep[:, 0].min() < 2.0 or deep[:, 0].max() > 2.9), "widening"
