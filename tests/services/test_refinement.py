"""Pose refinement QP: junction constraints hold, failures fall back and say so."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from schemas.params import PlacementParams
from services.evaluation import polygon_keypoint_error
from services.layout_model import build_polygon
from services.placement import Piece, place_pieces, rot90, translations_of
from services.placement.search import evaluate_placement
from services.refinement import (
    Anchor,
    measured_shifts,
    refine_translations,
    stray_anchors,
    translation_spread,
)
from tests.conftest import UNTUNED, bare_piece, chains_from_polygon, overlapping_halves

pytestmark = pytest.mark.timeout(60)


def _sites(pieces, rotations, translations):
    return [
        p.keypoints @ rot90(r).T + t
        for p, r, t in zip(pieces, rotations, translations, strict=True)
    ]


def test_parallel_junctions_become_collinear(l_room):
    pieces = chains_from_polygon(l_room, [1.0, 9.5, 12.5, 20.0], [0, 1, 2, 3])
    placement = place_pieces(pieces)
    assert placement is not None
    ordered = {p.id: p for p in pieces}
    ordered_pieces = [ordered[i] for i in placement.best.order]
    # Disturb the placement: pieces drift off their walls.
    noisy = placement.translations + np.array([[0, 0], [0.05, -0.08], [0.1, 0.04], [-0.06, 0.07]])
    # Chains cut from the polygon meet exactly: refined expecting no overlap at the cuts.
    refined = refine_translations(ordered_pieces, placement.best.rotations, noisy, UNTUNED)
    assert refined.status == "solved"
    assert refined.violation_before > 0.01
    assert refined.violation_after < 1e-3
    sites = _sites(ordered_pieces, placement.best.rotations, refined.translations)
    for i in range(len(sites)):
        q, p = sites[i][-1], sites[(i + 1) % len(sites)][0]
        d_in, d_out = sites[i][-1] - sites[i][-2], sites[(i + 1) % len(sites)][1] - p
        if abs(d_in @ d_out) > 0:  # parallel junction: same wall line
            axis = 1 if abs(d_in[0]) > abs(d_in[1]) else 0
            assert q[axis] == pytest.approx(p[axis], abs=1e-3)
    assert np.allclose(refined.translations[0], placement.translations[0])


def test_conflicting_inequalities_are_relaxed_and_say_so():
    # A loop of two collinear straight walls: at each junction the next wall must reach past
    # the previous one's far end (no overrun); both together are impossible, so the QP is
    # solved again without the inequalities and the status says so.
    square = np.array([[0, 0], [6, 0], [6, 6], [0, 6]], dtype=np.float64)
    bottom = chains_from_polygon(square, [1.0, 5.0], [0, 0])[0]
    refined = refine_translations([bottom, bottom], [0, 0], np.array([[0.0, 0.0], [4.0, 0.05]]))
    assert refined.status.startswith("relaxed")
    # The walls were pulled onto one line.
    assert refined.translations[1][1] == pytest.approx(0.0, abs=0.02)


def test_unsolvable_input_falls_back_to_the_placement():
    square = np.array([[0, 0], [6, 0], [6, 6], [0, 6]], dtype=np.float64)
    a, b = chains_from_polygon(square, [1.0, 13.0], [0, 0])
    translations = np.array([[0.0, 0.0], [np.nan, 0.0]])
    refined = refine_translations([a, b], [0, 0], translations)
    assert refined.status.startswith("fallback")
    assert np.array_equal(refined.translations, translations, equal_nan=True)


@pytest.mark.parametrize(("with_structure", "overlap"), [(True, -0.4), (False, -0.2)])
def test_an_overlap_the_structure_measures_takes_the_loop_gap(with_structure, overlap):
    # The loop's 0.4 m gap must go somewhere. Unmeasured, the two straight junctions share
    # it (the room comes out 0.2 m long, junctions hiding no overlap on average); measured,
    # the bottom junction takes all of it.
    pieces = overlapping_halves(with_structure)
    cand = evaluate_placement(pieces, ["p0", "p1"], [0, 0], UNTUNED)
    assert cand is not None
    shifts = measured_shifts(pieces, [0, 0])
    assert shifts[0] is None  # the top cut: nothing to register
    assert (shifts[1] is not None) == with_structure
    refined = refine_translations(pieces, [0, 0], translations_of(pieces, cand), UNTUNED)
    sites = _sites(pieces, [0, 0], refined.translations)
    bottom = sites[0][0][0] - sites[1][-1][0]  # p0's source past p1's target, along +x
    assert bottom == pytest.approx(overlap, abs=0.05)


def test_an_unmeasured_overlap_is_guessed_from_the_overlaps_scans_usually_have():
    # The halves overlap 0.4 m at the bottom cut; the top cut is a hidden corner. Expecting
    # no overlap, the refinement splits the loop's gap between the two; expecting the
    # overlap measured on the benchmarks (-0.2 m on average), the bottom takes more of it.
    pieces = overlapping_halves(False)
    cand = evaluate_placement(pieces, ["p0", "p1"], [0, 0])
    assert cand is not None
    start = translations_of(pieces, cand)

    def bottom(params: PlacementParams) -> float:
        refined = refine_translations(pieces, [0, 0], start, params)
        sites = _sites(pieces, [0, 0], refined.translations)
        return float(sites[0][0][0] - sites[1][-1][0])

    assert PlacementParams().refined_junction_mean < 0.0
    assert abs(bottom(PlacementParams()) + 0.4) < abs(bottom(UNTUNED) + 0.4) - 0.05


def test_the_placements_measurements_are_the_ones_the_refinement_takes():
    # The search registers every pair's ends once; the refinement reuses what it measured
    # instead of registering again, with the same result.
    pieces = overlapping_halves(True)
    placement = place_pieces(pieces)
    assert placement is not None
    order = {p.id: p for p in pieces}
    ordered = [order[fid] for fid in placement.best.order]
    rotations = placement.best.rotations
    assert placement.measured  # the structured bottom cut measures
    reused = measured_shifts(ordered, rotations, placement.measured)
    assert reused == measured_shifts(ordered, rotations)
    assert any(shift is not None for shift in reused)
    again = refine_translations(ordered, rotations, placement.translations)
    taken = refine_translations(
        ordered, rotations, placement.translations, measured=placement.measured
    )
    assert np.array_equal(again.translations, taken.translations)


def test_pieces_free_to_slide_have_a_wide_spread_that_a_measured_overlap_narrows():
    # Two halves cut on opposite walls: closing the loop fixes only the sum of the two
    # junctions' overlaps, so the second half may slide along the walls by the overlap
    # model's spread. Where one end's structure measures its overlap, the slide is pinned.
    free = overlapping_halves(False)
    pinned = overlapping_halves(True)
    assert measured_shifts(free, [0, 0]) == [None, None]
    spread_free = translation_spread(free, [0, 0])
    spread_pinned = translation_spread(pinned, [0, 0])
    params = PlacementParams()
    # Half the slide's variance: two junctions of that spread share it (and the first piece,
    # the frame, does not move at all).
    slide = np.hypot(params.junction_sigma, params.keypoint_sigma) / np.sqrt(2.0)
    assert spread_free == pytest.approx(slide / np.sqrt(2.0), rel=0.2)
    assert spread_pinned < 0.5 * spread_free


def test_priors_pin_pieces_the_junctions_leave_free_and_a_lone_prior_pins_nothing():
    # Two priors of 5 cm fix the halves relative to each other (the hints' frame itself is
    # free); a single prior only says where the room is, not how long it is.
    free = overlapping_halves(False)
    spread_free = translation_spread(free, [0, 0])
    both = {"p0": 0.05, "p1": 0.05}
    pinned = translation_spread(free, [0, 0], prior_sigmas=both)
    # At most the spread of the second half's position relative to the first by the two
    # priors alone (per axis hypot(5 cm, 5 cm), over two pieces, one fixed).
    assert pinned < np.hypot(0.05, 0.05)
    assert pinned < 0.5 * spread_free
    lone = translation_spread(free, [0, 0], prior_sigmas={"p1": 0.05})
    assert lone == pytest.approx(spread_free)
    loose = translation_spread(free, [0, 0], prior_sigmas={"p0": 50.0, "p1": 50.0})
    assert loose == pytest.approx(spread_free, rel=0.01)


def test_prior_positions_fix_what_the_junctions_leave_to_the_model():
    # The halves overlap 0.4 m at the bottom cut, which nothing measures: without priors the
    # second half sits where the overlap model (no overlap on average) guesses. Priors of
    # 2 cm at the true sources (in a frame shifted by (10, -5): only their relative
    # positions count) put it there.
    pieces = overlapping_halves(False)
    start = np.array([[3.0, 0.0], [0.3, 4.0]])
    guessed = refine_translations(pieces, [0, 0], start, UNTUNED)
    truth = np.array([[3.0, 0.0], [0.0, 4.0]])  # the sources: mid-bottom, top-left corner
    anchors = [Anchor(t + np.array([10.0, -5.0]), 0.02) for t in truth]
    anchored = refine_translations(pieces, [0, 0], start, UNTUNED, anchors=anchors)
    assert anchored.status == "solved"
    relative = anchored.translations[1] - anchored.translations[0]
    assert relative == pytest.approx(truth[1] - truth[0], abs=0.03)
    assert abs((guessed.translations[1] - guessed.translations[0] - relative)[0]) > 0.1
    # One prior alone pins nothing: the same as none.
    lone = refine_translations(pieces, [0, 0], start, UNTUNED, anchors=[None, anchors[1]])
    assert np.allclose(lone.translations, guessed.translations, atol=1e-6)


def test_a_prior_the_junctions_contradict_is_dropped():
    # A prior 5 m off where the walls must join is not obeyed: the refinement is the one
    # without priors.
    pieces = overlapping_halves(False)
    start = np.array([[3.0, 0.0], [0.3, 4.0]])
    guessed = refine_translations(pieces, [0, 0], start)
    anchors = [Anchor(np.array([3.0, 0.0]), 0.05), Anchor(np.array([0.0, 9.0]), 0.05)]
    stray = refine_translations(pieces, [0, 0], start, anchors=anchors)
    assert np.allclose(stray.translations, guessed.translations, atol=1e-6)


def test_one_prior_far_off_does_not_make_the_others_strays():
    # Three priors, one 1 m off at 5 cm: only that one is a stray.
    sources = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 3.0]])
    anchors = [Anchor(sources[0], 0.05), Anchor(sources[1], 0.05), Anchor(sources[2] + 1.0, 0.05)]
    assert stray_anchors(sources, anchors) == [False, False, True]
    assert stray_anchors(sources, [*anchors[:2], None]) == [False, False, False]


def test_a_lone_piece_has_no_spread():
    square = np.array([[0, 0], [6, 0], [6, 6], [0, 6]], dtype=np.float64)
    (whole,) = chains_from_polygon(square, [1.0], [0])
    assert translation_spread([whole], [0]) == 0.0


# A 6 x 4 m room seen by four single-wall frames from its centre (3, 2): each sees its wall
# 0.4 m short at both ends, so every junction hides a corner and 0.4 m either side of it.
_WALLS = (
    ((0.4, 0.0), (5.6, 0.0)),
    ((6.0, 0.4), (6.0, 3.6)),
    ((5.6, 4.0), (0.4, 4.0)),
    ((0.0, 3.6), (0.0, 0.4)),
)


def _frames_around(
    camera: tuple[float, float] = (3.0, 2.0), walls: tuple[Any, ...] = _WALLS
) -> list[Piece]:
    pieces = []
    for k, (source, target) in enumerate(walls):
        chain = np.array([source, target]) - np.array(source)
        offset = np.array([camera]) - np.array(source)
        pieces.append(dataclasses.replace(bare_piece(f"f{k}", chain), cameras=offset))
    return pieces


def _end_to_end(pieces: list[Piece]) -> np.ndarray:
    cand = evaluate_placement(pieces, [p.id for p in pieces], [0] * len(pieces))
    assert cand is not None
    return translations_of(pieces, cand)


def test_frames_of_one_station_fix_the_room_the_junctions_leave_to_the_model():
    # Joined end to end the room is 5.2 x 3.2 m, and the junctions' model (a hidden corner
    # with no unseen wall on average) keeps it so; the four cameras, one station, make it
    # the 6 x 4 m room they saw it from. Neighbours' cameras start 0.57 m apart, within
    # reach, and joined pairwise they all coincide; opposite walls' start 0.8 m apart, out
    # of reach, and are not taken in afterwards (that would chain stations together).
    pieces = _frames_around()
    start = _end_to_end(pieces)
    guessed = refine_translations(pieces, [0] * 4, start, PlacementParams(station_reach=0.0))
    joined = refine_translations(pieces, [0] * 4, start)
    assert guessed.stations == ()
    assert joined.status == "solved"
    assert sorted(joined.stations) == [(0, 1), (0, 3), (1, 2), (2, 3)]
    sources = joined.translations - joined.translations[0]
    truth = np.array([source for source, _ in _WALLS]) - np.array(_WALLS[0][0])
    assert sources == pytest.approx(truth, abs=0.05)
    assert abs((guessed.translations[1] - guessed.translations[0])[0] - 5.6) > 0.3


def test_cameras_out_of_each_others_reach_are_other_stations():
    # Cameras 2 m or more apart are not taken for one station: the refinement is the one
    # without cameras.
    pieces = [
        dataclasses.replace(p, cameras=p.cameras + shift)
        for p, shift in zip(_frames_around(), ([0, 0], [2, 0], [2, 2], [0, 2]), strict=True)
    ]
    start = _end_to_end(pieces)
    plain = refine_translations(pieces, [0] * 4, start, PlacementParams(station_reach=0.0))
    refined = refine_translations(pieces, [0] * 4, start)
    assert refined.stations == ()
    assert np.allclose(refined.translations, plain.translations)


def test_a_station_the_walls_keep_apart_is_dropped():
    # Two frames of the bottom wall (cut in its middle, so their walls must stay on one
    # line) whose cameras stand 0.5 m apart across it are two stations after all; the other
    # pairs keep their station.
    room = np.array([[0, 0], [6, 0], [6, 4], [0, 4]], dtype=np.float64)
    chains = chains_from_polygon(room, [0.6, 3.0, 6.6, 10.6, 16.6], [0] * 5)
    sources = np.array([[0.6, 0.0], [3.0, 0.0], [6.0, 0.6], [5.4, 4.0], [0.0, 3.4]])
    cameras = np.array([[3.0, 1.5], [3.0, 2.0], [3.0, 2.0], [3.0, 2.0], [3.0, 2.0]])
    pieces = [
        dataclasses.replace(p, cameras=(camera - source)[None, :])
        for p, source, camera in zip(chains, sources, cameras, strict=True)
    ]
    refined = refine_translations(pieces, [0] * 5, _end_to_end(pieces))
    assert refined.status == "solved"
    assert (0, 1) not in refined.stations
    assert {(1, 2), (1, 3), (1, 4), (2, 3)} <= set(refined.stations)
    walls = _sites(pieces, [0] * 5, refined.translations)
    assert walls[0][0][1] == pytest.approx(walls[1][0][1], abs=0.11)  # still one line


def test_frames_whose_views_share_a_camera_are_one_station_however_far_apart_the_loop_puts_them():
    # The same room's walls seen 1 m short at both ends: joined end to end, neighbouring
    # cameras stand 1.4 m apart, out of reach. Frames whose views say they share the camera
    # (station_mates, with the turn the assembly gives them) are one station all the same,
    # and the room is the 6 x 4 m one; told another turn, they are not taken.
    walls = (((1.0, 0.0), (5.0, 0.0)), ((6.0, 1.0), (6.0, 3.0)), ((5.0, 4.0), (1.0, 4.0)),
             ((0.0, 3.0), (0.0, 1.0)))  # fmt: skip
    pieces = _frames_around(walls=walls)
    start = _end_to_end(pieces)
    assert refine_translations(pieces, [0] * 4, start).stations == ()

    def told(turn: int) -> list[Piece]:
        return [
            dataclasses.replace(p, station_mates=tuple((q.id, turn) for q in pieces if q is not p))
            for p in pieces
        ]

    joined = refine_translations(told(0), [0] * 4, start)
    assert joined.status == "solved"
    assert sorted(joined.stations) == [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    sources = joined.translations - joined.translations[0]
    truth = np.array([source for source, _ in walls]) - np.array(walls[0][0])
    assert sources == pytest.approx(truth, abs=0.05)
    assert refine_translations(told(1), [0] * 4, start).stations == ()


# An L room (counter-clockwise) whose step wall y = 3.3 no frame saw: the chain along x = 4
# ends at the protruding corner, where its view lost the wall, and the next starts on
# x = 7.6 above it.
STEPPED_ROOM = np.array(
    [[0, 0], [4, 0], [4, 3.3], [7.6, 3.3], [7.6, 6.4], [0, 6.4]], dtype=np.float64
)
STEPPED_CHAINS = [
    [(0.0, 2.0), (0.0, 0.0), (2.5, 0.0)],
    [(2.5, 0.0), (4.0, 0.0), (4.0, 3.3)],
    [(7.6, 3.9), (7.6, 6.4), (4.0, 6.4)],
    [(4.0, 6.4), (0.0, 6.4), (0.0, 2.0)],
]


def _stepped(open_end: bool) -> list[Piece]:
    pieces = []
    for k, chain in enumerate(STEPPED_CHAINS):
        points = np.asarray(chain)
        piece = bare_piece(f"p{k}", points - points[0])
        if k == 1 and open_end:
            piece = dataclasses.replace(piece, open_ends=(False, True))
        pieces.append(piece)
    return pieces


def test_a_junction_at_an_open_end_keeps_the_step_the_view_lost():
    truth = [np.asarray(chain[0]) for chain in STEPPED_CHAINS]
    for open_end in (True, False):
        pieces = _stepped(open_end)
        loop = evaluate_placement(pieces, ["p0", "p1", "p2", "p3"], [0, 0, 0, 0], UNTUNED)
        assert loop is not None
        refined = refine_translations(pieces, [0, 0, 0, 0], np.asarray(truth), UNTUNED)
        sites = _sites(pieces, [0, 0, 0, 0], refined.translations)
        step = sites[2][0][0] - sites[1][-1][0]  # x of the wall after less the one before
        if open_end:
            # The loop closes through the open end at a small cost, and the refinement
            # keeps the step (most of its 3.6 m: the other junctions give a little): the
            # floorplan passes the paper's 5 % test.
            assert loop.features["closure"] < 5.0
            assert step == pytest.approx(3.6, abs=0.4)
            polygon = build_polygon(pieces, [0, 0, 0, 0], refined.translations)
            diagonal = float(np.hypot(7.6, 6.4))
            assert polygon_keypoint_error(polygon, STEPPED_ROOM) < 0.05 * diagonal
        else:
            # A junction seen on both sides may hide no step: the walls are made collinear.
            assert loop.features["closure"] > 20.0
            assert abs(step) < 0.05
