"""Frames of one station: the kept assemblies ranked by where their cameras stand."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from schemas.params import PlacementParams
from services.placement import (
    Piece,
    PlacementCandidate,
    place_pieces,
    rot90,
    translations_of,
)
from services.placement.priors import PiecePrior, SiteHints
from services.refinement import placed_cameras, prior_anchors, refine_translations
from services.stations import (
    broken_mates,
    refined_cameras,
    station_cost,
    station_count,
    with_station_cost,
    with_station_scored,
)
from tests.conftest import chains_from_polygon

pytestmark = pytest.mark.timeout(60)

ROOM = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [0.0, 4.0]])
SOURCES = ROOM  # the four frames are cut at the corners: each sees one whole wall
TURNS = [0, 1, 2, 3]  # each frame's own frame is turned by this many quarters


# Two stations: the frames of the bottom and right walls from one, the others' from another.
STATIONS = np.array([[4.5, 1.0], [4.5, 1.0], [1.0, 3.0], [1.0, 3.0]])


def _frames(cameras: np.ndarray | None) -> list[Piece]:
    """The four single-wall frames of the 6 x 4 m room, each taken from its camera (world;
    none: clouds)."""
    pieces = chains_from_polygon(ROOM, [0.0, 6.0, 10.0, 16.0], TURNS)
    if cameras is None:
        return pieces
    return [
        dataclasses.replace(p, cameras=((camera - source) @ rot90(turn).T)[None, :])
        for p, camera, source, turn in zip(pieces, cameras, SOURCES, TURNS, strict=True)
    ]


def test_the_assembly_whose_cameras_stand_together_wins_a_tie() -> None:
    # A rectangle's opposite walls look alike: the frames of its two short walls fit each
    # other's wall as well, each turned half. The walls cannot tell those assemblies apart;
    # the stations, off the room's centre, can.
    plain = place_pieces(_frames(None))
    assert plain is not None
    rivals = [c for c in plain.candidates if c.energy <= plain.best.energy + 1e-9]
    assert len(rivals) >= 2  # a tie among the look-alikes
    pieces = _frames(STATIONS)
    placement = place_pieces(pieces)
    assert placement is not None
    ranked = with_station_cost(placement, pieces, PlacementParams())
    assert ranked.best.order == ("p0", "p1", "p2", "p3")
    assert ranked.best.rotations == (0, 3, 2, 1)  # each frame turned back into the room's
    two = PlacementParams().station_occam  # two stations: one beyond the first
    assert ranked.best.features["stations"] == pytest.approx(two, abs=1e-3)
    assert all(c.features["stations"] > two + 1.0 for c in ranked.alternatives if not c.missing)
    assert ranked.alternatives[0].energy > ranked.best.energy + 1.0
    np.testing.assert_allclose(ranked.translations, SOURCES, atol=1e-6)


def test_of_assemblies_whose_cameras_all_have_partners_fewer_stations_win() -> None:
    # Every frame taken from one camera off the room's centre. Swapping the frames of the
    # two short walls (each turned half round onto the other's wall) moves both their
    # cameras to the same mirrored point: every camera still has a partner, now at two
    # stations. Only the count of stations tells that rival from the truth.
    pieces = _frames(np.repeat([[4.5, 1.0]], 4, axis=0))
    placement = place_pieces(pieces)
    assert placement is not None
    truth, swapped = ("p0", "p1", "p2", "p3"), ("p0", "p3", "p2", "p1")
    counted = with_station_cost(placement, pieces, PlacementParams())
    assert counted.best.order == truth
    rival = next(c for c in counted.alternatives if c.order == swapped)
    assert rival.features["stations"] == pytest.approx(PlacementParams().station_occam, abs=0.05)
    assert rival.energy > counted.best.energy + 1.0
    blind = with_station_cost(placement, pieces, PlacementParams(station_occam=0.0))
    energy = {c.order: c.energy for c in (blind.best, *blind.alternatives)}
    assert energy[swapped] == pytest.approx(energy[truth], abs=0.05)  # without it: a tie


def test_clouds_and_a_weight_of_nothing_leave_the_placement_as_it_is() -> None:
    clouds = _frames(None)
    placement = place_pieces(clouds)
    assert placement is not None
    assert with_station_cost(placement, clouds, PlacementParams()) is placement
    frames = _frames(STATIONS)
    placement = place_pieces(frames)
    assert placement is not None
    off = PlacementParams(station_weight=0.0)
    assert with_station_cost(placement, frames, off) is placement


def test_a_station_cost_counts_each_camera_to_its_nearest_other_frame() -> None:
    one = np.zeros((1, 2))
    assert station_cost([], 0.6, 0.3) == 0.0  # no pieces at all
    # Two cameras of one frame do not make a station of it.
    assert station_cost([np.array([[0.0, 0.0], [0.1, 0.0]])], 0.6, 0.3) == 0.0
    near = station_cost([one, np.array([[0.3, 0.0]]), np.array([[3.0, 0.0]])], 0.6, 0.3)
    assert near == pytest.approx(0.5 + 0.5 + 2.0)  # the far camera costs the cap


def test_prior_poses_anchor_the_refinement_a_station_term_is_measured_on() -> None:
    # The result's poses come from a refinement the priors anchor; the cameras the term is
    # measured on must be those, not an unanchored loop's. A prior 0.3 m off one frame's
    # source (two of its sigmas: kept, not dropped as a stray) pulls its camera off the
    # station's.
    pieces = _frames(STATIONS)
    placement = place_pieces(pieces)
    assert placement is not None
    truth = with_station_cost(placement, pieces, PlacementParams()).best
    turns = dict(zip(truth.order, truth.rotations, strict=True))
    offset = {"p1": np.array([0.0, 0.3])}
    priors = {
        p.id: PiecePrior(turns[p.id] * math.pi / 2, source + offset.get(p.id, 0.0), 0.15, 0.01)
        for p, source in zip(pieces, SOURCES, strict=True)
    }
    hints = SiteHints(priors=priors)
    # The term's distances alone (one station more or less would add a constant).
    distances = PlacementParams(station_occam=0.0)
    anchored = with_station_scored(truth, pieces, None, distances, hints)
    loose = with_station_scored(truth, pieces, None, distances)
    start = translations_of(pieces, truth)
    refined = refine_translations(
        pieces, truth.rotations, start, PlacementParams(), None, prior_anchors(hints, truth, start)
    )
    cameras = placed_cameras(pieces, truth.rotations, refined.translations)
    assert not refined.strays[1]
    assert anchored.features["stations"] == pytest.approx(station_cost(cameras, 0.6, 0.3))
    assert anchored.features["stations"] > 10 * loose.features["stations"]


def test_a_station_counts_cameras_linked_by_short_steps() -> None:
    cameras = [np.array([[0.0, 0.0], [0.5, 0.0]]), np.array([[1.0, 0.0]]), np.zeros((0, 2))]
    assert station_count(cameras, 0.6) == 1  # a chain of steps under the reach is one
    assert station_count(cameras, 0.45) == 3
    assert station_count([np.array([[0.0, 0.0]]), np.array([[3.0, 0.0]])], 0.6) == 2
    assert station_count([np.zeros((0, 2))], 0.6) == 0
    assert station_count([], 0.6) == 0


def test_the_refined_cameras_of_the_right_room_stand_at_its_stations() -> None:
    pieces = _frames(STATIONS)
    placement = place_pieces(pieces)
    assert placement is not None
    best = with_station_cost(placement, pieces, PlacementParams()).best
    cameras = refined_cameras(best, pieces, placement.measured, PlacementParams())
    # Loop order p0..p3: each piece's camera where the room's truth puts it.
    np.testing.assert_allclose(np.vstack(cameras), STATIONS, atol=0.01)
    assert station_count(cameras, PlacementParams().station_reach) == 2
    # A rival turning the short walls' frames half about stands them elsewhere.
    rival = next(c for c in placement.candidates if not c.missing and c.rotations != best.rotations)
    scattered = refined_cameras(rival, pieces, placement.measured, PlacementParams())
    assert station_count(scattered, PlacementParams().station_reach) > 2


def test_frames_whose_views_share_a_camera_cost_the_assemblies_turning_them_otherwise() -> None:
    # The bottom and right walls' frames were taken from one camera and their views agree
    # at the truth's quarter turn between them (p1 turned 3 more than p0).
    pieces = _frames(STATIONS)
    pieces[0] = dataclasses.replace(pieces[0], station_mates=(("p1", 3),))
    pieces[1] = dataclasses.replace(pieces[1], station_mates=(("p0", 1),))
    placement = place_pieces(pieces)
    assert placement is not None
    truth = next(
        c
        for c in placement.candidates
        if c.order == ("p0", "p1", "p2", "p3") and c.rotations == (0, 3, 2, 1)
    )
    assert broken_mates(truth, pieces) == 0

    def p1_turn(cand: PlacementCandidate) -> int:
        turns = dict(zip(cand.order, cand.rotations, strict=True))
        return (turns["p1"] - turns["p0"]) % 4

    turned = [c for c in placement.candidates if not c.missing and p1_turn(c) != 3]
    assert turned  # some kept assembly turns p1 otherwise
    assert all(broken_mates(c, pieces) == 1 for c in turned)
    priced, free = PlacementParams(station_mate_cost=1.5), PlacementParams(station_mate_cost=0.0)
    for cand in (truth, turned[0]):
        cost = with_station_scored(cand, pieces, None, priced).features["stations"]
        cost -= with_station_scored(cand, pieces, None, free).features["stations"]
        assert cost == pytest.approx(1.5 * broken_mates(cand, pieces))
