"""Candidate walls on the projection grid: evidence threshold, boundary test, bridges."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from schemas.params import LayoutParams
from services.frustum import CameraView
from services.pipeline import estimate_layout
from services.rgbd import OPTICAL_TO_LEVEL
from services.synthetic import SceneSpec, generate_scene
from services.synthetic.render import KINECT
from services.wall_graph import find_wall_chain
from services.wall_lines import (
    MAX_OPEN_ABOVE,
    WallLine,
    _closes_an_arm,
    _doors_closed,
    _faces_away,
    _Horizon,
    _make_grid,
    _occluded_links,
    _runs,
    _seen_through_opening,
    _shadowed,
    evidence_threshold,
    find_wall_lines,
)

pytestmark = pytest.mark.timeout(60)


def _box_room(rng: np.random.Generator, furniture: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Thinned-looking points and normals of two walls (y = 0 and x = 6) of a room whose
    interior is y > 0, x < 6, plus its floor; optionally a free-standing cabinet."""
    walls = []
    normals = []
    x = rng.uniform(0, 6, 6000)
    z = rng.uniform(0, 2.6, 6000)
    walls.append(np.column_stack([x, np.zeros_like(x), z]))
    normals.append(np.tile([0.0, 1.0, 0.0], (6000, 1)))
    y = rng.uniform(0, 4, 4000)
    z = rng.uniform(0, 2.6, 4000)
    walls.append(np.column_stack([np.full_like(y, 6.0), y, z]))
    normals.append(np.tile([-1.0, 0.0, 0.0], (4000, 1)))
    floor = np.column_stack([rng.uniform(0, 6, 8000), rng.uniform(0, 4, 8000), np.zeros(8000)])
    walls.append(floor)
    normals.append(np.tile([0.0, 0.0, 1.0], (8000, 1)))
    if furniture:  # a 1.2 m tall cabinet face in the middle of the room
        fx = rng.uniform(2, 3.5, 1500)
        fz = rng.uniform(0, 1.2, 1500)
        walls.append(np.column_stack([fx, np.full_like(fx, 2.0), fz]))
        normals.append(np.tile([0.0, -1.0, 0.0], (1500, 1)))
    return np.vstack(walls), np.vstack(normals)


def test_finds_both_walls_with_their_interior_side():
    points, normals = _box_room(np.random.default_rng(0))
    lines = [
        ln for ln in find_wall_lines(points, normals, 0.0, 2.6, LayoutParams()) if not ln.virtual
    ]
    by_axis = {ln.axis: ln for ln in lines}
    assert set(by_axis) == {0, 1}
    assert by_axis[0].offset == pytest.approx(0.0, abs=0.02)
    assert by_axis[1].offset == pytest.approx(6.0, abs=0.02)
    # Interior +y for the wall along x: travelled +x. Interior -x for the wall along y:
    # travelled +y. Both keep the interior on the left.
    assert by_axis[0].travel == 1
    assert by_axis[1].travel == 1


