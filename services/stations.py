"""Frames taken from one station: the kept assemblies scored by where their cameras stand.

Frames of a robot turning on the spot, or of a tripod, share their camera. In the right
assembly their cameras, once the loop is refined (which already makes the cameras of one
station coincide, :mod:`services.refinement`), stand together; in a rival that turns a
frame a quarter or swaps two of them, the cameras scatter. Each kept assembly of a site of
RGB-D frames is refined and gets an energy term of its own, the ``stations`` feature: per
camera, the squared distance to the nearest camera of another piece (at most the station
reach: cameras farther apart are other stations, and cost no more) over twice
``station_spread`` squared, plus ``station_occam`` per station beyond the first, weighted by
``station_weight``. The second part is an Occam factor: a rival that turns a frame or two
by a half turn can still give each camera a partner nearby, pairing them off at two
stations where the truth has one, and each station more is one more position the room
could have put anywhere. A third part prices the views' own word: two frames whose view
ranges agree at one quarter turn (``Piece.station_mates``) are made to share their camera
by the refinement only when the assembly turns them so; one that turns them otherwise
pays ``station_mate_cost`` per such pair (:func:`broken_mates`), since of the pairs passing
that test most share the truth's camera and turn. The search does not see the term (it is
known only once a loop is refined), so it ranks the assemblies the search kept, as the
floor seen outside them does. Clouds have no cameras: their placement is returned as it
is.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np
from scipy.sparse.csgraph import connected_components

from schemas.params import PlacementParams
from services.placement import Piece, Placement, PlacementCandidate, translations_of
from services.placement.priors import SiteHints
from services.refinement import (
    placed_cameras,
    prior_anchors,
    refine_translations,
    turned_as_views_say,
)
from services.types import FloatArray

__all__ = [
    "broken_mates",
    "counts_stations",
    "refined_cameras",
    "station_cost",
    "station_count",
    "station_term",
    "with_station_cost",
    "with_station_scored",
]


def station_cost(cameras: Sequence[FloatArray], reach: float, spread: float) -> float:
    """The ``stations`` feature of one placed assembly.

    cameras: per piece, (C, 2) its cameras' positions in the site frame (C may be 0).
    Each camera costs its distance to the nearest camera of another piece, capped at
    ``reach``, squared over ``2 spread^2``; 0 with fewer than two pieces with cameras.

    >>> station_cost([np.zeros((1, 2)), np.array([[0.3, 0.0]])], 0.6, 0.3)
    1.0
    >>> station_cost([np.zeros((1, 2)), np.array([[5.0, 0.0]])], 0.6, 0.3)
    4.0
    """
    empty = [np.zeros(0, dtype=np.int64)]  # no pieces at all: no owners, cost 0
    owners = np.concatenate([np.full(len(c), k) for k, c in enumerate(cameras)] + empty)
    if len(set(owners.tolist())) < 2:
        return 0.0
    points = np.concatenate([c for c in cameras if len(c)])
    distance = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2)
    distance[owners[:, None] == owners[None, :]] = np.inf  # a piece's own cameras
    nearest = np.minimum(distance.min(axis=1), reach)
    return float(np.sum(nearest**2) / (2.0 * spread**2))


def with_station_cost(
    placement: Placement,
    pieces: Sequence[Piece],
    params: PlacementParams,
    hints: SiteHints | None = None,
) -> Placement:
    """The placement with every kept closed assembly's energy raised by its ``stations``
    term and the assemblies ranked again (the best's translations recomputed); the same
    placement when fewer than two pieces have cameras, the weight is 0 or no loop closed.
    The hints' prior poses anchor each refinement, as they do the result's.
    """
    if not placement.closed or not counts_stations(pieces, params):
        return placement
    scored = [
        with_station_scored(c, pieces, placement.measured, params, hints)
        for c in placement.candidates
    ]
    ranked = sorted(scored, key=lambda c: c.energy)
    return replace(
        placement,
        best=ranked[0],
        translations=translations_of(pieces, ranked[0]),
        alternatives=tuple(ranked[1:]),
    )


def counts_stations(pieces: Sequence[Piece], params: PlacementParams) -> bool:
    """Whether the ``stations`` term ranks these pieces' assemblies: a non-zero weight and
    at least two pieces with cameras."""
    return params.station_weight != 0.0 and sum(len(p.cameras) > 0 for p in pieces) >= 2


def with_station_scored(
    cand: PlacementCandidate,
    pieces: Sequence[Piece],
    measured: Mapping[tuple[str, str], float] | None,
    params: PlacementParams,
    hints: SiteHints | None = None,
) -> PlacementCandidate:
    """One candidate with its ``stations`` term counted in (open chains as they are).

    measured: the overlaps and gaps the junctions' structure measured
    (``Placement.measured``), which the refinement uses; None: measured here.
    hints: their prior poses anchor the refinement.
    """
    if cand.missing:
        return cand
    cost = station_term(refined_cameras(cand, pieces, measured, params, hints), params)
    cost += params.station_mate_cost * broken_mates(cand, pieces)
    features = {**cand.features, "stations": cost}
    return replace(cand, energy=cand.energy + params.station_weight * cost, features=features)


def broken_mates(cand: PlacementCandidate, pieces: Sequence[Piece]) -> int:
    """How many pairs of the candidate's pieces whose views say they share their camera at
    one quarter turn (``Piece.station_mates``) it turns otherwise."""
    by_id = {p.id: p for p in pieces}
    turns = dict(zip(cand.order, cand.rotations, strict=True))
    return sum(
        1
        for fid in cand.order
        for other, turn in by_id[fid].station_mates
        if fid < other
        and other in turns
        and not turned_as_views_say(turn, turns[fid], turns[other])
    )


def station_term(cameras: Sequence[FloatArray], params: PlacementParams) -> float:
    """The ``stations`` feature of placed cameras (per piece, (C, 2), site frame): each
    camera's :func:`station_cost` and ``station_occam`` per station beyond the first
    (:func:`station_count`).

    >>> one_station = [np.zeros((1, 2)), np.zeros((1, 2))]
    >>> station_term(one_station, PlacementParams(station_occam=2.0))
    0.0
    >>> station_term(one_station + [np.full((1, 2), 3.0)] * 2, PlacementParams(station_occam=2.0))
    2.0
    """
    cost = station_cost(cameras, params.station_reach, params.station_spread)
    stations = station_count(cameras, params.station_reach)
    return cost + params.station_occam * max(0, stations - 1)


def refined_cameras(
    cand: PlacementCandidate,
    pieces: Sequence[Piece],
    measured: Mapping[tuple[str, str], float] | None,
    params: PlacementParams,
    hints: SiteHints | None = None,
) -> list[FloatArray]:
    """Per piece of a complete candidate (loop order), (C, 2) its cameras in the site frame
    once the loop is refined (measured, hints: as :func:`with_station_scored` takes them)."""
    by_id = {p.id: p for p in pieces}
    ordered = [by_id[fid] for fid in cand.order]
    start = translations_of(pieces, cand)
    anchors = prior_anchors(hints, cand, start) if hints is not None else []
    refined = refine_translations(
        ordered, cand.rotations, start, params, measured, anchors, cand.shared
    )
    return placed_cameras(ordered, cand.rotations, refined.translations)


def station_count(cameras: Sequence[FloatArray], reach: float) -> int:
    """How many stations the placed cameras stand at: groups of cameras linked by steps
    shorter than ``reach`` (m); 0 without cameras.

    >>> station_count([np.zeros((1, 2)), np.array([[0.3, 0.0], [4.0, 0.0]])], 0.6)
    2
    """
    points = np.concatenate([np.zeros((0, 2)), *cameras])
    if not len(points):
        return 0
    near = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2) < reach
    return int(connected_components(near, directed=False)[0])
