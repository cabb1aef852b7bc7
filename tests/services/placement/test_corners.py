"""Shared corners: pieces that both saw one corner, placed with the corners coinciding."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from services.geometry import signed_area
from services.layout_model import build_polygon
from services.placement import SiteHints, evaluate_placement, place_pieces, translations_of
from services.placement import search as search_module
from services.placement.corners import corner_offsets, corner_view, entered_at_corner, sharings
from services.refinement import refine_translations
from tests.conftest import UNTUNED, chains_from_polygon, point_at_arc

pytestmark = pytest.mark.timeout(120)

GEOMETRY = UNTUNED.model_copy(
    update={"use_boundary": False, "use_structure": False, "use_free_space": False}
)
# A 6 x 4 room (perimeter 20). Piece p1 starts 1 m before the corner at (6, 0), which p0
# turned 2 m before its end: the two overlap across that corner.
ROOM = np.array([[0, 0], [6, 0], [6, 4], [0, 4]], dtype=np.float64)
STARTS = [1.0, 5.0, 13.0]
ENDS = [8.0, 13.0, 21.0]
TURNS = [0, 3, 1]
# p1 starts 1 m before (6, 0), p0 ends 2 m past (6, 4): they share both corners.
TWO_STARTS = [1.0, 5.0, 15.0]
TWO_ENDS = [12.0, 15.0, 21.0]


def _frames(starts=STARTS, ends=ENDS, turns=TURNS, polygon=ROOM):
    pieces = chains_from_polygon(polygon, starts, turns, ends)
    return [dataclasses.replace(p, evidence="frame") for p in pieces]


def test_pieces_share_corners_that_turn_alike_and_fit_into_each_other():
    p0, p1, p2 = _frames()
    assert sharings(p0, p1) == (1,)
    # Any two frames whose corners turn alike may share one (the energy tells which do)...
    assert sharings(p1, p2) == (1,)
    # ...unless the later piece's wall after the corner ends before the earlier's does (p0's
    # 2 m against p1's 3 m), or its wall before the corner runs far past the earlier's
    # (p0's 5 m against p2's 4 m).
    assert sharings(p1, p0) == ()
    assert sharings(p2, p0) == ()
    clouds = [dataclasses.replace(p, evidence="cloud") for p in (p0, p1)]
    assert sharings(*clouds) == ()
    # Two corners: the wall between them as long in both (4 m).
    q0, q1, _ = _frames(TWO_STARTS, TWO_ENDS)
    assert sharings(q0, q1) == (1, 2)
    short = dataclasses.replace(q1, keypoints=q1.keypoints * np.array([0.9, 1.0]))
    assert 2 not in sharings(q0, short)


def test_the_search_places_an_overlap_across_a_corner_at_that_corner():
    pieces = _frames()
    placement = place_pieces(pieces, GEOMETRY)
    assert placement is not None and placement.exhaustive
    best = placement.best
    assert best.order == ("p0", "p1", "p2")
    assert best.shared == (0, 1, 0)
    # Each piece's source where the room has it, relative to p0's (p0 is not turned).
    truth = np.array([point_at_arc(ROOM, s) for s in STARTS]) - point_at_arc(ROOM, STARTS[0])
    assert np.allclose(placement.translations, truth, atol=1e-9)
    assert best.rotations == tuple((-t) % 4 for t in TURNS)
    # Without shared corners the same loop needs a hidden concave corner with 2 m and 1 m
    # of unseen wall either side: far less likely.
    plain = GEOMETRY.model_copy(update={"share_corners": False})
    without = evaluate_placement(pieces, best.order, best.rotations, plain)
    assert without is not None and without.energy > best.energy + 5.0


def test_evaluation_tries_every_shared_corner_and_matches_the_search():
    pieces = _frames()
    placement = place_pieces(pieces, GEOMETRY)
    assert placement is not None
    best = placement.best
    scored = evaluate_placement(pieces, best.order, best.rotations, GEOMETRY)
    assert scored is not None and scored.shared == best.shared
    assert scored.energy == pytest.approx(best.energy)
    # Brute force over orders, rotations and shared corners finds nothing better.
    rest = [p.id for p in pieces[1:]]
    for perm in itertools.permutations(rest):
        for rots in itertools.product(range(4), repeat=len(rest)):
            cand = evaluate_placement(pieces, ("p0", *perm), (0, *rots), GEOMETRY)
            assert cand is None or cand.energy >= best.energy - 1e-9


def test_a_shared_closing_junction_is_found_from_either_first_piece():
    # The loop closes at the shared corner when p1 leads.
    pieces = _frames()
    led = [pieces[1], pieces[2], pieces[0]]
    placement = place_pieces(led, GEOMETRY)
    assert placement is not None
    assert placement.best.order == ("p1", "p2", "p0")
    assert placement.best.shared == (1, 0, 0)


def test_the_beams_wall_test_cuts_a_shared_corners_walls_as_extend_does():
    pieces = _frames()
    search = search_module._Search(pieces, GEOMETRY, SiteHints(), True)
    root = search_module._root(search)
    children = search_module._children(search, [root])
    assert children.corners.any()
    placed = search_module._Placed.of([root])
    walls, crosses = search_module._children_walls(search, placed, children, slice(None))
    for c in range(len(children.piece)):
        j, shared = int(children.piece[c]), int(children.corners[c])
        own = search_module._walls_clear(
            search, root, j, int(children.rotation[c]), children.source[c], shared
        )
        count = search.wall_count[j] - shared
        if own is not None:
            assert np.array_equal(walls[c, :count], own)
            assert not crosses[c]
        else:
            assert crosses[c]


def test_a_corner_view_joins_the_shared_corner_straight():
    pieces = _frames()
    placement = place_pieces(pieces, GEOMETRY)
    assert placement is not None
    best = placement.best
    ordered = [{p.id: p for p in pieces}[fid] for fid in best.order]
    view, measured = corner_view(ordered, best.shared, {})
    moved = placement.translations + corner_offsets(ordered, best.rotations, best.shared)
    # p1 without its first wall starts at the corner (6, 0), 2 m behind p0's end.
    assert view[1].directions == ordered[1].directions[1:]
    assert np.array_equal(view[1].keypoints, entered_at_corner(ordered[1], 1).keypoints)
    corner = point_at_arc(ROOM, 6.0) - point_at_arc(ROOM, STARTS[0])
    assert np.allclose(moved[1], corner)
    assert np.allclose(moved[[0, 2]], placement.translations[[0, 2]])
    assert measured == {("p0", "p1"): pytest.approx(-2.0)}
    assert translations_of(pieces, best) == pytest.approx(placement.translations)


def test_an_overlap_across_two_corners_shares_both():
    pieces = _frames(TWO_STARTS, TWO_ENDS)
    placement = place_pieces(pieces, GEOMETRY)
    assert placement is not None and placement.exhaustive
    assert placement.best.order == ("p0", "p1", "p2")
    assert placement.best.shared == (0, 2, 0)
    truth = np.array([point_at_arc(ROOM, s) for s in TWO_STARTS]) - point_at_arc(ROOM, 1.0)
    assert np.allclose(placement.translations, truth, atol=1e-9)
    # Led by p1, the loop closes sharing them.
    led = place_pieces([pieces[1], pieces[2], pieces[0]], GEOMETRY)
    assert led is not None and led.best.shared == (2, 0, 0)


@pytest.mark.parametrize("seed", range(8))
def test_the_search_finds_the_least_energy_with_shared_corners(l_room, seed):
    # Overlaps of up to 5 m, many across one corner or two: the search's bounds must stay
    # below every way to finish the loop, shared corners and all (brute force agrees).
    rng = np.random.default_rng(seed)
    perimeter = 28.0
    starts = sorted((np.arange(4) * 7.0 + rng.uniform(0.0, 3.0, 4)).tolist())
    ends = [s + rng.uniform(0.0, 5.0) for s in [*starts[1:], starts[0] + perimeter]]
    pieces = _frames(starts, ends, rng.integers(0, 4, 4).tolist(), l_room)
    placement = place_pieces(pieces, GEOMETRY)
    assert placement is not None and placement.exhaustive
    least = np.inf
    for perm in itertools.permutations([p.id for p in pieces[1:]]):
        for rots in itertools.product(range(4), repeat=3):
            cand = evaluate_placement(pieces, ("p0", *perm), (0, *rots), GEOMETRY)
            if cand is not None:
                least = min(least, cand.energy)
    assert placement.best.energy == pytest.approx(least)


def test_a_loop_sharing_two_corners_refines_to_its_room():
    pieces = _frames(TWO_STARTS, TWO_ENDS)
    placement = place_pieces(pieces, GEOMETRY)
    assert placement is not None
    best = placement.best
    ordered = [{p.id: p for p in pieces}[fid] for fid in best.order]
    refined = refine_translations(
        ordered, best.rotations, placement.translations, GEOMETRY, {}, shared=best.shared
    )
    assert refined.status == "solved"
    assert np.allclose(refined.translations, placement.translations, atol=0.02)
    polygon = build_polygon(ordered, best.rotations, refined.translations, best.shared)
    assert len(polygon) == 4
    assert abs(signed_area(polygon)) == pytest.approx(24.0, rel=0.01)
