"""Pieces: quarter turns, wall rows and samples, make_piece on a hand-made layout, free space."""

from __future__ import annotations

import numpy as np
import pytest

from services.placement.pieces import (
    FreeSpace,
    box_of,
    direction_index,
    make_piece,
    rot90,
    shift_walls,
    wall_samples,
    walls_of,
)
from services.types import LocalLayout, ManhattanFrame

pytestmark = pytest.mark.timeout(120)

# An aligned-frame chain: along +x from (2, 1) to (6, 1), then along +y to (6, 5). The
# interior is on the left of both walls: x < 6, y > 1.
CHAIN = np.array([[2.0, 1.0], [6.0, 1.0], [6.0, 5.0]])
FLOOR, CEILING = 0.4, 2.9


def _grid(x0: float, x1: float, y0: float, y1: float, step: float = 0.1) -> np.ndarray:
    xs, ys = np.meshgrid(np.arange(x0, x1, step), np.arange(y0, y1, step))
    return np.column_stack([xs.ravel(), ys.ravel()])


def _layout(footprint=None, source=None, target=None) -> LocalLayout:
    frame = ManhattanFrame(rotation=np.eye(3), floor_z=FLOOR, ceiling_z=CEILING)
    empty3 = np.zeros((0, 3))
    return LocalLayout(
        keypoints=CHAIN,
        frame=frame,
        source_boundary=empty3 if source is None else np.asarray(source, dtype=np.float64),
        target_boundary=empty3 if target is None else np.asarray(target, dtype=np.float64),
        footprint=np.zeros((0, 2)) if footprint is None else footprint,
    )


# ---------------------------------------------------------------------------------------------
# Plane geometry helpers
# ---------------------------------------------------------------------------------------------


def test_rot90_turns_counter_clockwise_and_composes():
    assert rot90(1) @ np.array([1.0, 0.0]) == pytest.approx([0.0, 1.0])
    assert rot90(2) @ np.array([1.0, 2.0]) == pytest.approx([-1.0, -2.0])
    assert rot90(3) @ np.array([0.0, 1.0]) == pytest.approx([1.0, 0.0])
    assert np.array_equal(rot90(4), np.eye(2))
    assert np.array_equal(rot90(-1), rot90(3))
    for a in range(4):
        assert np.linalg.det(rot90(a)) == pytest.approx(1.0)
        for b in range(4):
            assert np.allclose(rot90(a) @ rot90(b), rot90(a + b))


@pytest.mark.parametrize(
    ("vector", "index"),
    [
        ((1.0, 0.0), 0),
        ((0.0, 2.5), 1),
        ((-3.0, 0.0), 2),
        ((0.0, -0.1), 3),
        ((4.0, 0.2), 0),  # nearly axis-parallel: the larger component decides
        ((-0.05, -2.0), 3),
        ((0.3, -0.01), 0),
        ((-0.3, 0.1), 2),
    ],
)
def test_direction_index(vector, index):
    assert direction_index(np.array(vector)) == index


def test_direction_index_agrees_with_rot90():
    for r in range(4):
        assert direction_index(rot90(r) @ np.array([2.0, 0.0])) == r


def test_walls_of_an_axis_parallel_chain():
    chain = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [1.0, 3.0]])
    expected = [[0, 0.0, 0.0, 4.0], [1, 4.0, 0.0, 3.0], [0, 3.0, 1.0, 4.0]]
    assert walls_of(chain).tolist() == expected


def test_shift_walls_matches_walls_of_the_shifted_chain():
    chain = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [1.0, 3.0], [1.0, 5.0]])
    shift = np.array([1.5, -2.0])
    moved = shift_walls(walls_of(chain), shift)
    assert np.allclose(moved, walls_of(chain + shift))
    assert moved[0].tolist() == [0, -2.0, 1.5, 5.5]  # along x: offset moves by y, run by x
    assert moved[1].tolist() == [1, 5.5, -2.0, 1.0]  # along y: offset moves by x, run by y


def test_wall_samples_are_evenly_spaced_and_skip_the_ends():
    chain = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    samples = wall_samples(chain, 0.1)
    assert len(samples) == 18  # 9 inner samples per 1 m wall
    first, second = samples[:9], samples[9:]
    assert np.allclose(first[:, 1], 0.0) and np.allclose(second[:, 0], 1.0)
    assert np.allclose(np.diff(first[:, 0]), 0.1)
    assert np.allclose(np.diff(second[:, 1]), 0.1)
    # Every chain keypoint (the ends and the corner) stays at least a spacing away.
    gaps = np.linalg.norm(samples[:, None, :] - chain[None], axis=2)
    assert gaps.min() == pytest.approx(0.1)