def test_stray_points_behind_a_wall_do_not_hide_it():
    # Outliers (and reflections) scattered behind both walls, with random normals, as many
    # per column as the floor has: the walls must still bound the scanned space.
    rng = np.random.default_rng(4)
    points, normals = _box_room(rng)
    stray = np.column_stack(
        [rng.uniform(-1.0, 7.0, 16000), rng.uniform(-1.0, 5.0, 16000), rng.uniform(0, 2.6, 16000)]
    )
    behind = (stray[:, 1] < -0.15) | (stray[:, 0] > 6.15)
    directions = rng.normal(size=(int(behind.sum()), 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    points = np.vstack([points, stray[behind]])
    normals = np.vstack([normals, directions])
    lines = [
        ln for ln in find_wall_lines(points, normals, 0.0, 2.6, LayoutParams()) if not ln.virtual
    ]
    assert {(ln.axis, round(ln.offset)) for ln in lines} >= {(0, 0), (1, 6)}


def test_gap_tests_see_past_the_last_segment():
    # A wall along x at y = 0 seen from x = 0 to 3, then open floor on both sides of its
    # line up to x = 6: a path following the line on (to a deduced corner) would cross it.
    rng = np.random.default_rng(6)
    x, z = rng.uniform(0, 3, 4000), rng.uniform(0, 2.6, 4000)
    wall = np.column_stack([x, np.zeros_like(x), z])
    floor = np.column_stack([rng.uniform(0, 6, 12000), rng.uniform(-3, 4, 12000), np.zeros(12000)])
    floor = floor[(floor[:, 0] > 3.2) | (floor[:, 1] > 0.0)]
    points = np.vstack([wall, floor])
    normals = np.vstack(
        [np.tile([0.0, 1.0, 0.0], (len(wall), 1)), np.tile([0, 0, 1.0], (len(floor), 1))]
    )
    lines = [
        ln for ln in find_wall_lines(points, normals, 0.0, 2.6, LayoutParams()) if ln.axis == 0
    ]
    assert len(lines) == 1 and lines[0].segments[-1, 1] < 3.1
    assert lines[0].crossing_gap(3.0, 6.0) > 2.0
    # A cell with too few points behind the line (a sparse patch) does not split the gap.
    patch = (floor[:, 0] > 4.5) & (floor[:, 0] < 4.58) & (floor[:, 1] < 0.0)
    sparse = np.vstack([wall, floor[~patch]])
    normals = normals[np.concatenate([np.ones(len(wall), bool), ~patch])]
    lines = [
        ln for ln in find_wall_lines(sparse, normals, 0.0, 2.6, LayoutParams()) if ln.axis == 0
    ]
    assert lines[0].crossing_gap(3.0, 6.0) > 2.0


def test_short_furniture_is_not_a_wall():
    points, normals = _box_room(np.random.default_rng(1), furniture=True)
    lines = find_wall_lines(points, normals, 0.0, 2.6, LayoutParams())
    assert not any(ln.axis == 0 and abs(ln.offset - 2.0) < 0.1 for ln in lines)


def _corner_with_wardrobe(rng: np.random.Generator, height: float) -> tuple[np.ndarray, np.ndarray]:
    """Points and normals of walls y = 0 and x = 6 (2.6 m high, interior y > 0, x < 6),
    the floor, and a wardrobe ``height`` tall against x = 6 at y 3-4, where the scan ends:
    its front x = 5.4 and its side y = 3 face the room, and the wall over it shows (its top,
    above the scanner, does not)."""

    def face(
        n: int, lo: list[float], hi: list[float], normal: list[float]
    ) -> tuple[np.ndarray, np.ndarray]:
        return rng.uniform(lo, hi, size=(n, 3)), np.tile(normal, (n, 1))

    parts = [
        face(6000, [0, 0, 0], [6, 0, 2.6], [0.0, 1.0, 0.0]),
        face(3000, [6, 0, 0], [6, 3, 2.6], [-1.0, 0.0, 0.0]),
        face(500, [6, 3, height], [6, 4, 2.6], [-1.0, 0.0, 0.0]),
        face(1000, [5.4, 3, 0], [5.4, 4, height], [-1.0, 0.0, 0.0]),
        face(600, [5.4, 3, 0], [6, 3, height], [0.0, -1.0, 0.0]),
        face(8000, [0, 0, 0], [6, 3, 0], [0.0, 0.0, 1.0]),
        face(2000, [0, 3, 0], [5.4, 4, 0], [0.0, 0.0, 1.0]),
    ]
    return np.vstack([p for p, _ in parts]), np.vstack([n for _, n in parts])


@pytest.mark.parametrize(("height", "wall"), [(2.25, False), (2.6, True)])
def test_a_wardrobe_short_of_the_ceiling_is_not_a_wall(height: float, wall: bool) -> None:
    # 2.25 m of a 2.6 m room reaches high, yet walls reach the ceiling: at a scan's end, a
    # wardrobe's side taken for a wall turned the chain into a corner the room does not have.
    points, normals = _corner_with_wardrobe(np.random.default_rng(3), height)
    lines = find_wall_lines(points, normals, 0.0, 2.6, LayoutParams())
    side = [ln for ln in lines if ln.axis == 0 and abs(ln.offset - 3.0) < 0.1]
    assert bool(side) == wall
    assert any(ln.axis == 0 and abs(ln.offset) < 0.1 for ln in lines)  # the room's walls
    assert any(ln.axis == 1 and abs(ln.offset - 6.0) < 0.1 for ln in lines)


@pytest.mark.parametrize(("seen_behind", "wall"), [(False, True), (True, False)])
def test_a_wall_seen_only_over_tall_furniture_is_a_wall(seen_behind: bool, wall: bool) -> None:
    # Wardrobes 2 m tall along the whole of x = 6 (y 0-3, front x = 5.4) leave only the
    # wall's top 0.6 m in view. With floor seen behind it, the same top is a lintel over an
    # opening, not wall bounding the room.
    rng = np.random.default_rng(5)
    points, normals = _corner_with_wardrobe(rng, 2.0)
    keep = ~((np.abs(points[:, 0] - 6.0) < 1e-9) & (points[:, 2] < 2.0))
    facing_room, up = np.array([-1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
    faces = [
        (points[keep], normals[keep]),
        (rng.uniform([6, 0, 2.0], [6, 3, 2.6], size=(1500, 3)), facing_room),  # over
        (rng.uniform([5.4, 0, 0], [5.4, 3, 2.0], size=(3000, 3)), facing_room),  # front
    ]
    if seen_behind:
        faces.append((rng.uniform([6.2, 0, 0], [7.0, 3, 0], size=(2000, 3)), up))
    points = np.vstack([p for p, _ in faces])
    normals = np.vstack([np.broadcast_to(n, p.shape) for p, n in faces])
    lines = find_wall_lines(points, normals, 0.0, 2.6, LayoutParams())
    back = [ln for ln in lines if ln.axis == 1 and abs(ln.offset - 6.0) < 0.1 and ln.travel == 1]
    covered = sum(float(b - a) for ln in back for a, b in ln.segments if b > 0.5 and a < 2.5)
    assert (covered > 1.5) == wall


def test_a_thin_scans_wall_whose_columns_miss_their_top_here_and_there_is_still_a_wall() -> None:
    # A thin scan leaves most of a wall's columns short of the top: keep the top 0.4 m of
    # the wall y = 0 in one 8 cm column of every four only.
    points, normals = _box_room(np.random.default_rng(1))
    x, y, z = points.T
    column = np.floor(x / LayoutParams().cell_size).astype(int)
    cut = (np.abs(y) < 1e-9) & (z > 2.2) & (column % 4 != 0) & (np.abs(normals[:, 1]) > 0.5)
    lines = find_wall_lines(points[~cut], normals[~cut], 0.0, 2.6, LayoutParams(), thin=True)
    wall = [ln for ln in lines if ln.axis == 0 and abs(ln.offset) < 0.1]
    assert len(wall) == 1 and len(wall[0].segments) == 1
    assert wall[0].segments[0, 0] < 0.1 and wall[0].segments[0, 1] > 5.9
    # A dense scan's column shows its own top: there the wall breaks up.
    dense = find_wall_lines(points[~cut], normals[~cut], 0.0, 2.6, LayoutParams())
    assert not any(ln.axis == 0 and abs(ln.offset) < 0.1 for ln in dense)


def test_threshold_follows_room_height_and_sensor_density():
    params = LayoutParams()
    dense = np.full(100, 40, dtype=np.int64)
    assert evidence_threshold(dense, band=2.4, params=params) == 15  # half the band: 1.2 m
    assert evidence_threshold(dense, band=3.5, params=params) == 20  # the paper's N
    sparse = np.full(100, 8, dtype=np.int64)  # a 16-ring LiDAR fills few height bins
    assert evidence_threshold(sparse, band=2.8, params=params) == 4
    assert evidence_threshold(np.zeros(0, dtype=np.int64), band=10.0, params=params) == 20


def test_runs_bridge_small_gaps_and_drop_short_runs():
    mask = np.array([1, 1, 0, 1, 1, 0, 0, 0, 1, 1, 1, 1, 0, 1], dtype=bool)
    assert _runs(mask, max_gap=2, min_len=3) == [(0, 5), (8, 14)]
    assert _runs(mask, max_gap=0, min_len=3) == [(8, 12)]
    assert _runs(np.zeros(5, dtype=bool), 2, 3) == []


def _wall(rng: np.random.Generator, start: tuple[float, float], end: tuple[float, float]):
    """Points of a 2.6 m high wall from start to end (x, y), 1500 per meter."""
    n = int(1500 * np.hypot(end[0] - start[0], end[1] - start[1]))
    t = rng.uniform(0, 1, n)
    xy = np.asarray(start) + t[:, None] * (np.asarray(end) - np.asarray(start))
    return np.column_stack([xy, rng.uniform(0, 2.6, n)])


def test_hidden_back_of_a_shallow_alcove_is_deduced():
    # A corridor wall at x = 0 (interior -x) up to y = 0, then an alcove 1 m deep whose back
    # wall at x = 1 starts at y = 0.1; the alcove's side wall (y = 0, x from 0 to 1) is
    # hidden. The deduced side wall must be found even though its strips run along the
    # corridor wall at its ends.
    rng = np.random.default_rng(3)
    parts = [_wall(rng, (0.0, -5.0), (0.0, 0.0)), _wall(rng, (1.0, 0.1), (1.0, 2.0))]
    floor = np.column_stack([rng.uniform(-2, 0, 8000), rng.uniform(-5, 2, 8000), np.zeros(8000)])
    alcove = np.column_stack([rng.uniform(0, 1, 1500), rng.uniform(0, 2, 1500), np.zeros(1500)])
    points = np.vstack([*parts, floor, alcove])
    normals = np.vstack(
        [
            np.tile([1.0, 0.0, 0.0], (len(parts[0]) + len(parts[1]), 1)),
            np.tile([0.0, 0.0, 1.0], (len(floor) + len(alcove), 1)),
        ]
    )
    lines = find_wall_lines(points, normals, 0.0, 2.6, LayoutParams())
    deduced = [ln for ln in lines if ln.virtual and ln.axis == 0]
    assert any(abs(ln.offset) < 0.15 for ln in deduced)


def test_a_histogram_peak_without_points_near_it_is_skipped():
    # Regression: a sparse world-preset fragment whose offset histogram peaked between its
    # points made find_wall_lines take the median of nothing and crash.
    spec = dataclasses.replace(
        SceneSpec.world(),
        n_fragments_range=(9, 12),
        size_range=((2.0, 5.0), (18.0, 20.0)),  # the preset's rooms until 2026-12-05
        no_ceiling_share=0.0,
    )
    fragment = next(f for f in generate_scene(spec, 203008).fragments if f.id == "frag_01")
    layout = estimate_layout(fragment.points)
    assert layout.ok


def _occupied_line(occupied: np.ndarray, axis: int = 0, offset: float = 0.0) -> WallLine:
    """A line at ``offset`` whose cells (0.1 m from run 0) hold wall points where ``occupied``."""
    return WallLine(
        axis=axis,
        offset=offset,
        travel=1,
        origin=0.0,
        cell_size=0.1,
        high=occupied.copy(),
        segments=np.array([[0.0, 0.1 * len(occupied)]]),
        virtual=False,
        occupied=occupied,
    )


def test_doors_of_a_nearer_wall_are_closed_unless_they_open_onto_a_recess() -> None:
    # Wall points on [0, 1) m, a 1 m door, points on [2, 3) m, a 2.5 m gap, points again.
    occupied = np.zeros(80, dtype=bool)
    occupied[:10] = occupied[20:30] = occupied[55:] = True
    near = _occupied_line(occupied)
    closed = _doors_closed(near, [near], away=-1.0)
    assert closed[10:20].all()  # the door
    assert not closed[30:55].any()  # too wide for a door: the wall ends there
    # A wall leaves the door's edge 1 m away from the camera: a recess of the room.
    side = dataclasses.replace(
        _occupied_line(np.ones(10, dtype=bool), axis=1, offset=1.0),
        segments=np.array([[-1.0, 0.0]]),
    )
    assert not _doors_closed(near, [near, side], away=-1.0)[10:20].any()
    # Nor when the wall leaves at the far end of the points beside the gap (a cabinet's face
    # at the line, in a wing of the room whose side wall stands beyond it).
    wing = dataclasses.replace(side, offset=2.9)
    assert not _doors_closed(near, [near, wing], away=-1.0)[10:20].any()
    # The door's reveal (the wall's 0.15 m thickness) is no recess.
    reveal = dataclasses.replace(side, segments=np.array([[-0.15, 0.0]]))
    assert _doors_closed(near, [near, reveal], away=-1.0)[10:20].all()


def test_a_wall_is_in_shadow_where_a_nearer_wall_stands_between_it_and_the_camera() -> None:
    # The camera at (2.7, 1.3); a block's side at x = 3.9 for y in [2, 3]; the room's wall at
    # x = 5 behind it: hidden where the sight line crosses the side, y in [2.64, 4.56].
    wall = _occupied_line(np.ones(70, dtype=bool), axis=1, offset=5.0)
    side = dataclasses.replace(
        _occupied_line(np.ones(70, dtype=bool), axis=1, offset=3.9), segments=np.array([[2.0, 3.0]])
    )
    y = 0.1 * np.arange(70) + 0.05
    hidden = _shadowed(wall, [wall, side], np.array([2.7, 1.3]))
    np.testing.assert_array_equal(hidden, (y > 2.64) & (y < 4.56))
    # A wall does not shadow itself, nor does one behind it.
    behind = dataclasses.replace(side, offset=6.0)
    assert not _shadowed(wall, [wall, behind], np.array([2.7, 1.3])).any()


@pytest.mark.parametrize("lintel", [True, False])
def test_a_door_at_a_walls_end_is_told_by_its_lintel(lintel):
    # A wall along x at y = 0 (interior +y) from x = 0 to 3, then a doorway to x = 3.9:
    # floor seen through it behind the line, and the wall over the door (z 2.05 to 2.6)
    # when ``lintel``; without one, the line just runs on past the wall's end.
    rng = np.random.default_rng(8)
    x, z = rng.uniform(0, 3, 4000), rng.uniform(0, 2.6, 4000)
    parts = [np.column_stack([x, np.zeros_like(x), z])]
    if lintel:
        x, z = rng.uniform(3, 3.9, 600), rng.uniform(2.05, 2.6, 600)
        parts.append(np.column_stack([x, np.zeros_like(x), z]))
    wall = np.vstack(parts)
    floor = np.column_stack(
        [rng.uniform(0, 3.9, 12000), rng.uniform(-1.5, 4, 12000), np.zeros(12000)]
    )
    floor = floor[(floor[:, 0] > 3.05) | (floor[:, 1] > 0.0)]
    points = np.vstack([wall, floor])
    normals = np.vstack(
        [np.tile([0.0, 1.0, 0.0], (len(wall), 1)), np.tile([0, 0, 1.0], (len(floor), 1))]
    )
    (line,) = [
        ln for ln in find_wall_lines(points, normals, 0.0, 2.6, LayoutParams()) if ln.axis == 0
    ]
    end = float(line.segments[-1, 1])
    assert end == pytest.approx(3.0, abs=0.1)
    reach = line.high_wall_beyond(end, 1)
    assert reach == (pytest.approx(0.9, abs=0.1) if lintel else 0.0)
    assert line.high_wall_beyond(float(line.segments[0, 0]), -1) == 0.0  # nothing seen there


@pytest.mark.parametrize(
    ("lead", "reach"),
    [("jamb", 1.6), ("nothing seen", 0.0), ("too long", 0.0)],
)
def test_a_walls_end_is_carried_to_a_lintel_across_wall_seen_in_part(lead, reach):
    # Whole wall up to 3.0 m (cells of 0.1 m), then wall seen only in part (a jamb, a low
    # cabinet) before a lintel over a doorway with space seen behind it.
    high = np.zeros(80, dtype=bool)
    high[:30] = True
    lintel = np.zeros(80, dtype=bool)
    start = 44 if lead == "too long" else 34  # 1.4 m of partly seen wall: beyond the reach
    lintel[start : start + 12] = True
    occupied = high | lintel
    if lead != "nothing seen":
        occupied[30:start] = True
    seen_through = np.zeros(80, dtype=bool)
    seen_through[30 : start + 12] = True
    line = dataclasses.replace(
        _occupied_line(occupied), high=high, lintel=lintel, seen_through=seen_through
    )
    assert line.high_wall_beyond(3.0, 1) == pytest.approx(reach)


def test_high_evidence_beyond_a_point_is_measured_along_the_line() -> None:
    high = np.zeros(50, dtype=bool)
    high[10:20] = True  # cells of 0.1 m from run 0: high from 1.0 to 2.0 m
    high[21:23] = True  # a one-cell gap is bridged
    line = WallLine(0, 0.0, 1, 0.0, 0.1, high, np.array([[1.0, 2.3]]))
    assert line.high_run_beyond(0.95, 1) == pytest.approx(2.3 - 1.0)  # starts a cell on
    assert line.high_run_beyond(2.35, -1) == pytest.approx(2.3 - 1.0, abs=0.11)
    assert line.high_run_beyond(0.5, 1) == 0.0  # nothing within two cells of the point


def test_high_cells_are_the_centres_of_runs_long_enough_to_be_walls() -> None:
    high = np.zeros(20, dtype=bool)
    high[[1, 2, 4, 5]] = True  # one run (a gap of one cell bridged), 4 high cells
    high[[10, 11]] = True  # too short for a wall of 3 cells
    along_x = _occupied_line(high, axis=0, offset=2.0)
    centres = along_x.high_cells(min_cells=3)
    assert centres[:, 0] == pytest.approx([0.15, 0.25, 0.45, 0.55])
    assert np.all(centres[:, 1] == 2.0)
    along_y = _occupied_line(high, axis=1, offset=-1.0)
    assert along_y.high_cells(min_cells=3)[:, ::-1] == pytest.approx(
        np.column_stack([[0.15, 0.25, 0.45, 0.55], np.full(4, -1.0)])
    )
    assert len(along_x.high_cells(min_cells=2)) == 6
    deduced = dataclasses.replace(along_x, virtual=True)
    assert deduced.high_cells(min_cells=3).shape == (0, 2)


def _level_kinect_at_origin() -> CameraView:
    """A level Kinect-like camera at the origin of the aligned frame, looking along +y."""
    return CameraView.from_intrinsics(KINECT, OPTICAL_TO_LEVEL, np.zeros(3))


def _seen_over_a_cabinet(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """What a level camera at the origin (1.2 m over the floor, looking along +y) sees of a
    2.8 m tall wall at y = 4 with a 2 m tall cabinet at y = 3 in front of its middle: the
    cabinet's front, and of the wall behind it only the strip over the cabinet's top
    (z > 1.07, 0.5 m)."""
    parts, normals = [], []

    def add(points: np.ndarray, normal: tuple[float, float, float]) -> None:
        parts.append(points)
        normals.append(np.tile(normal, (len(points), 1)))

    x, z = rng.uniform(-1.5, 1.5, 8000), rng.uniform(-1.2, 1.6, 8000)
    over = (np.abs(x) > 0.6) | (z > 0.8 * 4.0 / 3.0)
    add(np.column_stack([x[over], np.full(over.sum(), 4.0), z[over]]), (0.0, -1.0, 0.0))
    x, z = rng.uniform(-0.6, 0.6, 2000), rng.uniform(-1.2, 0.8, 2000)
    add(np.column_stack([x, np.full_like(x, 3.0), z]), (0.0, -1.0, 0.0))
    x, y = rng.uniform(-1.5, 1.5, 6000), rng.uniform(1.5, 4.0, 6000)
    floor = ~((np.abs(x) < 0.6) & (y > 3.0))
    add(np.column_stack([x[floor], y[floor], np.full(floor.sum(), -1.2)]), (0.0, 0.0, 1.0))
    return np.vstack(parts), np.vstack(normals)


def test_a_wall_seen_only_over_a_cabinet_in_front_of_it_is_still_a_wall() -> None:
    points, normals = _seen_over_a_cabinet(np.random.default_rng(5))
    view = _level_kinect_at_origin()
    lines = find_wall_lines(points, normals, -1.2, None, LayoutParams(), [view])
    back = [ln for ln in lines if ln.axis == 0 and abs(ln.offset - 4.0) < 0.05 and not ln.virtual]
    assert back, "the wall behind the cabinet is found"
    spans = back[0].segments
    # One wall across the cabinet, not two pieces either side of it.
    assert len(spans) == 1
    assert spans[0, 0] < -1.3 and spans[0, 1] > 1.3


def test_the_horizon_is_where_the_camera_sees_over_nearer_things() -> None:
    cabinet = np.column_stack([np.zeros(5), np.full(5, 3.0), np.linspace(-1.2, 0.8, 5)])
    horizon = _Horizon.of(np.zeros(3), cabinet)
    seen = horizon.lowest_seen(np.array([[0.0, 4.0], [2.0, 4.0], [0.0, 3.2]]))
    assert seen[0] == pytest.approx(0.8 * 4.0 / 3.0)  # over the cabinet's top
    assert seen[1] == -np.inf  # nothing stands on that bearing
    assert seen[2] == -np.inf  # the cabinet stands against that column: it is no occluder


def _seen_line(
    axis: int, offset: float, travel: int, spans: list[list[float]], origin: float = 0.0
) -> WallLine:
    """A wall line seen high all along, its candidate segments over the run spans ``spans``."""
    return WallLine(
        axis=axis,
        offset=offset,
        travel=travel,
        origin=origin,
        cell_size=0.08,
        high=np.ones(100, dtype=bool),
        segments=np.array(spans, dtype=np.float64),
    )


def _side(offset: float, spans: list[list[float]]) -> WallLine:
    """A seen wall along y (axis 1) at x = ``offset`` over the run spans ``spans``."""
    return _seen_line(1, offset, -1, spans)


def test_a_long_bridge_closes_an_arm_only_behind_the_walls_end_and_beside_its_other_side():
    # The camera at (1.58, 5.68) sees a pier's end at x = 1.34 on y = 4.38 and the arm's far
    # wall y = 0 from x = 0.39 (where the end's shadow falls, 0.53) to x = 0, where the
    # arm's other side x = 0 meets it and is seen back up most of the way.
    camera = np.array([1.58, 5.68])
    near, far, far_seen = (1.34, 4.38), (0.39, 0.0), np.array([0.0, 0.39])
    side = _side(0.0, [[0.0, 1.92], [2.56, 3.12], [4.08, 4.48]])
    assert _closes_an_arm(near, far, far_seen, 0, camera, [side])
    # The far wall seen again well away from the shadow: not what the end hid.
    assert not _closes_an_arm(near, (1.0, 0.0), np.array([0.0, 1.0]), 0, camera, [side])
    # No seen side back up the arm (under half its depth, or off the far wall's end).
    assert not _closes_an_arm(near, far, far_seen, 0, camera, [_side(0.0, [[0.0, 1.5]])])
    assert not _closes_an_arm(near, far, far_seen, 0, camera, [_side(-0.5, [[0.0, 4.4]])])
    # The "far" wall in front of the near one, seen from the camera (the ray past its end
    # lands on the pier's top, and a wall runs up from the top's other end).
    upright = _side(2.0, [[0.0, 4.4]])
    assert not _closes_an_arm(far, near, np.array([1.34, 2.0]), 0, camera, [side, upright])


def test_a_bridge_deeper_than_an_occlusion_is_only_made_across_an_arm():
    # As above, through _occluded_links: the arm's floor seen, nothing behind the pier.
    rng = np.random.default_rng(5)
    floor = np.column_stack([rng.uniform(0.0, 1.3, 4000), rng.uniform(0.0, 7.4, 4000)])
    room = np.column_stack([rng.uniform(0.0, 4.7, 4000), rng.uniform(4.5, 7.4, 4000)])
    xy = np.vstack([floor, room])
    grid = _make_grid(xy, 0.08, np.ones(len(xy), dtype=bool))

    walls = [
        _seen_line(0, 0.0, 1, [[0.0, 0.39]], -1.0),
        _seen_line(0, 4.38, 1, [[1.34, 1.82]], -1.0),
    ]
    camera = np.array([1.58, 5.68])

    def hidden_sides(lines: list[WallLine]) -> list[float]:
        return [ln.offset for ln in _occluded_links(lines, grid, camera) if ln.axis == 1]

    side = _side(0.0, [[0.0, 1.92], [2.56, 3.12], [4.08, 4.48]])
    assert hidden_sides([*walls, side]) == pytest.approx([1.34])
    assert hidden_sides(walls) == []


def test_a_frames_wall_with_its_floor_hidden_is_scanned_where_its_own_points_stand() -> None:
    # A level camera at the origin looks along +y at a wall at y = 4 (floor at z = -1.2).
    # In front of its middle (|x| < 0.6) something hides the floor, and of the wall there
    # only a sill under a window shows (z < -0.5): not a standing wall, but scanned.
    rng = np.random.default_rng(3)
    x, z = rng.uniform(-1.5, 1.5, 8000), rng.uniform(-1.2, 1.6, 8000)
    keep = (np.abs(x) > 0.6) | (z < -0.5)
    wall = np.column_stack([x[keep], np.full(keep.sum(), 4.0), z[keep]])
    fx, fy = rng.uniform(-1.5, 1.5, 6000), rng.uniform(1.5, 4.0, 6000)
    seen = (np.abs(fx) > 0.6) | (fy < 2.5)
    floor = np.column_stack([fx[seen], fy[seen], np.full(seen.sum(), -1.2)])
    points = np.vstack([wall, floor])
    normals = np.vstack(
        [np.tile([0.0, -1.0, 0.0], (len(wall), 1)), np.tile([0.0, 0.0, 1.0], (len(floor), 1))]
    )
    view = _level_kinect_at_origin()

    def open_gap(views: list[CameraView]) -> float:
        lines = find_wall_lines(points, normals, -1.2, None, LayoutParams(), views)
        (line,) = [ln for ln in lines if ln.axis == 0 and abs(ln.offset - 4.0) < 0.05]
        return line.open_gap(-1.0, 1.0)

    assert open_gap([view]) == 0.0  # the frame's wall may run on across the window
    assert open_gap([]) > 1.0  # a cloud's rule is unchanged: nothing scanned before it


def _surface(
    rng: np.random.Generator, lo: list[float], hi: list[float], normal: list[float], n: int
) -> tuple[np.ndarray, np.ndarray]:
    """Points (n) uniform in the box [lo, hi], one side of zero extent (a surface), and
    their normal."""
    points = rng.uniform(lo, hi, (n, 3))
    return points, np.tile(np.asarray(normal, dtype=np.float64), (n, 1))


def _scene(parts: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    return np.vstack([p for p, _ in parts]), np.vstack([n for _, n in parts])


def _wall_with_window(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A corner: a wall along y at x = 0 (interior +x) and a wall along x at y = 0 (interior
    +y) from x = 0 to 5, with a window from x = 3.8 to the scan's end at 5 (sill at 0.8 m,
    head at 2.0 m, their reveals 0.25 m deep behind the wall), and the floor in front."""
    parts = [
        _surface(rng, [0, 0, 0], [0, 3, 2.6], [1, 0, 0], 4000),
        _surface(rng, [0, 0, 0], [3.8, 0, 2.6], [0, 1, 0], 5000),
        _surface(rng, [3.8, 0, 0], [5, 0, 0.8], [0, 1, 0], 500),
        _surface(rng, [3.8, 0, 2.0], [5, 0, 2.6], [0, 1, 0], 400),
        _surface(rng, [3.8, -0.25, 0.8], [5, 0, 0.8], [0, 0, 1], 1500),
        _surface(rng, [3.8, -0.25, 2.0], [5, 0, 2.0], [0, 0, -1], 1500),
        _surface(rng, [0, 0, 0], [5, 3, 0], [0, 0, 1], 12000),
    ]
    return _scene(parts)


def test_the_wall_under_and_over_a_window_stands_and_a_chain_runs_across_it() -> None:
    points, normals = _wall_with_window(np.random.default_rng(3))
    lines = find_wall_lines(points, normals, 0.0, 2.6, LayoutParams())
    (line,) = [ln for ln in lines if ln.axis == 0 and not ln.virtual]
    assert float(line.segments[-1, 1]) == pytest.approx(3.8, abs=0.1)  # whole wall ends
    run = line.origin + (np.arange(len(line.high)) + 0.5) * line.cell_size
    assert line.lintel is not None
    assert line.lintel[(run > 3.9) & (run < 4.9)].all(), "wall stands under and over it"
    assert not line.lintel[(run > 0.2) & (run < 3.7)].any()
    chain = find_wall_chain(lines, LayoutParams())
    assert chain is not None
    np.testing.assert_allclose(chain.keypoints[0], [0.0, 3.0], atol=0.1)
    np.testing.assert_allclose(chain.keypoints[1], [0.0, 0.0], atol=0.05)
    np.testing.assert_allclose(chain.keypoints[-1], [5.0, 0.0], atol=0.1)


def _door_with_the_next_room_behind(rng: np.random.Generator, lintel: bool):
    """A corner: walls at x = 0 (interior +x) and y = 0 (interior +y, x from 0 to 3) with a
    door from x = 1.5 to 2.4 (the wall over it from 2.0 m when ``lintel``; without, an opening
    up to the ceiling); through it the floor, wider farther away, and 2.2 m behind a wall
    2.7 m long facing the door."""
    parts = [
        _surface(rng, [0, 0, 0], [0, 3, 2.6], [1, 0, 0], 4000),
        _surface(rng, [0, 0, 0], [1.5, 0, 2.6], [0, 1, 0], 2000),
        _surface(rng, [2.4, 0, 0], [3, 0, 2.6], [0, 1, 0], 800),
        _surface(rng, [1.5, -1.2, 0], [2.4, 0, 0], [0, 0, 1], 800),
        _surface(rng, [0.6, -2.2, 0], [3.3, -1.2, 0], [0, 0, 1], 2000),  # the view widens
        _surface(rng, [0.6, -2.2, 0], [3.3, -2.2, 2.6], [0, 1, 0], 4000),
        _surface(rng, [0, 0, 0], [3, 3, 0], [0, 0, 1], 8000),
    ]
    if lintel:
        parts.append(_surface(rng, [1.5, 0, 2.0], [2.4, 0, 2.6], [0, 1, 0], 400))
    return _scene(parts)


@pytest.mark.parametrize("lintel", [True, False])
def test_a_wall_seen_through_a_door_is_the_next_rooms(lintel: bool) -> None:
    # Under a lintel the far wall is the next room's, seen through the door: no wall of
    # this scan. Without one the opening may be the room stepping back: its wall is kept.
    points, normals = _door_with_the_next_room_behind(np.random.default_rng(5), lintel)
    lines = find_wall_lines(points, normals, 0.0, 2.6, LayoutParams())
    along_x = {round(ln.offset, 1) for ln in lines if ln.axis == 0 and not ln.virtual}
    assert along_x == ({0.0} if lintel else {0.0, -2.2})
    chain = find_wall_chain(lines, LayoutParams())
    assert chain is not None
    if lintel:
        np.testing.assert_allclose(chain.keypoints, [[0.0, 3.0], [0.0, 0.0], [3.0, 0.0]], atol=0.1)


def test_a_wall_with_space_seen_only_behind_it_faces_that_space() -> None:
    # A 1.4 m wall at y = 0 (interior +y) that is mostly a door (x from 0.3 to 1.3, wall over
    # it from 2 m); through it the next room's floor, widening, up to its wall 2.5 m behind,
    # which is 3.2 m long: beside the view through the door nothing shows on either side of
    # that wall. Taken with its interior away from the door it passed for a wall of a room
    # behind it, and was the longest wall the scan had.
    rng = np.random.default_rng(6)
    fan = rng.uniform([-0.9, -2.5, 0], [2.5, -0.15, 0], (5000, 3))
    depth = -fan[:, 1]
    fan = fan[(fan[:, 0] > 0.3 - 0.4 * depth) & (fan[:, 0] < 1.3 + 0.4 * depth)]
    points, normals = _scene(
        [
            _surface(rng, [0, 0, 0], [0.3, 0, 2.6], [0, 1, 0], 500),
            _surface(rng, [1.3, 0, 0], [1.4, 0, 2.6], [0, 1, 0], 200),
            _surface(rng, [0.3, 0, 2.0], [1.3, 0, 2.6], [0, 1, 0], 500),
            _surface(rng, [-0.9, -2.5, 0], [2.3, -2.5, 2.6], [0, 1, 0], 6000),
            _surface(rng, [-0.2, 0, 0], [1.6, 2.0, 0], [0, 0, 1], 4000),
            (fan, np.tile([0.0, 0.0, 1.0], (len(fan), 1))),
        ]
    )
    lines = find_wall_lines(points, normals, 0.0, 2.6, LayoutParams())
    far = [ln for ln in lines if ln.axis == 0 and not ln.virtual and abs(ln.offset + 2.5) < 0.05]
    assert all(ln.travel == 1 for ln in far), [ln.travel for ln in far]
    # The wall with the door is the scan's own, its jambs wall though the floor seen through
    # the door lies behind them: the far wall is then no wall (seen through the door).
    near = [ln for ln in lines if ln.axis == 0 and not ln.virtual and abs(ln.offset) < 0.05]
    assert [ln.travel for ln in near] == [1]
    assert not far


def test_a_wall_facing_away_is_told_by_space_only_behind_it() -> None:
    spans = [(2, 8)]
    occupied = np.zeros(10, dtype=bool)
    occupied[2:8] = True
    nothing, some = np.zeros(10), np.zeros(10)
    some[4:6] = 5.0
    assert _faces_away(spans, nothing, some, occupied)  # space behind only
    assert not _faces_away(spans, some, some, occupied)  # space in front too
    assert not _faces_away(spans, nothing, nothing, occupied)  # walls alone: kept


def _notch_beside_a_door(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A wall along x at y = 0 (interior +y, x from 0 to 6) with a notch out of the room
    (x from 1.9 to 2.5, 0.8 m deep) and a door from x = 3.0 to 3.9 (wall over it from 2 m);
    through the door the floor of the next room, wider the farther from the door, reaching
    behind the notch's side at x = 2.5."""
    parts = [
        _surface(rng, [0, 0, 0], [1.9, 0, 2.6], [0, 1, 0], 2500),
        _surface(rng, [2.5, 0, 0], [3.0, 0, 2.6], [0, 1, 0], 700),
        _surface(rng, [3.9, 0, 0], [6, 0, 2.6], [0, 1, 0], 2800),
        _surface(rng, [3.0, 0, 2.0], [3.9, 0, 2.6], [0, 1, 0], 300),
        _surface(rng, [1.9, -0.8, 0], [1.9, 0, 2.6], [1, 0, 0], 1100),
        _surface(rng, [2.5, -0.8, 0], [2.5, 0, 2.6], [-1, 0, 0], 1100),
        _surface(rng, [1.9, -0.8, 0], [2.5, -0.8, 2.6], [0, 1, 0], 800),
        _surface(rng, [0, 0, 0], [6, 3, 0], [0, 0, 1], 14000),
        _surface(rng, [1.9, -0.8, 0], [2.5, 0, 0], [0, 0, 1], 400),
    ]
    fan = rng.uniform([1.5, -2.5, 0], [5.4, -0.15, 0], (6000, 3))
    depth = -fan[:, 1]
    fan = fan[(fan[:, 0] > 3.0 - depth) & (fan[:, 0] < 3.9 + depth) & (fan[:, 0] > 2.55)]
    parts.append((fan, np.tile([0.0, 0.0, 1.0], (len(fan), 1))))
    return _scene(parts)


def test_the_floor_seen_through_a_door_is_no_space_past_the_wall_beside_it() -> None:
    # The notch's side at x = 2.5 has the next room's floor behind it, seen through the door
    # beside it, not through the side: it is still a wall, and the chain goes round the notch.
    points, normals = _notch_beside_a_door(np.random.default_rng(2))
    lines = find_wall_lines(points, normals, 0.0, 2.6, LayoutParams())
    sides = [ln for ln in lines if ln.axis == 1 and not ln.virtual and abs(ln.offset - 2.5) < 0.05]
    assert [ln.travel for ln in sides] == [1]
    chain = find_wall_chain(lines, LayoutParams())
    assert chain is not None
    notch = [[1.9, 0.0], [1.9, -0.8], [2.5, -0.8], [2.5, 0.0]]
    assert any(
        np.allclose(chain.keypoints[i : i + 4], notch, atol=0.1)
        for i in range(len(chain.keypoints) - 3)
    )


def test_a_wall_behind_a_soffit_is_kept() -> None:
    # A soffit 0.5 m before the wall (its face from 2.1 m to the ceiling, the floor seen
    # under it) shows only wall over an opening, none beside it: no door, so the wall
    # behind it is the room's.
    rng = np.random.default_rng(4)
    points, normals = _scene(
        [
            _surface(rng, [0, 0, 0], [4, 0, 2.6], [0, 1, 0], 5000),
            _surface(rng, [1, 0.5, 2.1], [3, 0.5, 2.6], [0, 1, 0], 800),
            _surface(rng, [1, 0, 2.1], [3, 0.5, 2.1], [0, 0, -1], 500),
            _surface(rng, [0, 0, 0], [4, 3, 0], [0, 0, 1], 9000),
        ]
    )
    lines = find_wall_lines(points, normals, 0.0, 2.6, LayoutParams())
    walls = [ln for ln in lines if ln.axis == 0 and not ln.virtual and abs(ln.offset) < 0.05]
    assert [ln.travel for ln in walls] == [1]
    assert np.count_nonzero(walls[0].high) * walls[0].cell_size > 3.5


def _u_seen_from_its_base(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A U room seen from its base (x from 0 to 2, y from -3 to 3; the scan ends at x = 1
    where y > 0): its arms (x from 2 to 4) at y < -1.2 and y > 0, the gap between them
    outside. Both walls facing the gap have a window from x = 2.2 to 3.8 (sill 0.9 m, head
    2.1 m), the ground in the gap seen through them; the upper arm's end wall one from
    y = 0.5 to 2.5, the ground behind it seen too."""
    parts = [
        _surface(rng, [0, -3, 0], [0, 0, 2.6], [1, 0, 0], 3000),
        _surface(rng, [1, 3, 0], [4, 3, 2.6], [0, -1, 0], 3000),
        _surface(rng, [0, -3, 0], [4, -3, 2.6], [0, 1, 0], 4000),
        _surface(rng, [4, 0, 0], [4, 0.5, 2.6], [-1, 0, 0], 500),
        _surface(rng, [4, 2.5, 0], [4, 3, 2.6], [-1, 0, 0], 500),
        _surface(rng, [4, 0.5, 0], [4, 2.5, 0.9], [-1, 0, 0], 700),
        _surface(rng, [4, 0.5, 2.1], [4, 2.5, 2.6], [-1, 0, 0], 400),
        _surface(rng, [4.1, 0.4, 0], [6, 2.6, 0], [0, 0, 1], 1500),  # seen through it
        _surface(rng, [4, -3, 0], [4, -1.2, 2.6], [-1, 0, 0], 2000),
        _surface(rng, [2, -1.2, 0], [2, 0, 2.6], [-1, 0, 0], 1300),
        _surface(rng, [0, -3, 0], [2, 0, 0], [0, 0, 1], 6000),
        _surface(rng, [1, 0, 0], [2, 3, 0], [0, 0, 1], 3000),
        _surface(rng, [2, 0, 0], [4, 3, 0], [0, 0, 1], 6000),
        _surface(rng, [2, -3, 0], [4, -1.2, 0], [0, 0, 1], 3600),
        _surface(rng, [2.4, -1.1, 0], [3.8, -0.1, 0], [0, 0, 1], 600),  # the gap's ground
    ]
    for y, facing in ((-1.2, -1.0), (0.0, 1.0)):
        for lo, hi in ((2.0, 2.2), (3.8, 4.0)):
            parts.append(_surface(rng, [lo, y, 0], [hi, y, 2.6], [0, facing, 0], 400))
        parts.append(_surface(rng, [2.2, y, 0], [3.8, y, 0.9], [0, facing, 0], 500))
        parts.append(_surface(rng, [2.2, y, 2.1], [3.8, y, 2.6], [0, facing, 0], 300))
    return _scene(parts)


def test_the_view_through_a_window_stops_at_a_wall_facing_away() -> None:
    # The upper arm's floor lies behind the lower arm's window, but past the upper arm's own
    # wall facing away from it: scanned from inside the room, not through the window. It is
    # space on both sides of the gap's side at x = 2, so the chain does not cut the arm off.
    points, normals = _u_seen_from_its_base(np.random.default_rng(6))
    lines = find_wall_lines(points, normals, 0.0, 2.6, LayoutParams())
    (side,) = [ln for ln in lines if ln.axis == 1 and not ln.virtual and abs(ln.offset - 2) < 0.05]
    assert side.crossing_gap(0.2, 2.8) > 2.0
    chain = find_wall_chain(lines, LayoutParams())
    assert chain is not None
    arm = [[2.0, -1.2], [2.0, 0.0], [4.0, 0.0], [4.0, 3.0], [1.0, 3.0]]
    np.testing.assert_allclose(chain.keypoints[-5:], arm, atol=0.1)


def test_a_wall_beside_a_door_is_wall_though_the_floor_seen_through_it_lies_behind():
    # A wall along x at y = 0 (interior +y): piers 0-0.7 m and 1.6-2.3 m floor to ceiling,
    # a door between them under its lintel (z 2.05 to 2.6). Through the door the scan saw
    # the next room's floor in a view that widens past the jambs, behind the piers too.
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.uniform(0, 0.7, 3000), rng.uniform(1.6, 2.3, 3000)])
    piers = np.column_stack([x, np.zeros_like(x), rng.uniform(0, 2.6, len(x))])
    x = rng.uniform(0.7, 1.6, 800)
    lintel = np.column_stack([x, np.zeros_like(x), rng.uniform(2.05, 2.6, len(x))])
    room = np.column_stack(
        [rng.uniform(-0.5, 2.8, 20000), rng.uniform(0.05, 3.0, 20000), np.zeros(20000)]
    )
    depth = rng.uniform(0.05, 1.5, 5000)
    across = rng.uniform(0.0, 1.0, 5000)
    fan = np.column_stack(
        [0.7 - depth + across * (0.9 + 2 * depth), -depth, np.zeros(5000)]
    )  # the next room's floor, as seen through the door
    wall = np.vstack([piers, lintel])
    floor = np.vstack([room, fan])
    points = np.vstack([wall, floor])
    normals = np.vstack(
        [np.tile([0.0, 1.0, 0.0], (len(wall), 1)), np.tile([0.0, 0.0, 1.0], (len(floor), 1))]
    )
    lines = [
        ln
        for ln in find_wall_lines(points, normals, 0.0, 2.6, LayoutParams())
        if ln.axis == 0 and abs(ln.offset) < 0.05
    ]
    assert [ln.travel for ln in lines] == [1]  # one wall, the room's side its interior
    (line,) = lines
    cells = line.origin + (np.flatnonzero(line.high) + 0.5) * line.cell_size
    assert cells.min() < 0.2 and cells.max() > 2.1  # both piers are wall
    assert not np.any((cells > 0.8) & (cells < 1.5))  # the door is not


def _line_with_opening(
    offset: float, wall: np.ndarray, opening: np.ndarray, segments: list[list[float]]
) -> WallLine:
    """A wall line along x (interior y > ``offset``) on 0.1 m cells from run 0: whole wall
    where ``wall``; where ``opening``, wall points only high up and space seen behind."""
    return WallLine(
        axis=0,
        offset=offset,
        travel=1,
        origin=0.0,
        cell_size=0.1,
        high=wall.copy(),
        segments=np.array(segments, dtype=np.float64),
        virtual=False,
        unsupported=np.zeros(len(wall), dtype=bool),
        seen_through=opening.copy(),
        occupied=wall | opening,
        lintel=opening.copy(),
    )


def test_no_hidden_wall_is_deduced_from_a_doorway_to_a_wall_seen_through_it() -> None:
    # The scan's wall y = 0 starts at x = 1.0, after a doorway (x 0.7-1.0) it was cut in;
    # through the door it sees 0.3 m of the next room's wall at y = -2.0. Bridging the two
    # would put a 2 m wall across the next room, and the chain out of the room along it.
    rng = np.random.default_rng(7)
    floor = np.column_stack([rng.uniform(0.0, 5.0, 6000), rng.uniform(0.1, 4.0, 6000)])
    grid = _make_grid(floor, 0.1, np.ones(len(floor), dtype=bool))
    cells = np.arange(50)
    wall, doorway = cells >= 10, (cells >= 7) & (cells < 10)
    # The next room's wall, seen over the doorway's width.
    through = _line_with_opening(-2.0, doorway, np.zeros(50, bool), [[0.7, 1.0]])

    def bridges(near_end: np.ndarray) -> list[float]:
        own = _line_with_opening(0.0, wall, near_end, [[1.0, 5.0]])
        bridged = _occluded_links([through, own], grid, jambs=True)
        return [ln.offset for ln in bridged if ln.virtual]

    # The same lines with nothing seen past the wall's start: a step of the room whose side
    # the scan did not see, bridged where the two walls meet.
    assert set(bridges(np.zeros(50, dtype=bool))) == {1.0}
    assert bridges(doorway) == []


def test_stray_points_high_over_a_walls_line_are_no_doorway_to_see_a_wall_through() -> None:
    # A nearer wall's line (y = 1) with whole wall on x 0-2 and 4-6; a wall 0.5 m behind it
    # (y = 0.5) is seen over x 1.5-4.5.
    cells = np.arange(60)
    wall = (cells < 20) | (cells >= 40)
    behind = _line_with_opening(0.5, (cells >= 15) & (cells < 45), np.zeros(60, bool), [[1.5, 4.5]])
    # Between, a doorway (wall only over it, space seen behind): the far wall is the next
    # room's, seen through it.
    doorway = (cells >= 20) & (cells < 40)
    near = _line_with_opening(1.0, wall, doorway, [[0.0, 2.0], [4.0, 6.0]])
    assert _seen_through_opening(behind, [near, behind])
    # Between, nothing but a few stray points high up, a column each: the room steps back
    # there, and the far wall is its own.
    strays = np.isin(cells, [22, 25, 28, 31, 34])
    near = _line_with_opening(1.0, wall, strays, [[0.0, 2.0], [4.0, 6.0]])
    near = dataclasses.replace(near, seen_through=doorway.copy())
    assert not _seen_through_opening(behind, [near, behind])


def _wall_ending_where_the_room_goes_on(
    rng: np.random.Generator, doorway: bool
) -> tuple[np.ndarray, np.ndarray]:
    """What a level camera at the origin (1.4 m over the floor, ceiling 1.3 m over it,
    looking along +y) sees of a wall at y = 3 from x = -1.5 to 0.2, past which the room goes
    on (floor beyond, and the ceiling 0.8-1.6 m beyond: rays to it cross y = 3 at 2.4-2.6 m
    over the floor); with ``doorway`` the wall goes on to x = 1.5 instead, with a door at
    x = 0.3-1.2 whose lintel (2.1 m) lets through only rays to the floor or to the
    ceiling 2.6 m beyond and more."""
    parts, normals = [], []

    def add(points: np.ndarray, normal: tuple[float, float, float]) -> None:
        parts.append(points)
        normals.append(np.tile(normal, (len(points), 1)))

    x, z = rng.uniform(-1.5, 1.5 if doorway else 0.2, 8000), rng.uniform(-1.4, 1.3, 8000)
    wall = ~((x > 0.3) & (x < 1.2) & (z < 0.7)) if doorway else np.ones(len(x), bool)
    add(np.column_stack([x[wall], np.full(wall.sum(), 3.0), z[wall]]), (0.0, -1.0, 0.0))
    x, y = rng.uniform(-1.5, 1.5, 6000), rng.uniform(1.5, 3.0, 6000)
    add(np.column_stack([x, y, np.full_like(x, -1.4)]), (0.0, 0.0, 1.0))
    x, y = rng.uniform(0.35, 1.15, 3000), rng.uniform(3.2, 6.0, 3000)
    add(np.column_stack([x, y, np.full_like(x, -1.4)]), (0.0, 0.0, 1.0))
    x = rng.uniform(0.35, 1.15, 3000)
    y = rng.uniform(5.6, 6.0, 3000) if doorway else rng.uniform(3.8, 4.6, 3000)
    add(np.column_stack([x, y, np.full_like(x, 1.3)]), (0.0, 0.0, -1.0))
    return np.vstack(parts), np.vstack(normals)


@pytest.mark.parametrize("doorway", [False, True])
def test_a_line_seen_through_over_a_doors_top_is_where_the_room_goes_on(doorway: bool) -> None:
    points, normals = _wall_ending_where_the_room_goes_on(np.random.default_rng(8), doorway)
    lines = find_wall_lines(points, normals, -1.4, 1.3, LayoutParams(), [_level_kinect_at_origin()])
    (wall,) = [
        ln for ln in lines if ln.axis == 0 and abs(ln.offset - 3.0) < 0.05 and not ln.virtual
    ]
    assert wall.crossing_gap(0.3, 1.2) > 0.5  # the floor beyond is seen either way
    if doorway:  # the lintel stops every ray over 2.1 m: it may be a door
        assert wall.open_above_gap(0.3, 1.2) == 0.0
    else:  # rays crossed it at 2.4 m and up: no door is that tall, no wall stands there
        assert wall.open_above_gap(0.3, 1.2) > MAX_OPEN_ABOVE
    assert wall.open_above_gap(-1.5, 0.1) == 0.0  # nor where the wall stands


def test_a_frames_chain_does_not_bridge_where_its_camera_saw_the_room_go_on_over_doors(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The room of the test above goes on past the wall's end into an arm whose far side,
    # x = 1.2, faces the camera: its line meets the wall's at (1.2, 3), 1 m on, across the
    # arm's mouth, which rays crossed 2.4 m and more over the floor.
    rng = np.random.default_rng(9)
    points, normals = _wall_ending_where_the_room_goes_on(rng, doorway=False)
    y, z = rng.uniform(1.5, 5.0, 6000), rng.uniform(-1.4, 1.3, 6000)
    side = np.column_stack([np.full_like(y, 1.2), y, z])
    points = np.vstack([points, side])
    normals = np.vstack([normals, np.tile([-1.0, 0.0, 0.0], (len(side), 1))])
    views = [_level_kinect_at_origin()]
    lines = find_wall_lines(points, normals, -1.4, 1.3, LayoutParams(), views)

    def corners(limit: float) -> np.ndarray:
        monkeypatch.setattr("services.wall_graph.MAX_OPEN_ABOVE", limit)
        chain = find_wall_chain(lines, LayoutParams(), views)
        assert chain is not None
        return chain.keypoints

    across = np.array([1.2, 3.0])
    assert np.min(np.linalg.norm(corners(np.inf) - across, axis=1)) < 0.1  # as it did
    assert np.min(np.linalg.norm(corners(MAX_OPEN_ABOVE) - across, axis=1)) > 0.5
