"""rank_assemblies: the placements found as distinct rooms with probabilities."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from services.confidence import (
    FITTED_STATIONS,
    KINECT_VIEW,
    rank_assemblies,
    room_slack,
    same_room_groups,
)
from services.geometry import signed_area
from services.placement import Piece, Placement, PlacementCandidate, place_pieces, translations_of
from tests.conftest import UNTUNED, chains_from_polygon

pytestmark = pytest.mark.timeout(120)

GEOMETRY = UNTUNED.model_copy(
    update={"use_boundary": False, "use_structure": False, "use_free_space": False}
)
SQUARE = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], dtype=np.float64)


def _ranked(polygon, cuts, params=GEOMETRY):
    pieces = chains_from_polygon(polygon, cuts, list(range(len(cuts))))
    placement = place_pieces(pieces, params)
    assert placement is not None and placement.closed
    return pieces, placement, rank_assemblies(pieces, placement, params)


def test_probabilities_are_sorted_and_leave_room_for_none_of_these(l_room):
    _, placement, assemblies = _ranked(l_room, [1.0, 9.5, 12.5, 20.0])
    assert len(assemblies) == len(placement.candidates) == 4  # four different rooms
    probabilities = [a.probability for a in assemblies]
    assert probabilities == sorted(probabilities, reverse=True)
    assert all(0.0 < p < 1.0 for p in probabilities)
    assert sum(probabilities) < 1.0
    # Boltzmann: the ratio of two rooms' probabilities is e to their energy difference.
    first, second = assemblies[0], assemblies[1]
    ratio = first.probability / second.probability
    assert ratio == pytest.approx(math.exp(second.candidate.energy - first.candidate.energy))
    assert first.candidate == placement.best


def test_swapped_identical_pieces_are_two_answers_of_one_floorplan():
    # A square cut into a U and two identical L pieces: p0 p1 p2 and p0 p2 p1 draw the same
    # floorplan, yet put the scans of p1 and p2 in each other's place: a fleet acting on
    # either map moves a robot to the wrong corner half the time, so neither is sure.
    _, placement, assemblies = _ranked(SQUARE, [2.0, 10.0, 14.0])
    assert len(placement.candidates) == 2
    assert len(assemblies) == 2
    first, second = assemblies
    assert first.members == second.members == 1
    assert {first.candidate.order, second.candidate.order} == {
        ("p0", "p1", "p2"),
        ("p0", "p2", "p1"),
    }
    assert np.allclose(first.polygon, second.polygon)
    unexplored = math.exp(-GEOMETRY.unexplored_energy)
    assert first.probability == pytest.approx(1.0 / (2.0 + unexplored))


def test_different_rooms_at_equal_energy_stay_apart(l_room):
    *_, assemblies = _ranked(l_room, [1.0, 9.5, 14.0, 20.0])
    orders = {a.candidate.order for a in assemblies[:2]}
    assert orders == {("p0", "p1", "p2", "p3"), ("p0", "p2", "p1", "p3")}
    assert all(a.members == 1 for a in assemblies)
    assert assemblies[0].probability == pytest.approx(assemblies[1].probability)
    assert assemblies[0].probability < 0.5


def test_same_room_share_decides_what_is_one_room(l_room):
    # So wide a share makes one answer of every placement that turns each fragment alike.
    params = GEOMETRY.model_copy(update={"same_room_share": 10.0})
    _, placement, assemblies = _ranked(l_room, [1.0, 9.5, 14.0, 20.0], params)
    turns = {frozenset(zip(c.order, c.rotations, strict=True)) for c in placement.candidates}
    assert len(assemblies) == len(turns) < len(placement.candidates)
    assert sum(a.members for a in assemblies) == len(placement.candidates)


def test_assembly_geometry_is_the_candidate_room(l_room):
    pieces, _, assemblies = _ranked(l_room, [1.0, 9.5, 12.5, 20.0])
    best = assemblies[0]
    assert best.translations == pytest.approx(translations_of(pieces, best.candidate))
    assert signed_area(best.polygon) == pytest.approx(39.0)  # the L room, counter-clockwise
    assert len(best.polygon) == 6


def _none_share(assemblies) -> float:
    return 1.0 - sum(a.probability for a in assemblies)


def _l_room_placed(l_room) -> tuple[list[Piece], Placement, float]:
    """The L room cut in four, its placement and its candidates' summed Boltzmann weights."""
    pieces = chains_from_polygon(l_room, [1.0, 9.5, 12.5, 20.0], [0, 1, 2, 3])
    placement = place_pieces(pieces, GEOMETRY)
    assert placement is not None
    lowest = placement.best.energy
    return pieces, placement, sum(math.exp(-(c.energy - lowest)) for c in placement.candidates)