def test_wall_samples_follow_the_direction_of_travel():
    chain = np.array([[0.0, 0.0], [-2.0, 0.0]])
    samples = wall_samples(chain, 0.5)
    assert samples.tolist() == [[-0.5, 0.0], [-1.0, 0.0], [-1.5, 0.0]]


def test_wall_samples_of_a_point_or_a_tiny_wall_are_empty():
    assert wall_samples(np.array([[0.0, 0.0]])).shape == (0, 2)
    assert wall_samples(np.array([[0.0, 0.0], [0.12, 0.0]]), 0.1).shape == (0, 2)


# ---------------------------------------------------------------------------------------------
# make_piece on a hand-made layout
# ---------------------------------------------------------------------------------------------


def test_make_piece_moves_the_source_to_the_origin():
    piece = make_piece("f", _layout())
    assert piece.id == "f"
    assert piece.keypoints.tolist() == [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]]
    assert piece.directions == (0, 1)
    assert piece.turning == 1
    assert piece.corners == 1
    assert piece.length == pytest.approx(8.0)
    assert piece.ceiling == pytest.approx(CEILING - FLOOR)


def test_make_piece_without_ceiling():
    frame = ManhattanFrame(rotation=np.eye(3), floor_z=FLOOR, ceiling_z=None)
    piece = make_piece("f", LocalLayout(keypoints=CHAIN, frame=frame))
    assert piece.ceiling is None


def test_end_regions_are_in_their_travel_frames():
    # Source end (2, 1), travel +x, interior +y: x along x, y = aligned y - 1.
    source = [[2.5, 1.8, 1.4], [1.7, 1.2, FLOOR]]
    # Target end (6, 5), travel +y, interior -x: x = aligned y - 5, y = 6 - aligned x.
    target = [[5.2, 5.3, 0.9], [5.9, 4.6, 2.4]]
    piece = make_piece("f", _layout(source=source, target=target))
    assert piece.source_region == pytest.approx(np.array([[0.5, 0.8, 1.0], [-0.3, 0.2, 0.0]]))
    assert piece.target_region == pytest.approx(np.array([[0.3, 0.8, 0.5], [-0.4, 0.1, 2.0]]))


def test_footprint_behind_the_own_walls_is_dropped_and_shifted():
    front = _grid(2.05, 6.0, 1.05, 5.0)
    near_behind = _grid(3.05, 5.0, 0.75, 0.95)  # less than 0.3 m behind the first wall: kept
    far_behind = _grid(3.05, 5.0, -1.0, 0.6)  # more than 0.3 m behind it (seen through a door)
    side_behind = _grid(6.45, 7.5, 2.05, 4.0)  # more than 0.3 m behind the second wall
    footprint = np.vstack([front, near_behind, far_behind, side_behind])
    piece = make_piece("f", _layout(footprint=footprint))
    kept = np.vstack([front, near_behind]) - CHAIN[0]
    assert len(piece.footprint) == len(kept)
    assert np.allclose(_rows(piece.footprint), _rows(kept))


def _rows(points: np.ndarray) -> np.ndarray:
    return points[np.lexsort(points.T[::-1])]


# ---------------------------------------------------------------------------------------------
# Free space
# ---------------------------------------------------------------------------------------------


def _room_piece():
    return make_piece("f", _layout(footprint=_grid(2.05, 6.0, 1.05, 5.0, 0.05)))


def test_free_space_excludes_a_band_along_the_own_walls():
    free = _room_piece().free
    assert free.grid.any()
    # Piece frame: walls along y = 0 (x in 0..4) and x = 4 (y in 0..4); interior x < 4, y > 0.
    along_first = np.column_stack([np.linspace(0.3, 3.7, 40), np.full(40, 0.2)])
    along_second = np.column_stack([np.full(40, 3.8), np.linspace(0.3, 3.7, 40)])
    assert free.hits(along_first) == 0
    assert free.hits(along_second) == 0
    middle = np.array([[1.5, 2.0], [2.0, 1.5], [2.5, 2.5]])
    assert free.hits(middle) == 3
    assert free.hits(np.zeros((0, 2))) == 0


def test_free_space_stays_inside_what_was_scanned():
    free = _room_piece().free
    outside = np.array([[-1.0, 2.0], [2.0, -1.0], [5.0, 2.0], [2.0, 5.0], [10.0, 10.0]])
    assert free.hits(outside) == 0
    # Within the scanned square (0..4 in the piece frame) and clear of the own walls.
    x_lo, y_lo, x_hi, y_hi = free.box
    assert x_lo >= 0.0 and y_hi <= 4.0
    assert y_lo >= 0.3 and x_hi <= 3.7


