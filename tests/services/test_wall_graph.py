"""Wall estimation graph and the chain between source and target."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from schemas.params import LayoutParams
from services.wall_graph import (
    _across_openings,
    _best_path,
    _build_nodes,
    _corners_only,
    _edges,
    _frustum_path,
    find_wall_chain,
)
from services.wall_lines import WallLine

pytestmark = pytest.mark.timeout(60)

CELL = 0.08


def _line(axis: int, offset: float, travel: int, spans: list[tuple[float, float]]) -> WallLine:
    origin = -2.0
    high = np.zeros(int(14.0 / CELL), dtype=bool)
    for lo, hi in spans:
        high[round((lo - origin) / CELL) : round((hi - origin) / CELL)] = True
    return WallLine(axis, offset, travel, origin, CELL, high, np.array(spans, dtype=np.float64))


@pytest.mark.parametrize("rule", ["spanning_forest", "evidence"])
def test_l_shaped_chain_with_an_occluded_corner(rule):
    # Wall along x at y = 0 (interior +y) seen from x = 0 to 4.5; wall along y at x = 5
    # (interior -x) seen from y = 0.6 to 3: the corner (5, 0) is occluded.
    lines = [_line(0, 0.0, 1, [(0.0, 4.5)]), _line(1, 5.0, 1, [(0.6, 3.0)])]
    chain = find_wall_chain(lines, LayoutParams(source_target=rule))
    assert chain is not None
    assert np.allclose(chain.keypoints, [[0.0, 0.0], [5.0, 0.0], [5.0, 3.0]], atol=0.05)


def test_corner_hidden_behind_a_wide_wardrobe_is_deduced():
    # As above, but a 2.5 m wardrobe in the corner hides the wall along y up to y = 2.5.
    lines = [_line(0, 0.0, 1, [(0.0, 4.4)]), _line(1, 5.0, 1, [(2.5, 5.0)])]
    chain = find_wall_chain(lines, LayoutParams())
    assert chain is not None
    assert np.allclose(chain.keypoints, [[0.0, 0.0], [5.0, 0.0], [5.0, 5.0]], atol=0.05)


def test_gap_of_a_door_stays_one_wall():
    lines = [_line(0, 1.0, 1, [(0.0, 2.0), (3.0, 6.0)])]
    chain = find_wall_chain(lines, LayoutParams())
    assert chain is not None
    assert np.allclose(chain.keypoints, [[0.0, 1.0], [6.0, 1.0]], atol=0.05)


def test_chain_follows_the_travel_direction():
    # Interior -y: the wall is travelled towards -x, so the source is its right end.
    lines = [_line(0, 2.0, -1, [(1.0, 4.0)])]
    chain = find_wall_chain(lines, LayoutParams())
    assert chain is not None
    assert chain.keypoints[0][0] == pytest.approx(4.0)
    assert chain.keypoints[-1][0] == pytest.approx(1.0)


def test_no_lines_no_chain():
    assert find_wall_chain([], LayoutParams()) is None


def _recess(mouth_seen_through: bool) -> list[WallLine]:
    """A wall along x at y = 0 (interior +y, x from 0 to 10) with a recess 3 m wide and 2 m
    deep below it between x = 3.5 and 6.5; the wall line has no evidence across the mouth."""
    main = _line(0, 0.0, 1, [(0.0, 3.5), (6.5, 10.0)])
    if mouth_seen_through:
        # The scan saw floor on both sides of the mouth: no wall stands there.
        flags = np.zeros_like(main.high)
        flags[round((3.6 - main.origin) / CELL) : round((6.4 - main.origin) / CELL)] = True
        main = dataclasses.replace(main, seen_through=flags)
    return [
        main,
        _line(1, 3.5, -1, [(-2.0, 0.0)]),  # down the recess's left side, interior +x
        _line(0, -2.0, 1, [(3.5, 6.5)]),  # its back, interior +y
        _line(1, 6.5, 1, [(-2.0, 0.0)]),  # back up its right side, interior -x
    ]


@pytest.mark.parametrize("seen_through", [False, True])
def test_chain_walks_around_a_recess_instead_of_across_its_mouth(seen_through):
    # The straight edge along y = 0 is cheaper per the paper's weight (8 of 10 m evidenced,
    # one edge), but the chain that explains the recess walls is the one that was seen.
    chain = find_wall_chain(_recess(seen_through), LayoutParams())
    assert chain is not None
    expected = np.array([[0, 0], [3.5, 0], [3.5, -2], [6.5, -2], [6.5, 0], [10, 0]], dtype=float)
    assert np.allclose(chain.keypoints, expected, atol=0.05)


def test_no_wall_runs_across_space_seen_on_both_sides():
    # Only the main wall: across the seen-through mouth the chain must stop, not bridge.
    chain = find_wall_chain(_recess(True)[:1], LayoutParams())
    assert chain is not None
    assert len(chain.keypoints) == 2
    assert abs(chain.keypoints[-1][0] - chain.keypoints[0][0]) == pytest.approx(3.5, abs=0.1)


def test_a_door_seen_through_is_still_bridged():
    main = _line(0, 1.0, 1, [(0.0, 2.0), (3.0, 6.0)])
    flags = np.zeros_like(main.high)
    flags[round((2.0 - main.origin) / CELL) : round((3.0 - main.origin) / CELL)] = True
    chain = find_wall_chain([dataclasses.replace(main, seen_through=flags)], LayoutParams())
    assert chain is not None
    assert np.allclose(chain.keypoints, [[0.0, 1.0], [6.0, 1.0]], atol=0.05)


def _ends_in_doorway(
    width: float, lintel: bool, source_side: bool, seen_behind: bool = True
) -> WallLine:
    """A wall along x at y = 1 (interior +y) seen from x = 0 to 3.04, the scan ending inside
    a doorway: floor seen behind the line over ``width`` m past the wall's right end (its
    left end when ``source_side``; nothing seen behind unless ``seen_behind``), with a wall
    over it when ``lintel``."""
    line = _line(0, 1.0, 1, [(0.0, 3.04)])  # 3.04: a cell boundary of the grid at -2
    lo, hi = (-width, 0.0) if source_side else (3.04, 3.04 + width)
    cells = slice(round((lo - line.origin) / CELL), round((hi - line.origin) / CELL))
    seen_through = np.zeros_like(line.high)
    seen_through[cells] = seen_behind
    over_opening = np.zeros_like(line.high)
    over_opening[cells] = lintel
    return dataclasses.replace(line, seen_through=seen_through, lintel=over_opening)


@pytest.mark.parametrize("source_side", [False, True])
def test_a_chain_that_stops_in_a_doorway_runs_on_under_its_lintel(source_side):
    chain = find_wall_chain([_ends_in_doorway(0.88, True, source_side)], LayoutParams())
    assert chain is not None
    expected = [[-0.88, 1.0], [3.04, 1.0]] if source_side else [[0.0, 1.0], [3.92, 1.0]]
    assert np.allclose(chain.keypoints, expected, atol=0.01)


@pytest.mark.parametrize(
    "width, lintel",
    [
        (0.88, False),  # space on both sides, nothing above: the room runs on past a corner
        (2.4, True),  # wider than a doorway
        (0.16, True),  # a sliver: a jamb's shadow, not a door
    ],
)
def test_a_chain_end_stays_without_a_doorway(width, lintel):
    chain = find_wall_chain([_ends_in_doorway(width, lintel, False)], LayoutParams())
    assert chain is not None
    assert np.allclose(chain.keypoints, [[0.0, 1.0], [3.04, 1.0]], atol=0.01)


@pytest.mark.parametrize("width, runs_on", [(0.88, True), (0.4, False)])
def test_a_wall_hidden_below_by_tall_furniture_runs_on_if_long_enough(width, runs_on):
    # Wall seen only above door height and nothing seen behind it: a wardrobe hides its
    # lower part. A short such run is a corner's clutter, not wall.
    line = _ends_in_doorway(width, lintel=True, source_side=False, seen_behind=False)
    chain = find_wall_chain([line], LayoutParams())
    assert chain is not None
    end = 3.04 + (width if runs_on else 0.0)
    assert np.allclose(chain.keypoints, [[0.0, 1.0], [end, 1.0]], atol=0.01)


def _flags(line: WallLine, spans: list[tuple[float, float]]) -> np.ndarray:
    flags = np.zeros_like(line.high)
    for lo, hi in spans:
        flags[round((lo - line.origin) / CELL) : round((hi - line.origin) / CELL)] = True
    return flags


def _seen_room(bottom_high: list[tuple[float, float]], top_spans: list[tuple[float, float]]):
    """A 6 x 4 m room seen all around, interior inside. The bottom wall holds wall points
    all along, high evidence only over ``bottom_high``; the top wall holds wall points (all
    high) only over ``top_spans``, and between them the scan saw nothing (no wall points, no
    space behind the line). The sides are seen whole."""
    bottom = _line(0, 0.0, 1, bottom_high)
    bottom = dataclasses.replace(
        bottom, occupied=_flags(bottom, [(0.0, 6.0)]), seen_through=_flags(bottom, [])
    )
    top = _line(0, 4.0, -1, top_spans)
    top = dataclasses.replace(top, occupied=_flags(top, top_spans), seen_through=_flags(top, []))
    sides = [_line(1, 6.0, 1, [(0.0, 4.0)]), _line(1, 0.0, -1, [(0.0, 4.0)])]
    sides = [
        dataclasses.replace(s, occupied=s.high.copy(), seen_through=_flags(s, [])) for s in sides
    ]
    return [bottom, top, *sides]


def _room_seen_all_around(bottom_low: tuple[float, float], top_gap: tuple[float, float]):
    """The room of :func:`_seen_room` with a cabinet hiding the bottom wall's lower part
    over ``bottom_low`` (wall points above it, none high enough to be high evidence) and
    nothing seen of the top wall over ``top_gap``: where the scan stopped."""
    return _seen_room(
        [(0.0, bottom_low[0]), (bottom_low[1], 6.0)], [(0.0, top_gap[0]), (top_gap[1], 6.0)]
    )


@pytest.mark.parametrize(
    ("top_gap", "cabinet"),
    [
        ((1.0, 2.5), (4.5, 5.5)),
        ((1.5, 3.0), (3.5, 4.5)),
        ((2.0, 3.5), (3.5, 4.5)),
        # The chain opening at the unseen stretch starts 1.5 m or more before its first
        # corner: the path bridging the stretch held that corner in the one-path-per-state
        # search, so these opened at the cabinet until the search ran again without bridges.
        ((1.5, 3.0), (4.5, 5.5)),
        ((2.5, 4.0), (3.5, 4.5)),
        ((3.0, 4.5), (4.5, 5.5)),
    ],
)
def test_a_chain_seen_all_around_opens_where_nothing_was_seen(top_gap, cabinet):
    # Neither stretch has high evidence; only the top one shows no wall at all. A cabinet in
    # front of a wall is no place for the scan's end, the unseen stretch is: the chain runs
    # along the whole bottom wall and ends where the top wall's gap begins.
    chain = find_wall_chain(_room_seen_all_around(cabinet, top_gap), LayoutParams())
    assert chain is not None
    corners = [[0.0, 0.0], [6.0, 0.0], [6.0, 4.0]]
    assert any(np.allclose(chain.keypoints[k : k + 3], corners, atol=0.1) for k in range(3))
    assert np.allclose(chain.keypoints[-1], [top_gap[1], 4.0], atol=0.1)


@pytest.mark.parametrize("split", [0.5, 1.0, 2.0])
def test_a_chain_opens_at_the_unseen_stretch_however_many_edges_bridge_it(split):
    # The top wall's seen part left of the gap is two runs meeting at ``split``: a node lies
    # there, so several edges bridge the gap, and a path bridging it held the corner the
    # right chain starts from (the best chain did not even bridge it when split = 2).
    room = _seen_room([(0.0, 6.0)], [(0.0, split), (split, 2.5), (4.0, 6.0)])
    chain = find_wall_chain(room, LayoutParams())
    assert chain is not None
    assert np.allclose(chain.keypoints[0], [2.5, 4.0], atol=0.1)
    assert np.allclose(chain.keypoints[-1], [4.0, 4.0], atol=0.1)
    assert len(chain.keypoints) == 6  # once around, no wall run twice


@pytest.mark.parametrize(("price", "corners"), [(0.3, 0), (0.2, 1)])
def test_a_corner_is_taken_when_its_wall_pays_its_price(price: float, corners: int) -> None:
    # 3 m of wall along x, then a turn onto 0.25 m of wall along y: the turn adds less wall
    # than a cloud's price for a corner (0.3 m) and more than a frame's (0.2 m).
    lines = [_line(0, 0.0, 1, [(0.0, 3.0)]), _line(1, 3.0, 1, [(0.0, 0.25)])]
    nodes = _build_nodes(lines)
    we, _, cover, unseen = _edges(lines, nodes, LayoutParams().complexity_penalty)
    found = _best_path(we, cover, unseen, np.asarray(nodes.points), price)
    assert found is not None
    keypoints = _corners_only(np.array([nodes.points[i] for i in found[0]]))
    assert len(keypoints) - 2 == corners


def _doorway(lintel: bool, width: float = 1.0) -> list[WallLine]:
    """A wall along x at y = 0 (interior +y, x from 0 to 10) with an opening ``width`` m wide
    from x = 4.5, space seen on both sides of it, and behind it the next room's far wall
    (y = -1.5) and the opening's sides, seen edge-on; the wall across the opening is seen
    only high up when ``lintel`` (a door), not at all otherwise (an alcove open to the
    ceiling)."""
    lo, hi = 4.5, 4.5 + width
    main = _line(0, 0.0, 1, [(0.0, lo), (hi, 10.0)])
    mouth = np.zeros_like(main.high)
    mouth[round((lo + 0.08 - main.origin) / CELL) : round((hi - 0.08 - main.origin) / CELL)] = True
    main = dataclasses.replace(main, seen_through=mouth, lintel=mouth & lintel)
    return [
        main,
        _line(1, lo, -1, [(-1.5, 0.0)]),
        _line(0, -1.5, 1, [(lo, hi)]),
        _line(1, hi, 1, [(-1.5, 0.0)]),
    ]


@pytest.mark.parametrize(("lintel", "width"), [(True, 1.0), (False, 1.0), (True, 2.5)])
def test_a_chain_does_not_run_out_through_a_doorway(lintel: bool, width: float) -> None:
    # The chain explaining the most wall runs out through the opening, along the far wall
    # and back; under a lintel, and no wider than a doorway, the opening is a door and the
    # chain runs across it. An alcove (no lintel) or a wider opening keeps its walls.
    chain = find_wall_chain(_doorway(lintel, width), LayoutParams())
    assert chain is not None
    lo, hi = 4.5, 4.5 + width
    detour = [[0, 0], [lo, 0], [lo, -1.5], [hi, -1.5], [hi, 0], [10, 0]]
    expected = [[0, 0], [10, 0]] if lintel and width <= 2.0 else detour
    assert np.allclose(chain.keypoints, np.array(expected, dtype=float), atol=0.05)


def _wall_with_opening(
    axis: int,
    travel: int,
    spans: list[tuple[float, float]],
    opening: tuple[float, float],
    standing: bool,
) -> WallLine:
    """A wall line whose wall is seen over ``spans`` and, when ``standing``, only high up over
    ``opening`` (a window's lintel); nothing there otherwise (the room steps out)."""
    line = _line(axis, 0.0 if axis else 2.0, travel, spans if standing else spans[:1])
    lintel = np.zeros_like(line.high)
    lo, hi = sorted(opening)
    lintel[round((lo - line.origin) / CELL) : round((hi - line.origin) / CELL)] = standing
    return dataclasses.replace(line, lintel=lintel)


@pytest.mark.parametrize("standing", [True, False])
def test_a_chain_does_not_run_out_through_an_opening_before_a_corner(standing: bool) -> None:
    # Up the wall x = 0 (interior -x), out through an opening at y = 0..1.5 to the next
    # room's far wall 1.3 m behind, up it, and back along the top wall (y = 2) past the
    # corner (0, 2): the chain should have turned at the corner. Without wall across the
    # opening, the room itself steps out there.
    chain = np.array([[0.0, -3.0], [0.0, 0.0], [1.3, 0.0], [1.3, 2.0], [-3.0, 2.0]])
    wall = _wall_with_opening(1, 1, [(-3.0, 0.0), (1.5, 2.0)], (0.0, 1.5), standing)
    kept = _across_openings(chain, [wall])
    expected = [[0.0, -3.0], [0.0, 2.0], [-3.0, 2.0]] if standing else chain
    assert np.allclose(kept, expected)


@pytest.mark.parametrize("standing", [True, False])
def test_a_chain_does_not_run_out_through_an_opening_after_a_corner(standing: bool) -> None:
    # Up the wall x = 0 past the corner (0, 2), through an opening in the top wall (y = 2,
    # interior -y, x = -1.5..0) to the next room's far wall at y = 3.3, along it, back in
    # and along the top wall: the chain should have turned at the corner.
    chain = np.array([[0.0, -3.0], [0.0, 3.3], [-1.5, 3.3], [-1.5, 2.0], [-5.0, 2.0]])
    wall = _wall_with_opening(0, -1, [(-5.0, -1.5), (-0.2, 0.0)], (-1.5, 0.0), standing)
    kept = _across_openings(chain, [wall])
    expected = [[0.0, -3.0], [0.0, 2.0], [-5.0, 2.0]] if standing else chain
    assert np.allclose(kept, expected)


def test_a_chain_seen_nearly_all_around_keeps_the_wall_it_starts_along() -> None:
    # A U room (7.1 x 9 m, a 2.6 m wide notch 7.2 m deep into its top) seen by one scan
    # along every wall but the right side's top half and the notch's top: the scan starts
    # 2.95 m up the notch's right side, runs down it, round the notch, the left arm, the
    # bottom and ends 4 m up the right side. In the one-path-per-state search the best path
    # into the notch's left side came back round the room, holding a node the whole chain
    # needed: the chain began at the notch's corner and dropped the 5.6 m it starts along.
    lines = [
        _line(0, 1.5, 1, [(2.44, 9.56)]),  # bottom, interior +y
        _line(0, 3.31, -1, [(4.12, 6.68)]),  # the notch's bottom, interior -y
        _line(0, 10.5, -1, [(2.44, 4.12)]),  # the left arm's top, interior -y
        _line(1, 2.46, -1, [(1.51, 4.23), (5.35, 10.47)]),  # left side with a door
        _line(1, 4.1, 1, [(3.35, 10.47)]),  # the notch's left side, interior -x
        _line(1, 6.69, -1, [(3.35, 8.95)]),  # the notch's right side, interior +x
        _line(1, 9.54, 1, [(1.51, 5.51)]),  # right side, interior -x
    ]
    chain = find_wall_chain(lines, LayoutParams())
    assert chain is not None
    assert np.allclose(chain.keypoints[0], [6.69, 8.95], atol=0.1)
    assert np.allclose(chain.keypoints[1], [6.69, 3.31], atol=0.1)
    assert np.allclose(chain.keypoints[-1], [9.54, 5.51], atol=0.1)
    assert len(chain.keypoints) == 8


def test_a_frame_chain_shows_the_camera_a_wall_from_inside() -> None:
    """A camera at the origin looking along +y. The widest pair of keypoints in view joins
    a wall 1.5 m ahead whose inner side faces away from the camera (deduced behind a
    shelf, say); the far wall faces it. No camera in the room sees a wall only from
    behind: the chain is the far wall."""
    from scipy.sparse import csr_matrix

    from services.frustum import CameraView
    from services.rgbd import OPTICAL_TO_LEVEL
    from services.synthetic.render import KINECT

    points = np.array([[-1.0, 1.5], [1.0, 1.5], [1.0, 4.8], [-1.6, 4.8]])
    # Directed edges keep the interior on the left: 0 -> 1 has it beyond, 2 -> 3 before.
    weights = csr_matrix((np.ones(2), ([0, 2], [1, 3])), shape=(4, 4))
    view = CameraView.from_intrinsics(KINECT, OPTICAL_TO_LEVEL, np.zeros(3))
    found = _frustum_path(weights, points, [view])
    assert found is not None
    assert found[0] == [2, 3]


@pytest.mark.parametrize("deduced", [True, False])
def test_a_deduced_wall_makes_no_corner_past_the_step_it_bridges(deduced: bool) -> None:
    """One camera saw a wall along y at x = -1.2 end at y = 1 and a farther one at
    x = -3.7 (an arm of an L behind a pier): the hidden wall between them runs along
    x at y = 1 from x = -3.7 to -1.2. A wall along y at x = 1.4, seen from y = 1.4 on,
    would meet that line 2.6 m past the bridge's end, across floor the camera saw: a
    seen wall may be carried that far to a corner, a deduced one not."""
    from services.wall_lines import _bridge

    near = _line(1, -1.2, -1, [(0.5, 1.0)])
    far = _line(1, -3.7, -1, [(3.0, 3.8)])
    step = _bridge(far, near, 1.0) if deduced else _line(0, 1.0, 1, [(-3.7, -1.2)])
    side = _line(1, 1.4, 1, [(1.4, 3.8)])
    nodes = _build_nodes([near, far, step, side])
    corner = np.array([1.4, 1.0])
    found = any(np.allclose(p, corner, atol=1e-6) for p in nodes.points)
    assert found is not deduced


@pytest.mark.parametrize(("camera", "runner_up"), [("kinect", True), ("wide", False)])
def test_a_frame_keeps_the_chain_it_did_not_take_as_its_runner_up(
    camera: str, runner_up: bool
) -> None:
    # A camera 6 m in front of the recess's wall, looking at it. A kinect's view holds the
    # recess alone: the frustum's chain is the recess, the chain explaining the most wall
    # runs on along the wall both ways and is taken; the recess alone is its runner-up. A
    # wide camera sees the same chain both ways: no runner-up.
    from services.frustum import CameraView
    from services.rgbd import OPTICAL_TO_LEVEL
    from services.synthetic.render import CAMERAS

    facing_down = np.diag([-1.0, -1.0, 1.0])  # the level frame turned to look along -y
    view = CameraView.from_intrinsics(
        CAMERAS[camera], facing_down @ OPTICAL_TO_LEVEL, np.array([5.0, 6.0, 1.2])
    )
    chain = find_wall_chain(_recess(False), LayoutParams(), [view])
    assert chain is not None
    whole = np.array([[0, 0], [3.5, 0], [3.5, -2], [6.5, -2], [6.5, 0], [10, 0]], dtype=float)
    assert np.allclose(chain.keypoints, whole, atol=0.05)
    if runner_up:
        assert chain.runner_up is not None
        assert np.allclose(chain.runner_up, whole[1:-1], atol=0.05)
    else:
        assert chain.runner_up is None
    cloud = find_wall_chain(_recess(False), LayoutParams())
    assert cloud is not None and cloud.runner_up is None  # no views: no runner-up
