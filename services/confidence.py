"""How sure the placement is: the assemblies found, as distinct rooms with probabilities.

The search returns its best few assemblies with energies (negative log-likelihoods up to a
constant; the weights are fitted, ``bench/tune_placement.py``). Assemblies whose floorplans
are the same room (mean keypoint distance under a small share of the diagonal: a jog placed
either side of a cut) and that place every fragment alike are one answer, and their
Boltzmann shares add up; swapped look-alike pieces draw the same floorplan but are two
answers, since the fleet acts on each scan's pose. A 'none of these' share stands for
everything the search did not return (a wrong local layout, an assembly beyond the node
budget).

The shares rank the rooms; how far to trust the first one also depends on what they do not
see (how many pieces, how well the loop closes, whether the search finished), so the main
room's probability is a logistic function of its share and of those, fitted on the
benchmark's tune split. Chains resting on less evidence than those clouds had (RGB-D frames:
wrong about one in four against one in thirteen; clouds of under 15 000 points) fail in
ways no placement term sees, so rooms of them get a second, linear map of that logit per
kind, fitted on tune seeds of the frames and the other-scanners benchmarks. A main room
whose refined cameras stand at more stations than the rooms that map was fitted on is
doubted further: a wrong room scatters the frames of one station. The other rooms share
what is left in proportion to their shares, none likelier than the main room.

A room whose pieces the junctions leave free to slide (its length fixed only by the model
of what cuts hide, ``room_slack``) can be the only assembly and still the wrong size: its
confidence is capped at what such rooms scored on the tune split.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from schemas.params import PlacementParams
from services.evaluation import polygon_keypoint_error
from services.layout_model import build_polygon
from services.placement import (
    Piece,
    Placement,
    PlacementCandidate,
    evidence_share,
    translations_of,
)
from services.refinement import translation_spread
from services.stations import refined_cameras, station_count
from services.types import Evidence, FloatArray

__all__ = [
    "CALIBRATION_FEATURES",
    "FITTED_STATIONS",
    "KINECT_VIEW",
    "Assembly",
    "calibration_features",
    "floorplan_diagonal",
    "fragment_confidences",
    "free_pieces",
    "rank_assemblies",
    "room_slack",
    "same_room",
    "same_room_groups",
    "view_beyond_kinect",
    "view_top_below_fitted",
]

# rad: the lowest top of a view the frames' map was fitted on (a kinect, 49 degrees high,
# looking 20 degrees down: 4.6 degrees above level), less the levelling's error
_LOWEST_FITTED_TOP = float(np.radians(4.0))
KINECT_VIEW = 1.094  # rad (63 degrees across): the camera the frames' map was first fitted on
# rad (119 degrees): the widest view the map's slope was fitted on; wider views (merged
# frames, panoramas) are taken as this, not extrapolated.
_WIDEST_FITTED_VIEW = 2.08
CALIBRATION_FEATURES = (
    "bias", "logit share", "pieces", "closure", "conflict", "turns", "truncated",
)  # fmt: skip
# Stations a main room's cameras may stand at before frame_station_slope lowers its
# confidence: the frames' map was fitted on rooms seen from 1-3 stations, and rooms of one or
# two were right as often as it says.
FITTED_STATIONS = 2
_SHARE_CLIP = 1e-4
_RIGHT_SHARE = 0.05  # the paper's test: mean keypoint error under 5 % of the diagonal


@dataclass(frozen=True)
class Assembly:
    """One distinct room the pieces close into.

    candidate: the lowest-energy placement of that room; members: how many placements the
    search found for it; share: its Boltzmann share; probability: calibrated probability
    that this room is the right one.
    translations: (n, 2) site positions of the candidate's sources (unrefined), loop order.
    polygon: (V, 2) its unrefined floorplan, site frame.
    """

    candidate: PlacementCandidate
    members: int
    share: float
    probability: float
    translations: FloatArray
    polygon: FloatArray


def same_room_groups(
    pieces: Sequence[Piece], candidates: Sequence[PlacementCandidate], share: float
) -> tuple[list[int], list[FloatArray], list[FloatArray]]:
    """Group complete candidates by answer, lowest energy first.

    Returns (group index per candidate, the unrefined translations and floorplan of each
    group's first candidate). A candidate joins the first group whose floorplan is within
    ``share`` of the diagonal of its own and that places every fragment alike: the same
    quarter turns, sources within ``share`` of that diagonal (as
    :func:`fragment_confidences` compares them). The same floorplan with fragments placed
    elsewhere in it (a piece on another wall that looks alike) is another map for the fleet.
    """
    by_id = {p.id: p for p in pieces}
    groups: list[int] = []
    translations: list[FloatArray] = []
    polygons: list[FloatArray] = []
    placements: list[dict[str, tuple[int, FloatArray]]] = []
    for cand in candidates:
        moved = translations_of(pieces, cand)
        ordered = [by_id[fid] for fid in cand.order]
        polygon = build_polygon(ordered, cand.rotations, moved, cand.shared)
        placed = _placements(cand, moved)
        match = next(
            (
                g
                for g, p in enumerate(polygons)
                if same_room(polygon, p, share)
                and _placed_alike(placed, placements[g], share * floorplan_diagonal(p))
            ),
            None,
        )
        if match is None:
            match = len(polygons)
            translations.append(moved)
            polygons.append(polygon)
            placements.append(placed)
        groups.append(match)
    return groups, translations, polygons


def _placements(
    cand: PlacementCandidate, translations: FloatArray
) -> dict[str, tuple[int, FloatArray]]:
    """Fragment id -> (quarter turns, source position) of a candidate, search frame."""
    return {
        fid: (rotation, translations[k])
        for k, (fid, rotation) in enumerate(zip(cand.order, cand.rotations, strict=True))
    }


def _placed_alike(
    a: Mapping[str, tuple[int, FloatArray]],
    b: Mapping[str, tuple[int, FloatArray]],
    tolerance: float,
) -> bool:
    """Every fragment of ``a`` in the same place in ``b`` (:func:`_same_place`)."""
    return all(_same_place(pose, b.get(fid), tolerance) for fid, pose in a.items())


def _same_place(
    pose: tuple[int, FloatArray], other: tuple[int, FloatArray] | None, tolerance: float
) -> bool:
    """One fragment's (quarter turns, source) alike in two assemblies: the same turns, the
    sources within ``tolerance`` (m); never when the other does not place it."""
    if other is None or other[0] != pose[0]:
        return False
    return float(np.linalg.norm(other[1] - pose[1])) <= tolerance


def calibration_features(
    share: float, best: PlacementCandidate, pieces: float, truncated: bool
) -> FloatArray:
    """The calibration's inputs (``CALIBRATION_FEATURES``) for a main room."""
    clipped = min(max(share, _SHARE_CLIP), 1.0 - _SHARE_CLIP)
    return np.array(
        [
            1.0,
            math.log(clipped / (1.0 - clipped)),
            pieces,
            best.features.get("closure", 0.0),
            best.features.get("conflict", 0.0),
            best.features.get("turns", 0.0),
            float(truncated),
        ]
    )


def room_slack(
    pieces: Sequence[Piece],
    candidate: PlacementCandidate,
    polygon: FloatArray,
    measured: Mapping[tuple[str, str], float],
    params: PlacementParams,
    prior_sigmas: Mapping[str, float] | None = None,
) -> float:
    """How freely the room's pieces may still slide (``translation_spread``; with the
    hinted pieces' prior sigmas by id), in units of the error the paper's test allows a
    floorplan of that size (5 % of its diagonal). Near 1 or above, the room's size is a
    guess however clear the assembly is."""
    by_id = {p.id: p for p in pieces}
    ordered = [by_id[fid] for fid in candidate.order]
    spread = translation_spread(
        ordered, candidate.rotations, params, measured, prior_sigmas, candidate.shared
    )
    return spread / max(_RIGHT_SHARE * floorplan_diagonal(polygon), 1e-6)


def rank_assemblies(
    pieces: Sequence[Piece],
    placement: Placement,
    params: PlacementParams,
    prior_sigmas: Mapping[str, float] | None = None,
) -> list[Assembly]:
    """The distinct closed assemblies of a placement, most probable first.

    Parameters
    ----------
    pieces : the pieces the placement was searched over.
    placement : a closed placement (its candidates place every piece).
    params : same-room share, 'none of these' energy, calibration coefficients, and the
        maps of the logit for frames and thin clouds (each in the share of pieces of its
        kind).
    prior_sigmas : the standard deviation (m) of each piece's prior position, by id, for
        the pieces whose place a prior pose tells. The 'none of these' share and the
        calibration grow with the pieces the search had to place itself (fitted without
        hints); a piece the fleet already placed is not one of those, and one whose prior
        is wide (``placed_prior_sigma``) only in part (:func:`free_pieces`). Two priors or more
        also pin the pieces' positions that the junctions leave loose (``room_slack``).

    Returns
    -------
    Assemblies whose probabilities sum to at most 1 (the rest is 'none of these').
    """
    complete = sorted((c for c in placement.candidates if c.missing == 0), key=lambda c: c.energy)
    if not complete:
        return []
    groups, translations, polygons = same_room_groups(pieces, complete, params.same_room_share)
    lowest = complete[0].energy
    weights = np.zeros(len(polygons))
    for cand, group in zip(complete, groups, strict=True):
        weights[group] += math.exp(-(cand.energy - lowest))
    sigmas = prior_sigmas or {}
    free = free_pieces([p.id for p in pieces], sigmas, params.placed_prior_sigma)
    unexplored = params.unexplored_energy + params.unexplored_per_piece * free
    shares = weights / (weights.sum() + math.exp(-unexplored))
    firsts = [complete[groups.index(g)] for g in range(len(polygons))]
    members = np.bincount(groups, minlength=len(polygons))
    order = sorted(range(len(polygons)), key=lambda g: (-shares[g], firsts[g].energy))
    main = order[0]
    inputs = calibration_features(float(shares[main]), firsts[main], free, not placement.exhaustive)
    z = float(np.asarray(params.confidence_coefficients) @ inputs)
    z += _evidence_shift(pieces, z, params, _stations(pieces, firsts[main], placement, params))
    confidence = 1.0 / (1.0 + math.exp(-z))
    # A room whose size the junctions leave loose is a guess the calibration does not see.
    slack = room_slack(pieces, firsts[main], polygons[main], placement.measured, params, sigmas)
    if slack >= params.loose_room_slack:
        confidence = min(confidence, params.loose_room_confidence)
    return [
        Assembly(
            firsts[g],
            int(members[g]),
            float(shares[g]),
            confidence if g == main else _runner_up(shares, main, g, confidence),
            translations[g],
            polygons[g],
        )
        for g in order
    ]


def free_pieces(
    ids: Sequence[str], prior_sigmas: Mapping[str, float], placed_sigma: float
) -> float:
    """How many pieces the search placed itself, for the calibration (at least 1): a piece
    without a prior counts 1, one with a prior of position sigma s counts s / placed_sigma
    (at most 1). A prior of a few decimeters pins its piece among the room's look-alike
    walls; one as wide as a wall is long leaves the search to choose between them.

    >>> round(free_pieces(["a", "b", "c", "d"], {"a": 0.3, "b": 3.0}, 1.5), 6)
    3.2
    >>> free_pieces(["a"], {"a": 0.1}, 1.5)  # the calibration never saw fewer than one
    1.0
    """
    counts = [min(1.0, prior_sigmas[i] / placed_sigma) if i in prior_sigmas else 1.0 for i in ids]
    return max(1.0, sum(counts))


def _runner_up(shares: FloatArray, main: int, g: int, confidence: float) -> float:
    """Probability of room g besides the main one: its share of what the main room leaves,
    and never more than the main room's own probability times their shares' ratio. Where
    the calibration doubts the main room more than its share says, the runners-up are no
    surer for it: a room with a smaller share reported as likelier than the main one would
    contradict the ranking (the rest is 'none of these')."""
    rest = max(1.0 - float(shares[main]), 1e-12)
    left = float(shares[g]) * (1.0 - confidence) / rest
    return min(left, confidence * float(shares[g]) / max(float(shares[main]), 1e-12))


def _stations(
    pieces: Sequence[Piece], main: PlacementCandidate, placement: Placement, params: PlacementParams
) -> int:
    """How many stations the main room's refined cameras stand at; 0 without cameras, or
    when ``station_reach`` (0: no stations) or ``frame_station_slope`` turns it off."""
    off = params.station_reach == 0.0 or params.frame_station_slope == 0.0
    if off or not any(len(p.cameras) for p in pieces):
        return 0
    cameras = refined_cameras(main, pieces, placement.measured, params)
    return station_count(cameras, params.station_reach)


def _evidence_shift(
    pieces: Sequence[Piece], z: float, params: PlacementParams, stations: int = 0
) -> float:
    """The change of the main room's logit ``z`` for pieces resting on less than the
    calibration's clouds: each kind's map a + b z, in the share of the pieces of that kind.
    With a slope under 1 a map also lifts the lowest confidences a little (below a / (1 - b):
    about 0.11 for frames, 0.03 for thin clouds), as the fit found them. Frames' rooms also
    move by ``frame_view_slope`` per radian their cameras see across beyond the kinect's,
    by ``frame_view_top_slope`` per radian their views' tops lie below the fitted, and by
    ``frame_station_slope`` per station of the main room's cameras beyond
    ``FITTED_STATIONS``."""
    maps: dict[Evidence, tuple[float, float]] = {
        "frame": params.frame_calibration,
        "thin_cloud": params.thin_cloud_calibration,
    }
    shift = 0.0
    for kind, (bias, slope) in maps.items():
        shift += evidence_share(pieces, kind) * (bias + (slope - 1.0) * z)
    frames = [p for p in pieces if p.evidence == "frame"]
    share = evidence_share(pieces, "frame")
    wider = view_beyond_kinect([p.view_angle for p in frames if p.view_angle is not None])
    below = view_top_below_fitted([p.view_top for p in frames if p.view_top is not None])
    shift += share * params.frame_view_slope * wider
    shift += share * params.frame_station_slope * max(0, stations - FITTED_STATIONS)
    return shift + share * params.frame_view_top_slope * below


def view_top_below_fitted(tops: Sequence[float]) -> float:
    """What ``frame_view_top_slope`` weighs: how far the top of the frames' views lies below
    the lowest the frames' calibration was fitted on (radians), averaged over the frames
    (one frame's wrong chain spoils the room); 0 when none is known.

    >>> round(view_top_below_fitted([np.radians(-16.0), np.radians(30.0)]), 4)
    0.1745
    """
    if not tops:
        return 0.0
    return float(np.mean(np.maximum(0.0, _LOWEST_FITTED_TOP - np.asarray(tops))))


def view_beyond_kinect(views: Sequence[float]) -> float:
    """What the frames' map weighs by ``frame_view_slope``: the frames' mean view angle
    (radians) beyond the kinect's, the widest fitted at most; 0 when none is known (a frame
    stored before its view was kept is taken as the kinect's)."""
    if not views:
        return 0.0
    return min(float(np.mean(views)), _WIDEST_FITTED_VIEW) - KINECT_VIEW


def fragment_confidences(
    main: Assembly, assemblies: Sequence[Assembly], share: float
) -> dict[str, float]:
    """Per fragment of ``main``: the probability that its pose is right.

    A robot can act on its own pose when every likely room places it alike, even if the
    rooms differ elsewhere: the fragment's probability sums those of the assemblies that
    give it the main's rotation and a source within ``share`` of the main floorplan's
    diagonal. Poses are compared in the search's frame, where the first fragment is fixed
    in every assembly (so its own confidence is the mass of all the rooms found).
    """
    tolerance = share * floorplan_diagonal(main.polygon)
    reference = _placements(main.candidate, main.translations)
    out = dict.fromkeys(reference, 0.0)
    for assembly in assemblies:
        poses = _placements(assembly.candidate, assembly.translations)
        for fid, pose in reference.items():
            if _same_place(pose, poses.get(fid), tolerance):
                out[fid] += assembly.probability
    return {fid: min(1.0, value) for fid, value in out.items()}


def same_room(a: FloatArray, b: FloatArray, share: float) -> bool:
    """True when two floorplans (same frame) are one room within ``share`` of the diagonal."""
    if len(a) < 3 or len(b) < 3:
        return False
    return polygon_keypoint_error(a, b) < share * floorplan_diagonal(np.vstack([a, b]))


def floorplan_diagonal(polygon: FloatArray) -> float:
    """Length of the diagonal of a floorplan's (V, 2) bounding box, m (0 when empty)."""
    if not len(polygon):
        return 0.0
    return float(np.linalg.norm(polygon.max(axis=0) - polygon.min(axis=0)))
