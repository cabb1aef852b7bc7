"""Global placement: the search against brute force, pruning rules, constraints, ablation."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from schemas.params import PlacementParams
from services.placement import (
    _CLOSURE_DIRECTIONS,
    Piece,
    _boundary_mismatch,
    evaluate_placement,
    make_piece,
    place_pieces,
    rot90,
)
from services.types import LocalLayout, ManhattanFrame
from tests.conftest import chains_from_polygon

pytestmark = pytest.mark.timeout(120)


def _brute_force(pieces, params):
    best = None
    rest = [p.id for p in pieces[1:]]
    for perm in itertools.permutations(rest):
        for rots in itertools.product(range(4), repeat=len(rest)):
            cand = evaluate_placement(pieces, (pieces[0].id, *perm), (0, *rots), params)
            if cand is not None and (best is None or cand.energy < best.energy - 1e-9):
                best = cand
    return best


@pytest.mark.parametrize("seed", range(6))
def test_search_finds_the_brute_force_minimum(l_room, seed):
    rng = np.random.default_rng(seed)
    n = 4 if seed % 2 else 3
    cuts = sorted(rng.uniform(0, 28, size=n).tolist())
    pieces = chains_from_polygon(l_room, cuts, rng.integers(0, 4, size=n).tolist())
    params = PlacementParams(use_boundary=False)
    placement = place_pieces(pieces, params)
    brute = _brute_force(pieces, params)
    assert placement is not None and brute is not None
    assert placement.exhaustive
    assert placement.best.energy == pytest.approx(brute.energy, abs=1e-9)


def test_recovers_order_and_rotations_of_a_cut_room(l_room):
    # Cuts in the middle of walls of different lengths: one placement closes the loop.
    cuts = [1.0, 9.5, 12.5, 20.0]
    pieces = chains_from_polygon(l_room, cuts, [0, 1, 2, 3])
    shuffled = [pieces[0], pieces[3], pieces[1], pieces[2]]
    placement = place_pieces(shuffled, PlacementParams(use_boundary=False))
    assert placement is not None and placement.closed
    assert placement.best.order == ("p0", "p1", "p2", "p3")
    assert placement.best.closure == pytest.approx(0.0, abs=1e-9)
    # The placement undoes each piece's turn relative to the first.
    assert list(placement.best.rotations) == [0, 3, 2, 1]


def test_the_true_placement_is_optimal_even_when_tied(l_room):
    cuts = [1.0, 9.5, 14.0, 20.0, 25.5]
    pieces = chains_from_polygon(l_room, cuts, [0, 1, 2, 3, 1])
    params = PlacementParams(use_boundary=False)
    truth = evaluate_placement(pieces, ["p0", "p1", "p2", "p3", "p4"], [0, 3, 2, 1, 3], params)
    placement = place_pieces(pieces, params)
    assert truth is not None and placement is not None
    assert placement.best.energy == pytest.approx(truth.energy)


def test_runner_up_alternatives_are_reported_in_energy_order(l_room):
    pieces = chains_from_polygon(l_room, [1.0, 9.5, 14.0, 20.0], [0, 0, 0, 0])
    placement = place_pieces(pieces, PlacementParams(top_k=3))
    assert placement is not None
    energies = [placement.best.energy] + [a.energy for a in placement.alternatives]
    assert energies == sorted(energies)
    assert len(placement.alternatives) >= 1


def test_known_neighbours_constrain_the_order(l_room):
    # p1 and p2 are interchangeable here (both orders close the loop at equal energy):
    # exactly the ambiguity a known neighbour pair resolves.
    pieces = chains_from_polygon(l_room, [1.0, 9.5, 14.0, 20.0], [0, 0, 0, 0])
    for follower in ("p1", "p2"):
        forced = place_pieces(pieces, neighbours=[("p0", follower)])
        assert forced is not None
        assert forced.best.order[1] == follower
    free = place_pieces(pieces)
    assert free is not None and free.alternatives
    assert free.alternatives[0].energy == pytest.approx(free.best.energy)  # a reported tie


def test_order_hint_is_followed(l_room):
    pieces = chains_from_polygon(l_room, [1.0, 9.5, 14.0, 20.0], [0, 2, 1, 3])
    placement = place_pieces(pieces, order_hint=["p0", "p1", "p2", "p3"])
    assert placement is not None
    assert placement.best.order == ("p0", "p1", "p2", "p3")


def test_single_partial_piece_is_placed_open():
    square = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], dtype=np.float64)
    piece = chains_from_polygon(square, [1.0, 9.0], [0, 0])[0]
    placement = place_pieces([piece])
    assert placement is not None
    assert not placement.closed


@pytest.mark.parametrize("term", ["use_complexity", "use_closure", "use_boundary"])
def test_each_energy_term_can_be_switched_off(l_room, term):
    pieces = chains_from_polygon(l_room, [1.0, 9.5, 14.0, 20.0], [0, 1, 2, 3])
    placement = place_pieces(pieces, PlacementParams(**{term: False}))
    assert placement is not None
    best = placement.best
    full = best.complexity + best.closure + best.boundary + 10.0 * best.free_space
    dropped = {
        "use_complexity": best.complexity,
        "use_closure": best.closure,
        "use_boundary": best.boundary,
    }[term]
    assert best.energy == pytest.approx(full - dropped)


def test_invalid_placements_are_rejected(l_room):
    pieces = chains_from_polygon(l_room, [1.0, 9.5, 14.0, 20.0], [0, 0, 0, 0])
    assert evaluate_placement(pieces, ["p1", "p0", "p2", "p3"], [0, 0, 0, 0]) is None
    # Folding a piece back onto the previous wall (a 180 degree junction) is not a loop.
    assert evaluate_placement(pieces, ["p0", "p1", "p2", "p3"], [0, 2, 0, 0]) is None


def test_alternatives_are_distinct_placements(l_room):
    # The quick broadening passes and the full pass meet the same leaves: each is kept once.
    pieces = chains_from_polygon(l_room, [1.0, 9.5, 14.0, 20.0, 25.5], [0, 1, 2, 3, 1])
    placement = place_pieces(pieces, PlacementParams(top_k=5))
    assert placement is not None
    keys = [(c.order, c.rotations) for c in (placement.best, *placement.alternatives)]
    assert len(keys) == len(set(keys)) == 5


def _grid(x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
    xs, ys = np.meshgrid(np.arange(x0, x1, 0.25), np.arange(y0, y1, 0.25))
    return np.column_stack([xs.ravel(), ys.ravel()])


def test_space_seen_behind_the_fragments_own_wall_is_not_footprint():
    # A wall along +x at y = 0 (interior above it); the scan also saw floor through a door,
    # 1 to 2 m behind the wall: that space is outside the room by the scan's own evidence.
    frame = ManhattanFrame(rotation=np.eye(3), floor_z=0.0, ceiling_z=None)
    front, behind = _grid(0.1, 4.0, 0.1, 2.0), _grid(1.0, 3.0, -2.0, -1.0)
    layout = LocalLayout(
        keypoints=np.array([[0.0, 0.0], [4.0, 0.0]]),
        frame=frame,
        footprint=np.vstack([front, behind]),
    )
    piece = make_piece("f", layout)
    assert len(piece.footprint) == len(front)
    assert piece.footprint[:, 1].min() > 0.0


def test_free_space_counts_the_share_of_scanned_floor_outside_the_room(l_room):
    pieces = chains_from_polygon(l_room, [1.0, 9.5, 14.0, 20.0], [0, 0, 0, 0])
    order, rotations = ["p0", "p1", "p2", "p3"], [0, 0, 0, 0]
    # p0 starts at (1, 0) on the bottom wall: cells relative to its source.
    inside, outside = _grid(0.5, 2.5, 0.5, 2.5), _grid(-4.0, -2.0, 0.5, 2.5)
    params = PlacementParams(use_boundary=False)
    for cells, share in ((inside, 0.0), (np.vstack([inside, outside]), 0.5)):
        scanned = [dataclasses.replace(pieces[0], footprint=cells), *pieces[1:]]
        cand = evaluate_placement(scanned, order, rotations, params)
        assert cand is not None
        assert cand.free_space == pytest.approx(share)


def test_reach_bounds_where_a_rotated_piece_can_move_the_loops_end():
    # An L of two 2 m walls: its end moves 2 m along an axis but 4 m along a diagonal.
    empty3, empty2 = np.zeros((0, 3)), np.zeros((0, 2))
    corner = Piece(
        "l", np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]]), (0, 1), empty3, empty3, empty2
    )
    directions = map(tuple, _CLOSURE_DIRECTIONS.tolist())
    reach = dict(zip(directions, corner.reach.tolist(), strict=True))
    assert reach[(1.0, 0.0)] == pytest.approx(2.0)
    assert reach[(1.0, 1.0)] == pytest.approx(4.0)
    # Never less than any rotation actually reaches (the bound stays a lower bound).
    for r in range(4):
        moved = rot90(r) @ corner.keypoints[-1]
        assert np.all(_CLOSURE_DIRECTIONS @ moved <= corner.reach + 1e-12)


def _profile(rng: np.random.Generator, interior: tuple[float, float]) -> np.ndarray:
    """Boundary points of a plain wall with floor: (M, 3), the wall through the origin,
    the interior towards ``interior``; 10 cm thick band along the wall."""
    offset = np.concatenate([np.zeros(300), rng.uniform(0.0, 2.0, 300)])
    height = np.concatenate([rng.uniform(0.0, 2.5, 300), np.zeros(300)])
    along = rng.uniform(-0.1, 0.1, 600)
    normal = np.asarray(interior)
    wall = np.array([normal[1], -normal[0]])
    xy = offset[:, None] * normal + along[:, None] * wall
    return np.column_stack([xy, height])


def test_boundary_mismatch_reads_each_profile_in_its_own_cutting_plane():
    # a ends on a wall along +x (interior +y); b starts on a wall along +y (interior -x),
    # as when the cut fell at a corner. The two profiles are the same wall-and-floor shape.
    rng = np.random.default_rng(5)
    empty3, empty2 = np.zeros((0, 3)), np.zeros((0, 2))
    a = Piece("a", np.array([[-2.0, 0.0], [0.0, 0.0]]), (0,), empty3, _profile(rng, (0, 1)), empty2)
    b = Piece("b", np.array([[0.0, 0.0], [0.0, 2.0]]), (1,), _profile(rng, (-1, 0)), empty3, empty2)
    straight = Piece("c", a.keypoints, (0,), _profile(rng, (0, 1)), empty3, empty2)
    params = PlacementParams()
    assert _boundary_mismatch(a, b, params) == pytest.approx(
        _boundary_mismatch(a, straight, params), abs=0.05
    )
    assert _boundary_mismatch(a, b, params) < 0.2
