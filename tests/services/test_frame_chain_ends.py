"""RGB-D frame chains: the floor under a table top, furniture fronts flattened into the wall
behind them, a corner hidden by furniture, an opening's reveal at a chain end, chain ends
moved out to the frustum's edges, and the frustum's floor-plan wedge."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from schemas.params import PipelineParams
from services.frame_layout import (
    _drop_end_reveals,
    _drop_end_sides,
    _flatten_corner_fronts,
    _flatten_furniture,
    _floor,
    _past_corner_fronts,
    _to_frustum_edges,
    _without_furniture,
)
from services.frustum import CameraView, in_any_view, side_rays, swept_cells
from services.synthetic.render import KINECT
from services.wall_lines import WallLine
from tests.frame_fixtures import WIDE

pytestmark = pytest.mark.timeout(30)

LEVEL = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # optical -> z up, looking +y


def _pitched(degrees: float) -> np.ndarray:
    a = np.radians(degrees)
    tilt = np.array([[1.0, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    return tilt @ LEVEL


def _patch(z: float, n: int, normal_z: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(n)
    xy = rng.uniform(-1.0, 1.0, (n, 2)) + np.array([0.0, 3.0])
    normal = np.array([0.0, np.sqrt(1 - normal_z**2), normal_z])
    return np.column_stack([xy, np.full(n, z)]), np.tile(normal, (n, 1))


def test_the_floor_is_the_lowest_level_unless_walls_reach_lower() -> None:
    table, table_n = _patch(-0.5, 400)
    floor, floor_n = _patch(-1.4, 80)
    wall = np.column_stack([np.zeros(200), np.full(200, 4.0), np.linspace(-1.4, 0.5, 200)])
    wall_n = np.tile([0.0, -1.0, 0.0], (200, 1))
    points, normals = np.vstack([table, floor, wall]), np.vstack([table_n, floor_n, wall_n])
    assert _floor(points, normals, PipelineParams()) == pytest.approx(-1.4, abs=0.02)
    # The floor hidden under the table: the walls' foot says the table top is no floor.
    hidden = np.vstack([table, wall]), np.vstack([table_n, wall_n])
    assert _floor(*hidden, PipelineParams()) == pytest.approx(-1.4, abs=0.02)
    # Nothing reaches down: the assumed camera height.
    assert _floor(table[:10], table_n[:10], PipelineParams()) == -1.3


def test_a_shallow_step_into_the_room_that_comes_back_is_flattened() -> None:
    # Along y = 3 travelling -x (room below), a 0.6 m deep front from x = 1 to 0.
    chain = np.array([[3.0, 3.0], [1.0, 3.0], [1.0, 2.4], [0.0, 2.4], [0.0, 3.0], [-2.0, 3.0]])
    np.testing.assert_allclose(_flatten_furniture(chain), [[3.0, 3.0], [-2.0, 3.0]])
    # A 1.5 m deep protrusion is the room's own: kept.
    deep = chain.copy()
    deep[2:4, 1] = 1.5
    np.testing.assert_allclose(_flatten_furniture(deep), deep)
    # A chain ending on the front: the wall runs on to the end.
    tail = chain[:4]
    np.testing.assert_allclose(_flatten_furniture(tail), [[3.0, 3.0], [0.0, 3.0]])


def _line(offset: float, travel: int, axis: int = 0) -> WallLine:
    cells = 200
    return WallLine(
        axis=axis,
        offset=offset,
        travel=travel,
        origin=-8.0,
        cell_size=0.08,
        high=np.zeros(cells, dtype=bool),
        segments=np.array([[-1.0, 1.0]]),
        unsupported=np.zeros(cells, dtype=bool),
        seen_through=np.zeros(cells, dtype=bool),
        occupied=np.zeros(cells, dtype=bool),
    )


def test_a_shallow_front_in_a_corner_gives_the_corner_back_even_when_its_side_was_seen() -> None:
    # Up the wall x = 2, onto a wardrobe front 0.7 m before the wall y = 5.7, back out to it
    # along the wardrobe's side and on along y = 5.7.
    chain = np.array([[2.0, 3.0], [2.0, 5.0], [0.6, 5.0], [0.6, 5.7], [-1.0, 5.7]])
    corner = [[2.0, 3.0], [2.0, 5.7], [-1.0, 5.7]]
    np.testing.assert_allclose(_flatten_corner_fronts(chain), corner)
    # The same front at the chain's far corner (walked the other way round).
    far = np.array([[1.0, 3.7], [-0.3, 3.7], [-0.3, 3.0], [-2.5, 3.0], [-2.5, 2.0]])
    expected = [[1.0, 3.7], [-2.5, 3.7], [-2.5, 2.0]]
    np.testing.assert_allclose(_flatten_corner_fronts(far), expected)
    # A step deeper than a wardrobe is the room's own.
    deep = chain.copy()
    deep[1:3, 1] = 4.5
    np.testing.assert_allclose(_flatten_corner_fronts(deep), deep)


def test_chain_ends_move_out_to_the_frustum_edges_or_to_a_wall_turning_on_the_way() -> None:
    view = CameraView.from_intrinsics(KINECT, LEVEL, np.zeros(3))
    right, left = side_rays(view)
    chain = np.array([[1.0, 3.0], [-1.0, 3.0]])  # a wall at y = 3, room below, travel -x
    moved = _to_frustum_edges(chain, [_line(3.0, -1)], [view])
    np.testing.assert_allclose(moved[0], 3.0 / right[1] * right, atol=1e-9)
    np.testing.assert_allclose(moved[1], 3.0 / left[1] * left, atol=1e-9)
    # A seen wall meets the line past the target end: the chain ends at that corner, not
    # at the frustum's edge past it.
    corner = _line(-1.5, 1, axis=1)
    corner = WallLine(**{**corner.__dict__, "segments": np.array([[2.0, 3.0]])})
    turned = _to_frustum_edges(chain, [_line(3.0, -1), corner], [view])
    np.testing.assert_allclose(turned[1], [-1.5, 3.0], atol=1e-9)
    # A wall that meets the line just behind the end (within its slack) moves nothing.
    behind = WallLine(**{**corner.__dict__, "offset": -0.9})
    kept = _to_frustum_edges(chain, [_line(3.0, -1), behind], [view])
    np.testing.assert_allclose(kept[1], chain[1])
    # A door's reveal there (the wall's thickness, behind it) is no turn of the wall.
    reveal = WallLine(**{**corner.__dict__, "segments": np.array([[3.0, 3.15]])})
    moved = _to_frustum_edges(chain, [_line(3.0, -1), reveal], [view])
    np.testing.assert_allclose(moved[1], 3.0 / left[1] * left, atol=1e-9)


def _ranges(segments: list[tuple[tuple[float, float], tuple[float, float]]]) -> np.ndarray:
    """View ranges (:func:`services.view_ranges.view_ranges`' form) of a camera at the
    origin seeing the floor-plan wall ``segments`` ((x0, y0), (x1, y1)): the nearest hit
    per half-degree bin."""
    azimuth = -np.pi + (np.arange(720) + 0.5) * np.radians(0.5)
    ray = np.column_stack([np.cos(azimuth), np.sin(azimuth)])
    nearest = np.full(len(azimuth), np.inf)
    for a, b in segments:
        start, step = np.array(a), np.subtract(b, a)
        # Solve t * ray = start + u * step for t (along the ray) and u (along the segment).
        det = ray[:, 0] * -step[1] + ray[:, 1] * step[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (start[0] * -step[1] + start[1] * step[0]) / det
            u = (ray[:, 0] * start[1] - ray[:, 1] * start[0]) / det
        hit = (np.abs(det) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
        nearest = np.where(hit, np.minimum(nearest, t), nearest)
    seen = np.isfinite(nearest)
    return np.column_stack([azimuth[seen], nearest[seen]])


def test_a_chain_end_stops_at_a_wall_across_that_furniture_hid_at_the_corner() -> None:
    # A wide camera 1 m before the wall y = 1 (room below, travel -x); the chain's target
    # end is at the corner x = -0.3, where the room's wall x = -0.3 turns towards the
    # camera. Furniture hid that wall near the corner: its line's segment stops 0.6 m short
    # of y = 1, so no wall across meets the line there, and what hides the line past the
    # corner stands under a furniture's depth off it. (Outside frames seed 22,
    # `wide_019_real` frame_00: carried 2.2 m past the room's corner.)
    view = CameraView.from_intrinsics(WIDE, LEVEL, np.zeros(3))
    _, left = side_rays(view)
    chain = np.array([[0.3, 1.0], [-0.3, 1.0]])
    across = WallLine(**{**_line(-0.3, 1, axis=1).__dict__, "segments": np.array([[-2.0, 0.4]])})
    lines = [_line(1.0, -1), across]
    corner = _ranges([((0.3, 1.0), (-0.3, 1.0)), ((-0.3, 1.0), (-0.3, -3.0))])
    moved = _to_frustum_edges(chain, lines, [view], corner)
    np.testing.assert_allclose(moved[1], chain[1], atol=0.05)
    # The same view with no wall seen across there: the end goes on (until the line lies a
    # furniture's depth behind what the camera saw).
    moved = _to_frustum_edges(chain, [_line(1.0, -1)], [view], corner)
    assert moved[1][0] < -1.0
    # A furniture front 0.5 m before the wall hides the line past the end instead (along
    # it, not across): the wall goes on behind it, to the frustum's edge.
    front = _ranges([((0.3, 1.0), (-0.3, 1.0)), ((-0.3, 0.5), (-3.0, 0.5))])
    moved = _to_frustum_edges(chain, lines, [view], front)
    np.testing.assert_allclose(moved[1], 1.0 / left[1] * left, atol=1e-9)


def test_the_floor_plan_wedge_of_a_pitched_camera_is_wider_than_its_eye_level_cut() -> None:
    view = CameraView.from_intrinsics(WIDE, _pitched(-20.0), np.zeros(3))
    right, _ = side_rays(view)
    eye = np.arctan2(right[0], right[1])
    beyond = 3.0 * np.array([np.sin(eye + np.radians(5.0)), np.cos(eye + np.radians(5.0))])
    assert in_any_view([view], beyond[None], tolerance_deg=0.0)[0]
    far_out = 3.0 * np.array([np.sin(eye + np.radians(30.0)), np.cos(eye + np.radians(30.0))])
    assert not in_any_view([view], far_out[None], tolerance_deg=0.0)[0]


def test_an_end_wall_as_short_as_a_reveal_turning_away_is_dropped() -> None:
    # Along y = 3 travelling -x (room below), the chain ends on a 0.25 m wall turning away
    # from the room (a right turn, +y): a door's or window's side.
    chain = np.array([[3.0, 3.0], [0.0, 3.0], [0.0, 3.25]])
    np.testing.assert_allclose(_drop_end_reveals(chain), chain[:2])
    # The same at the source end, walked the other way round.
    source = np.array([[0.0, 2.75], [0.0, 3.0], [3.0, 3.0]])
    np.testing.assert_allclose(_drop_end_reveals(source), source[1:])
    # A protruding corner seen 0.5 m long is the room's own; a left turn is a corner.
    longer = np.array([[3.0, 3.0], [0.0, 3.0], [0.0, 3.5]])
    np.testing.assert_allclose(_drop_end_reveals(longer), longer)
    inward = np.array([[3.0, 3.0], [0.0, 3.0], [0.0, 2.75]])
    np.testing.assert_allclose(_drop_end_reveals(inward), inward)


def test_a_corner_hidden_by_a_wardrobe_is_moved_where_the_wall_beside_it_ends() -> None:
    # Wall A along y = 3 travelled -x (room below) is seen on to x = -0.5; a wardrobe in the
    # corner hides the corner (x = -0.5), and the chain turned onto its front at x = 0.
    wall = _line(3.0, -1)
    cells = np.arange(len(wall.high))
    runs = wall.origin + (cells + 0.5) * wall.cell_size
    wall = dataclasses.replace(wall, high=(runs > -0.5) & (runs < 4.0))
    chain = np.array([[3.0, 3.0], [0.0, 3.0], [0.0, 1.0]])
    moved = _past_corner_fronts(chain, [wall])
    np.testing.assert_allclose(moved, [[3.0, 3.0], [-0.48, 3.0], [-0.48, 1.0]], atol=0.05)
    # Wall seen on past the turn by more than furniture is deep: another wall's evidence.
    far = dataclasses.replace(wall, high=(runs > -2.0) & (runs < 4.0))
    np.testing.assert_allclose(_past_corner_fronts(chain, [far]), chain)


def test_a_corner_hidden_by_a_wardrobe_is_found_behind_an_openings_reveal() -> None:
    # As above, and the chain ends on a door's 0.25 m reveal past the front: the early turn
    # is not the chain's last corner until the reveal is dropped.
    wall = _line(3.0, -1)
    runs = wall.origin + (np.arange(len(wall.high)) + 0.5) * wall.cell_size
    wall = dataclasses.replace(wall, high=(runs > -0.5) & (runs < 4.0))
    chain = np.array([[3.0, 3.0], [0.0, 3.0], [0.0, 1.0], [-0.25, 1.0]])
    np.testing.assert_allclose(
        _without_furniture(chain, [wall]), [[3.0, 3.0], [-0.48, 3.0], [-0.48, 1.0]], atol=0.05
    )


def _seen_along(line: WallLine, lo: float, hi: float) -> WallLine:
    """The line with high evidence and one candidate segment over runs lo..hi."""
    runs = line.origin + (np.arange(len(line.high)) + 0.5) * line.cell_size
    return dataclasses.replace(line, high=(runs > lo) & (runs < hi), segments=np.array([[lo, hi]]))


def test_a_lone_front_before_a_corner_gets_the_wall_beside_it_and_the_corner_back() -> None:
    # A wardrobe against the wall x = 0 fills the view but for a strip of the wall A along
    # y = 3 (travelled -x, room below) beside it: the chain is the wardrobe's front x = 0.6
    # alone, from A's line down. A is seen from x = 0.8 on past the front to the corner.
    chain = np.array([[0.6, 3.0], [0.6, 1.0]])
    wall = _seen_along(_line(3.0, -1), 0.0, 0.8)
    np.testing.assert_allclose(
        _without_furniture(chain, [wall]), [[0.8, 3.0], [0.0, 3.0], [0.0, 1.0]], atol=0.05
    )
    # Mirrored: the front ends the chain, A goes on from it (-x) and is seen behind it.
    mirrored = np.array([[-0.6, 1.0], [-0.6, 3.0]])
    np.testing.assert_allclose(
        _without_furniture(mirrored, [_seen_along(_line(3.0, -1), -0.8, 0.0)]),
        [[0.0, 1.0], [0.0, 3.0], [-0.8, 3.0]],
        atol=0.05,
    )
    # A seen hardly before the front's end (a window's reveal behind the wall the chain is
    # on), or not past it (the front is a wall: its corner with A is the room's).
    behind = _seen_along(_line(3.0, -1), 0.0, 0.65)
    np.testing.assert_allclose(_without_furniture(chain, [behind]), chain)
    before = _seen_along(_line(3.0, -1), 0.6, 1.5)
    np.testing.assert_allclose(_without_furniture(chain, [before]), chain)


def test_an_end_wall_as_short_as_a_furnitures_side_is_dropped_unless_seen_up_high() -> None:
    # Along y = 2 travelling -x (room below), the chain ends on a 0.4 m wall turning into the
    # room (a left turn): a shelf's side, or a room's corner. The level camera sees that
    # column up to 0.8-0.95 m over itself: 1.1-1.25 m over a floor 0.3 m under it, too low
    # to tell a wall from a shelf; 1.8-1.95 m over a floor 1 m under it.
    view = CameraView.from_intrinsics(KINECT, LEVEL, np.zeros(3))
    chain = np.array([[3.0, 2.0], [0.0, 2.0], [0.0, 1.6]])
    seen_low, seen_high = -0.3, -1.0
    none = np.zeros((0, 3))  # the camera sits on the end wall's line: it faces neither side
    np.testing.assert_allclose(_drop_end_sides(chain, [view], none, seen_low), chain[:2])
    np.testing.assert_allclose(_drop_end_sides(chain, [view], none, seen_high), chain)
    # The same at the source end, walked the other way round.
    source = np.array([[0.0, 1.6], [0.0, 2.0], [-3.0, 2.0]])
    np.testing.assert_allclose(_drop_end_sides(source, [view], none, seen_low), source[1:])
    # Deeper than furniture stands: the room's own.
    deep = np.array([[3.0, 2.0], [0.0, 2.0], [0.0, 1.1]])
    np.testing.assert_allclose(_drop_end_sides(deep, [view], none, seen_low), deep)
    # Of two short walls only the shorter can be a side.
    short = np.array([[0.5, 2.0], [0.0, 2.0], [0.0, 1.6]])
    np.testing.assert_allclose(_drop_end_sides(short, [view], none, seen_low), short[:2])
    # Turning away from the room is no furniture's side (a reveal: _drop_end_reveals).
    away = np.array([[3.0, 2.0], [0.0, 2.0], [0.0, 2.4]])
    np.testing.assert_allclose(_drop_end_sides(away, [view], none, seen_low), away)


def _face(a: tuple[float, float], b: tuple[float, float], z: tuple[float, float]) -> np.ndarray:
    """Points 3 cm apart on the upright rectangle over the floor-plan segment a-b."""
    t, height = np.meshgrid(np.linspace(0.0, 1.0, 40), np.arange(z[0], z[1], 0.03))
    xy = np.asarray(a) + t.ravel()[:, None] * (np.asarray(b) - np.asarray(a))
    return np.column_stack([xy, height.ravel()])


# Along y = 3 travelling -x (room below), the chain ends on a 0.8 m wall turning into the
# room at x = -1: a sofa's side (up to 1.05 m deep) or a wall. The level camera at the origin,
# 1.3 m over the floor, sees its columns from under the floor to over 2.4 m.
FLOOR = -1.3
SIDE_CHAIN = np.array([[2.0, 3.0], [-1.0, 3.0], [-1.0, 2.2]])
ROOM_WALL = _face((2.0, 3.0), (-1.8, 3.0), (FLOOR, FLOOR + 2.5))


def _sofa(top: float = FLOOR + 0.8) -> np.ndarray:
    seat_x, seat_y = np.meshgrid(np.arange(-1.8, -1.0, 0.03), np.arange(2.2, 3.0, 0.03))
    seat = np.column_stack([seat_x.ravel(), seat_y.ravel(), np.full(seat_x.size, top)])
    return np.vstack([_face((-1.0, 3.0), (-1.0, 2.2), (FLOOR, top)), seat, ROOM_WALL])


def test_an_end_wall_a_facing_camera_saw_over_is_dropped_as_a_furnitures_side() -> None:
    view = CameraView.from_intrinsics(KINECT, LEVEL, np.zeros(3))
    np.testing.assert_allclose(_drop_end_sides(SIDE_CHAIN, [view], _sofa(), FLOOR), SIDE_CHAIN[:2])
    # Deeper than a sofa stands: the room's own.
    deep = SIDE_CHAIN + np.array([[0.0, 0.0], [0.0, 0.0], [0.0, -0.4]])
    np.testing.assert_allclose(_drop_end_sides(deep, [view], _sofa(), FLOOR), deep)
    # A camera behind the side (a notch's wall seen from its far side) never looked over it.
    behind = CameraView.from_intrinsics(KINECT, LEVEL, np.array([-2.0, 0.0, 0.0]))
    np.testing.assert_allclose(_drop_end_sides(SIDE_CHAIN, [behind], _sofa(), FLOOR), SIDE_CHAIN)


def test_an_end_wall_is_kept_where_it_stands_high_or_the_view_over_it_was_blocked() -> None:
    view = CameraView.from_intrinsics(KINECT, LEVEL, np.zeros(3))
    # A wall with a doorway's gap in the middle: the view over that column is clear, but
    # the wall's points beside it stand higher than any furniture.
    wall = _face((-1.0, 3.0), (-1.0, 2.2), (FLOOR, FLOOR + 2.5))
    with_door = np.vstack([wall[(wall[:, 1] < 2.5) | (wall[:, 1] > 2.7)], ROOM_WALL])
    np.testing.assert_allclose(_drop_end_sides(SIDE_CHAIN, [view], with_door, FLOOR), SIDE_CHAIN)
    # A wall hidden behind a wardrobe (1.94 m high, 1.5 m from the camera) shows no points,
    # but no ray reached it either.
    wardrobe = _face((-1.2, 1.5), (-0.3, 1.5), (FLOOR, FLOOR + 1.94))
    hidden = np.vstack([wardrobe, ROOM_WALL])
    np.testing.assert_allclose(_drop_end_sides(SIDE_CHAIN, [view], hidden, FLOOR), SIDE_CHAIN)


def test_an_end_wall_seen_up_to_the_views_top_is_not_seen_over() -> None:
    # A 0.4 m wall whose points stop at 1.38 m over the floor because the view's top does
    # (at 1.38-1.52 m over these columns): no column was seen 0.3 m over its points.
    floor = -0.17
    chain = np.array([[2.0, 3.0], [-1.0, 3.0], [-1.0, 2.6]])
    view = CameraView.from_intrinsics(KINECT, LEVEL, np.zeros(3))
    points = np.vstack(
        [
            _face((-1.0, 3.0), (-1.0, 2.6), (floor, floor + 1.38)),
            _face((2.0, 3.0), (-1.0, 3.0), (floor, floor + 1.38)),
        ]
    )
    np.testing.assert_allclose(_drop_end_sides(chain, [view], points, floor), chain)


def test_the_cells_a_camera_saw_through_reach_its_wall_but_not_past_a_stray_point() -> None:
    view = CameraView.from_intrinsics(KINECT, LEVEL, np.zeros(3))
    wall = np.column_stack([np.linspace(-1.5, 1.5, 300), np.full(300, 3.0)])
    stray = np.array([[0.02, 6.0]])  # one point through a window
    cells = swept_cells([view], np.vstack([wall, stray]), 0.25)
    straight_ahead = cells[np.abs(cells[:, 0]) < 0.25]
    assert straight_ahead[:, 1].min() < 0.25  # from the camera on
    assert 2.5 < straight_ahead[:, 1].max() < 3.0  # up to the wall, not through it
    assert not (np.abs(cells[:, 0]) > 2.5).any()  # nothing outside the camera's wedge
    behind = swept_cells([view], np.array([[0.0, -3.0]]), 0.25)
    assert len(behind) == 0  # a point behind the camera is not one it saw