def test_none_of_these_share_follows_its_energy(l_room):
    pieces, placement, weights = _l_room_placed(l_room)
    shares = []
    for per_piece in (-0.5, -0.25, 0.0, 0.25):
        params = GEOMETRY.model_copy(update={"unexplored_per_piece": per_piece})
        share = _none_share(rank_assemblies(pieces, placement, params))
        unexplored = math.exp(-(params.unexplored_energy + per_piece * len(pieces)))
        assert share == pytest.approx(unexplored / (weights + unexplored))
        shares.append(share)
    # 'none of these' is an energy: the more it costs per piece, the smaller its share.
    assert shares == sorted(shares, reverse=True) and len(set(shares)) == len(shares)


def test_a_wide_prior_leaves_its_piece_to_the_search(l_room):
    # The 'none of these' share counts the pieces the search placed: a prior as wide as
    # placed_prior_sigma leaves its piece as free as none does; a narrow one mostly places it.
    pieces, placement, weights = _l_room_placed(l_room)
    params = GEOMETRY.model_copy(update={"unexplored_per_piece": -0.5})

    def none_share(sigmas: dict[str, float]) -> float:
        return _none_share(rank_assemblies(pieces, placement, params, sigmas))

    def expected(free: float) -> float:
        unexplored = math.exp(-(params.unexplored_energy - 0.5 * free))
        return unexplored / (weights + unexplored)

    wide = {p.id: params.placed_prior_sigma for p in pieces}
    assert none_share(wide) == pytest.approx(none_share({})) == pytest.approx(expected(4))
    narrow = {p.id: 0.2 * params.placed_prior_sigma for p in pieces[:3]}
    assert none_share(narrow) == pytest.approx(expected(3 * 0.2 + 1))
    assert none_share(narrow) < none_share(wide)


def test_a_placement_without_complete_candidates_has_no_assemblies():
    # An open chain that leaves a piece out is no room.
    pieces = chains_from_polygon(SQUARE, [1.0, 5.0, 9.0], [0, 0, 0])
    open_chain = PlacementCandidate(100.0, ("p0", "p1"), (0, 0), {}, missing=1)
    placement = Placement(open_chain, np.zeros((2, 2)), (), 1, True, False)
    assert rank_assemblies(pieces, placement, GEOMETRY) == []


def _main_logit(pieces, placement, params, frames: int) -> float:
    """Logit of the main room's probability when the first ``frames`` pieces are frames."""
    mixed = [
        dataclasses.replace(p, evidence="frame" if k < frames else "cloud")
        for k, p in enumerate(pieces)
    ]
    probability = rank_assemblies(mixed, placement, params)[0].probability
    return math.log(probability / (1.0 - probability))


def test_frames_map_the_main_logit_in_their_share_of_the_pieces(l_room):
    pieces, placement, _ = _ranked(l_room, [1.0, 9.5, 12.5, 20.0])
    params = GEOMETRY.model_copy(update={"frame_calibration": (-1.0, 0.5)})
    clouds = _main_logit(pieces, placement, params, 0)
    assert _main_logit(pieces, placement, params, 4) == pytest.approx(-1.0 + 0.5 * clouds)
    half = clouds + 0.5 * (-1.0 + (0.5 - 1.0) * clouds)
    assert _main_logit(pieces, placement, params, 2) == pytest.approx(half)
    identity = GEOMETRY.model_copy(update={"frame_calibration": (0.0, 1.0)})
    assert _main_logit(pieces, placement, identity, 4) == pytest.approx(clouds)