def test_a_lone_free_cell_is_eroded_away():
    # One scanned spot far from the walls: not enough seen around it to count.
    piece = make_piece("f", _layout(footprint=np.array([[3.6, 3.1]])))
    free = piece.free
    assert not free.grid.any()
    assert free.hits(np.array([[1.6, 2.1]])) == 0
    x_lo, y_lo, x_hi, y_hi = free.box
    assert x_lo > x_hi and y_lo > y_hi


def test_a_block_of_seen_floor_keeps_its_core():
    # A 1.2 m square of seen floor far from the walls: its core survives the erosion, its rim
    # does not.
    block = _grid(3.0, 4.2, 2.5, 3.7, 0.05)
    free = make_piece("f", _layout(footprint=block)).free
    core = block.mean(axis=0) - CHAIN[0]
    assert free.hits(core[None]) == 1
    rim = np.array([[3.02, 3.1], [4.18, 3.1], [3.6, 2.52], [3.6, 3.68]]) - CHAIN[0]
    assert free.hits(rim) == 0


@pytest.mark.parametrize("turn", range(4))
def test_sample_boxes_bound_the_turned_samples(turn):
    piece = _room_piece()
    samples = piece.rotated[turn][2]
    x_lo, y_lo, x_hi, y_hi = piece.sample_boxes[turn]
    assert (x_lo, y_lo) == tuple(samples.min(axis=0)) and (x_hi, y_hi) == tuple(samples.max(axis=0))
    assert box_of(np.zeros((0, 2))) == (np.inf, np.inf, -np.inf, -np.inf)


def test_free_space_of_no_footprint_hits_nothing():
    free = make_piece("f", _layout(footprint=np.zeros((0, 2)))).free
    assert free.grid.size == 0
    assert free.hits(np.array([[1.0, 1.0], [-3.0, 2.0]])) == 0


@pytest.mark.parametrize("turn", range(4))
def test_rotated_free_space_hits_the_rotated_points(turn):
    free = _room_piece().free
    rng = np.random.default_rng(turn)
    points = rng.uniform(-1.0, 5.0, size=(400, 2))
    turned = free.rotated(turn)
    moved = points @ rot90(turn).T
    per_point = [free.hits(p[None]) for p in points]
    per_turned = [turned.hits(p[None]) for p in moved]
    assert per_point == per_turned
    assert sum(per_point) > 50  # the test sees free cells, not only empty space
    assert turned.hits(moved) == free.hits(points)


@pytest.mark.parametrize("turn", range(4))
def test_free_space_box_contains_every_free_cell(turn):
    free = _room_piece().free.rotated(turn)
    centres = (np.argwhere(free.grid) + 0.5) * free.cell + free.origin
    assert len(centres) > 0
    x_lo, y_lo, x_hi, y_hi = free.box
    assert np.all(centres[:, 0] >= x_lo) and np.all(centres[:, 0] <= x_hi)
    assert np.all(centres[:, 1] >= y_lo) and np.all(centres[:, 1] <= y_hi)


def test_empty_free_space_is_the_same_in_every_frame():
    empty = FreeSpace(
        np.zeros((0, 0), dtype=bool), np.zeros(2), 0.25, np.full(2, np.inf), np.full(2, -np.inf)
    )
    for turn in range(4):
        assert empty.rotated(turn).hits(np.array([[0.0, 0.0], [1.0, 1.0]])) == 0


def test_piece_rotations_are_consistent():
    piece = _room_piece()
    for turn, (points, walls, samples) in enumerate(piece.rotated):
        assert np.allclose(points, piece.keypoints @ rot90(turn).T)
        assert np.allclose(walls, walls_of(points))
        assert len(samples) == len(wall_samples(piece.keypoints))
        assert piece.rotated_free[turn].hits(samples) == 0  # own walls are never in own space


def test_a_margin_counts_only_points_that_deep_inside_the_free_space():
    free = _room_piece().free
    rng = np.random.default_rng(7)
    points = rng.uniform(-1.0, 5.0, size=(400, 2))
    assert free.hits(points, 0.0) == free.hits(points)
    # The core of the seen floor is about a meter from its rim, the rim a cell from it.
    core, rim = np.array([[2.0, 2.0]]), np.array([[0.45, 2.0]])
    assert free.hits(core, 0.6) == 1 and free.hits(rim, 0.0) == 1
    assert free.hits(rim, 0.6) == 0
    assert free.hits(points, 0.6) < free.hits(points)
    # One margin per point: the same as asking for each point alone.
    margins = rng.uniform(0.0, 1.5, size=len(points))
    one_by_one = sum(free.hits(p[None], float(m)) for p, m in zip(points, margins, strict=True))
    assert free.hits(points, margins) == one_by_one
    for turn in range(4):
        assert free.rotated(turn).hits(points @ rot90(turn).T, margins) == one_by_one