def test_frames_of_a_wider_view_shift_the_logit_by_the_view_slope(l_room):
    pieces, placement, _ = _ranked(l_room, [1.0, 9.5, 12.5, 20.0])
    params = GEOMETRY.model_copy(
        update={"frame_calibration": (-1.0, 0.5), "frame_view_slope": -1.5}
    )
    kinect = _main_logit(pieces, placement, params, 2)
    views = [KINECT_VIEW + 0.4, KINECT_VIEW + 0.8, None, None]
    wide = [dataclasses.replace(p, view_angle=v) for p, v in zip(pieces, views, strict=True)]
    # Half the pieces are frames, their mean view 0.6 rad wider than the kinect's.
    assert _main_logit(wide, placement, params, 2) == pytest.approx(kinect + 0.5 * -1.5 * 0.6)
    # Views wider than any the slope was fitted on (merged frames, a panorama) count as the
    # widest fitted (119 degrees), not extrapolated.
    panorama = [dataclasses.replace(p, view_angle=2 * math.pi) for p in pieces]
    widest = [dataclasses.replace(p, view_angle=2.08) for p in pieces]
    assert _main_logit(panorama, placement, params, 2) == pytest.approx(
        _main_logit(widest, placement, params, 2)
    )
    assert _main_logit(widest, placement, params, 2) < _main_logit(wide, placement, params, 2)
    # A frame whose view is unknown (stored before it was kept) is taken as the kinect's.
    unknown = [dataclasses.replace(p, view_angle=None) for p in pieces]
    assert _main_logit(unknown, placement, params, 2) == pytest.approx(kinect)


def test_frames_seeing_less_wall_height_than_fitted_shift_the_logit_by_the_top_slope(l_room):
    pieces, placement, _ = _ranked(l_room, [1.0, 9.5, 12.5, 20.0])
    params = GEOMETRY.model_copy(
        update={"frame_calibration": (-1.0, 0.5), "frame_view_top_slope": -4.0}
    )
    level = _main_logit(pieces, placement, params, 2)

    def topped(degrees: list[float | None]) -> list[Piece]:
        tops = [None if d is None else math.radians(d) for d in degrees]
        return [dataclasses.replace(p, view_top=t) for p, t in zip(pieces, tops, strict=True)]

    # Views reaching 4 degrees above level or higher are what the map was fitted on.
    assert _main_logit(topped([4.0, 30.0, None, None]), placement, params, 2) == level
    # Two frames' views topping out 16 degrees below level and 30 above: 10 degrees below
    # the fitted on average.
    steep = _main_logit(topped([-16.0, 30.0, None, None]), placement, params, 2)
    assert steep == pytest.approx(level + 0.5 * -4.0 * math.radians(10.0))


def test_a_doubted_room_makes_its_runners_up_no_likelier_than_itself(l_room):
    pieces, placement, clouds = _ranked(l_room, [1.0, 9.5, 12.5, 20.0])
    frames = [dataclasses.replace(p, evidence="frame") for p in pieces]
    mapped = rank_assemblies(frames, placement, GEOMETRY)
    assert mapped[0].probability < clouds[0].probability  # the default map: frames doubt more
    assert [a.candidate for a in mapped] == [a.candidate for a in clouds]
    # The rooms keep the ratios of their shares: what the calibration takes from the main
    # room goes to 'none of these' (a wrong chain), not to a room the energy ranks lower.
    for room, cloud in zip(mapped[1:], clouds[1:], strict=True):
        ratio = room.probability / mapped[0].probability
        assert ratio == pytest.approx(cloud.probability / clouds[0].probability)
        assert room.probability < cloud.probability
    assert sum(a.probability for a in mapped) < 1.0


def test_a_trusted_room_leaves_its_runners_up_what_it_does_not_claim(l_room):
    pieces, placement, shares = _ranked(l_room, [1.0, 9.5, 12.5, 20.0])
    sure = GEOMETRY.model_copy(update={"frame_calibration": (3.0, 1.0)})
    frames = [dataclasses.replace(p, evidence="frame") for p in pieces]
    mapped = rank_assemblies(frames, placement, sure)
    assert mapped[0].probability > shares[0].probability
    rest = 1.0 - shares[0].probability
    for room, share in zip(mapped[1:], shares[1:], strict=True):
        left = share.probability * (1.0 - mapped[0].probability) / rest
        assert room.probability == pytest.approx(left)
        assert room.probability <= mapped[0].probability


def test_each_kind_of_evidence_has_its_own_map(l_room):
    pieces, placement, _ = _ranked(l_room, [1.0, 9.5, 12.5, 20.0])
    params = GEOMETRY.model_copy(
        update={"frame_calibration": (-1.0, 0.5), "thin_cloud_calibration": (-2.0, 1.0)}
    )
    clouds = _main_logit(pieces, placement, params, 0)
    kinds = ["frame", "thin_cloud", "cloud", "cloud"]
    mixed = [dataclasses.replace(p, evidence=kind) for p, kind in zip(pieces, kinds, strict=True)]
    probability = rank_assemblies(mixed, placement, params)[0].probability
    expected = clouds + 0.25 * (-1.0 - 0.5 * clouds) + 0.25 * (-2.0)
    assert math.log(probability / (1.0 - probability)) == pytest.approx(expected)


def _halves(scale: float, params=GEOMETRY) -> tuple[list[Piece], Placement]:
    """A 6 x 4 room times ``scale`` in two halves cut mid-bottom and mid-top, placed."""
    room = np.array([[0, 0], [6, 0], [6, 4], [0, 4]], dtype=np.float64) * scale
    pieces = chains_from_polygon(room, [3.0 * scale, 16.0 * scale], [0, 0])
    placement = place_pieces(pieces, params)
    assert placement is not None and placement.closed
    return pieces, placement


def test_a_room_its_pieces_may_slide_in_is_doubted_more_the_smaller_it_is():
    # Two halves cut mid-wall on opposite walls may slide along them by the overlap model's
    # spread; how much that matters depends on the error the room's size allows.
    def slack(scale: float) -> float:
        pieces, placement = _halves(scale)
        best = placement.best
        (polygon,) = same_room_groups(pieces, [best], GEOMETRY.same_room_share)[2]
        return room_slack(pieces, best, polygon, placement.measured, GEOMETRY)

    small, large = slack(0.5), slack(2.0)
    # The halves slide about 0.15 m: nearly all the 0.18 m that 5 % of a 3.6 m diagonal allows.
    assert small > 0.8
    assert large == pytest.approx(small / 4.0, rel=0.02)


def test_a_loose_room_is_never_surer_than_the_loose_rooms_cap():
    # The small halves may slide by about the error the 5 % test allows: however alone
    # the assembly, its confidence is capped; four times larger, the same slide is not,
    # and without the cap the small room is surer too.
    cap = GEOMETRY.loose_room_confidence
    small = rank_assemblies(*_halves(0.5), GEOMETRY)
    assert len(small) == 1 and small[0].probability == pytest.approx(cap)
    assert rank_assemblies(*_halves(2.0), GEOMETRY)[0].probability > cap
    free = GEOMETRY.model_copy(update={"loose_room_slack": 100.0})
    assert rank_assemblies(*_halves(0.5, free), free)[0].probability > cap


def test_priors_that_pin_a_loose_rooms_pieces_lift_its_cap():
    # The fleet's prior poses fix what the junctions leave loose: 5 cm priors on both small
    # halves make their room's size no guess; one prior alone says only where the room is.
    cap = GEOMETRY.loose_room_confidence
    pieces, placement = _halves(0.5)
    ids = [p.id for p in pieces]
    both = rank_assemblies(pieces, placement, GEOMETRY, dict.fromkeys(ids, 0.05))
    assert both[0].probability > cap
    one = rank_assemblies(pieces, placement, GEOMETRY, {ids[1]: 0.05})
    assert one[0].probability == pytest.approx(cap)


def test_frames_whose_cameras_scatter_over_more_stations_than_fitted_lower_the_logit(l_room):
    pieces, placement, _ = _ranked(l_room, [1.0, 9.5, 12.5, 20.0])
    params = GEOMETRY.model_copy(
        update={"frame_calibration": (-1.0, 0.5), "frame_station_slope": -2.0}
    )
    plain = _main_logit(pieces, placement, params, 2)
    # Each frame's camera at its own source: the four sources lie metres apart, so the
    # main room's cameras stand at four stations, two more than the map was fitted on.
    at_sources = [dataclasses.replace(p, cameras=np.zeros((1, 2))) for p in pieces]
    scattered = _main_logit(at_sources, placement, params, 2)
    assert scattered == pytest.approx(plain + 0.5 * -2.0 * (4 - FITTED_STATIONS))
    # Two stations (the first two pieces' cameras only) are what the map was fitted on.
    two = [
        dataclasses.replace(p, cameras=np.zeros((1, 2))) if k < 2 else p
        for k, p in enumerate(pieces)
    ]
    assert _main_logit(two, placement, params, 2) == pytest.approx(plain)
    # A station reach of 0 turns stations off: no camera is anyone's station mate.
    no_stations = params.model_copy(update={"station_reach": 0.0})
    assert _main_logit(at_sources, placement, no_stations, 2) == pytest.approx(
        _main_logit(pieces, placement, no_stations, 2)
    )
