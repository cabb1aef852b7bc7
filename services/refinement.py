"""Pose refinement: translations that join neighbouring wall chains (paper 3.3).

A quadratic program over one 2D translation per piece (the first stays put) minimises how
unlikely each junction's displacement (the next piece's source less this piece's target)
is, per axis, subject to the paper's junction constraints. The displacement model is the
placement's (:func:`services.placement.energy.junction_displacement`): a straight junction
hides an overlap or gap along its wall, a turning one some unseen wall either side of its
corner, and both carry keypoint noise. Where the two ends' structure registers sharply
(``EndMatch.measured_shift``), the overlap along the wall is measured, not guessed: this is
what fixes a room's length when all its cuts are mid-wall. Unmeasured, a straight junction
is taken to hide the overlap neighbouring scans usually have (``refined_junction_mean``;
the energy's closure term keeps ``junction_mean``). A measurement the solution disagrees
with by far is dropped and the problem solved again. Prior poses from the fleet
(``Anchor``) add a row per hinted piece against its prior position, in a frame of their own
that may shift freely (one prior alone says where the room is, not how it is shaped); a
prior the solution misses by more than three of its standard deviations is dropped the same
way. RGB-D frames taken from one station (a robot turning on the spot) share their camera:
cameras of two pieces that the refined loop puts within ``station_reach`` of each other get a
row that makes them coincide, and the loop is solved again; a pair the solution still leaves
``station_outlier`` apart was two stations after all and is dropped. Where the junctions
leave the pieces free to slide (every junction hiding an unseen stretch), the station is
what fixes the room's size.

* parallel junction: the two walls are collinear (equal offset) and neither overruns the
  other's far end;
* perpendicular junction: neither wall end passes the other wall's line.

Strict inequalities get a small margin. OSQP solves it; its status is checked because an
infeasible or unsolved problem returns a meaningless x.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import osqp
from numpy.typing import NDArray
from scipy import sparse

from schemas.params import PlacementParams
from services.placement import Piece, PlacementCandidate, rot90
from services.placement.corners import corner_offsets, corner_view
from services.placement.energy import JunctionNoise, junction_displacement
from services.placement.evidence import end_voxels, register_ends
from services.placement.pieces import UNIT
from services.placement.priors import SiteHints, priors_in_site_frame
from services.types import FloatArray

__all__ = [
    "Anchor",
    "Refinement",
    "measured_shifts",
    "placed_cameras",
    "prior_anchors",
    "refine_translations",
    "stray_anchors",
    "translation_spread",
    "turned_as_views_say",
    "widest_slide",
]

_MARGIN = 1e-3  # m, turns the paper's strict inequalities into solvable ones
_OFFSET_SLACK = 0.10  # m, largest offset mismatch left between walls joined in parallel
_OFFSET_WEIGHT = 10.0  # weight of that mismatch against the joints' distance
_SHIFT_OUTLIER = 0.25  # m, a measured overlap the solution misses by more is dropped
_ANCHOR_OUTLIER = 3.0  # standard deviations: a prior position missed by more is dropped


@dataclass(frozen=True)
class Anchor:
    """A prior position of one piece's source: (2,) in the site frame (the hints' frame
    brought back by its fitted yaw and shift) and its standard deviation, m."""

    position: FloatArray
    sigma: float


@dataclass(frozen=True)
class Refinement:
    """Refined translations.

    translations: (n, 2) float64, site position of each piece's source, loop order.
    status: "solved", or "fallback: <reason>" when the unrefined placement is kept.
    violation_before, violation_after: the largest junction-constraint violation (m) of the
    unrefined and the refined translations. Gaps along a continuing wall are not violations:
    the two collinear walls simply join; the loop is closed when no constraint is violated.
    strays: per piece (loop order; empty without anchors), whether its prior was dropped as
    one the scans contradict (``stray_anchors``).
    stations: pairs of pieces (loop indices) whose cameras were made to coincide.
    """

    translations: FloatArray
    status: str
    violation_before: float
    violation_after: float
    strays: tuple[bool, ...] = ()
    stations: tuple[tuple[int, int], ...] = ()


@dataclass(frozen=True)
class _Station:
    """Two cameras taken as one station: ``first`` of piece i and ``second`` of piece k,
    (2,) each relative to its piece's source, in the site's orientation."""

    i: int
    first: FloatArray
    k: int
    second: FloatArray

    def apart(self, translations: FloatArray) -> float:
        """How far apart the two cameras stand with the pieces' sources at ``translations``."""
        gap = translations[self.i] + self.first - translations[self.k] - self.second
        return float(np.linalg.norm(gap))


@dataclass(frozen=True)
class _Problem:
    """Least squares J t ~ g (weighted rows) and constraints l <= A t <= u.

    ``ordering`` marks the no-overrun / no-crossing rows, dropped in the relaxed retry.
    With anchors, t ends with the priors' frame offset (2 more unknowns).
    """

    J: FloatArray
    g: FloatArray
    A: FloatArray
    lo: FloatArray
    hi: FloatArray
    ordering: NDArray[np.bool_]


def _refinement_noise(params: PlacementParams) -> JunctionNoise:
    """The placement's junction model with the overlap the refinement expects at a straight
    junction (``refined_junction_mean``) in place of the energy's."""
    return replace(JunctionNoise.from_params(params), straight_mean=params.refined_junction_mean)


def _junction_rows(
    sites: list[FloatArray],
    pieces: Sequence[Piece],
    rotations: Sequence[int],
    noise: JunctionNoise,
    shifts: Sequence[float | None],
    anchors: Sequence[Anchor | None] = (),
    stations: Sequence[_Station] = (),
    station_sigma: float = 1.0,
) -> _Problem:
    """The QP's rows: each joint's displacement against its model (per axis, weighted by
    its spread; ``shifts[i]`` the measured overlap at straight junction i, if any), walls
    joined in parallel made collinear (a heavily weighted term, within a small slack:
    measured walls never close a loop exactly), the paper's no-overrun and no-crossing
    inequalities, with two anchors or more (``anchors[i]`` piece i's, if any) each
    anchored source against its prior position plus the free offset of the priors' frame,
    and each station's two cameras made to coincide (within ``station_sigma``). A junction
    at an open end (:mod:`services.open_ends`) spreads by ``noise.open_sigma`` more on both
    axes, and between parallel walls is not made collinear: a step the view lost may hide
    in it."""
    n = len(pieces)
    anchored = [(k, a) for k, a in enumerate(anchors) if a is not None]
    if len(anchored) < 2:
        anchored = []
    dim = 2 * n + (2 if anchored else 0)
    j_rows: list[FloatArray] = []
    g_vals: list[float] = []
    a_rows: list[FloatArray] = []
    bounds: list[tuple[float, float, bool]] = []
    for i in range(n):
        k = (i + 1) % n
        q, q_prev = sites[i][-1], sites[i][-2]
        p, p_next = sites[k][0], sites[k][1]
        heading_in = (pieces[i].directions[-1] + rotations[i]) % 4
        heading_out = (pieces[k].directions[0] + rotations[k]) % 4
        d_i, d_k = UNIT[heading_in], UNIT[heading_out]
        mean, var = junction_displacement(noise, heading_in, heading_out, shifts[i])
        opened = pieces[i].open_ends[1] + pieces[k].open_ends[0]
        var = var + opened * noise.open_sigma**2

        def diff(vec: FloatArray, i: int = i, k: int = k) -> FloatArray:
            """Row of vec . (t_k - t_i)."""
            row = np.zeros(dim)
            row[2 * k : 2 * k + 2] += vec
            row[2 * i : 2 * i + 2] -= vec
            return row

        for axis, mu, sigma in zip(np.eye(2), mean, np.sqrt(var), strict=True):
            # (p + t_k) - (q + t_i) ~ mu along the axis, in units of its spread.
            j_rows.append(-diff(axis) / sigma)
            g_vals.append(float(axis @ (p - q) - mu) / sigma)
        parallel = bool(np.allclose(d_i, d_k))
        # At an open end parallel walls are left apart: a step the view lost may hide there.
        if parallel and not opened:
            normal = np.array([-d_i[1], d_i[0]])
            target = float(normal @ (q - p))
            j_rows.append(-_OFFSET_WEIGHT * diff(normal))
            g_vals.append(-_OFFSET_WEIGHT * target)
            a_rows.append(diff(normal))  # offsets equal, within the slack
            bounds.append((target - _OFFSET_SLACK, target + _OFFSET_SLACK, False))
            longest = max(np.linalg.norm(q - q_prev), np.linalg.norm(p_next - p))
            a_rows.append(diff(d_i))  # no overrun
            bounds.append((float(longest + _MARGIN - d_i @ (p_next - q_prev)), np.inf, True))
        elif not parallel and abs(d_i @ d_k) < 0.5:
            a_rows.append(diff(d_i))  # q stays before the next wall's line
            bounds.append((float(d_i @ (q - p) + _MARGIN), np.inf, True))
            a_rows.append(diff(d_k))  # p starts past this wall's line
            bounds.append((float(d_k @ (q - p) + _MARGIN), np.inf, True))
    for row, value in [
        *_anchor_rows(sites, anchored, dim),
        *_station_rows(sites, stations, station_sigma, dim),
    ]:
        j_rows.append(row)
        g_vals.append(value)
    gauge = np.zeros((2, dim))
    gauge[0, 0] = gauge[1, 1] = 1.0  # the first piece does not move
    lows = [b[0] for b in bounds] + [0.0, 0.0]
    highs = [b[1] for b in bounds] + [0.0, 0.0]
    return _Problem(
        J=np.array(j_rows),
        g=np.array(g_vals),
        A=np.vstack([np.array(a_rows).reshape(-1, dim), gauge]),
        lo=np.array(lows),
        hi=np.array(highs),
        ordering=np.array([b[2] for b in bounds] + [False, False], dtype=bool),
    )


def _anchor_rows(
    sites: list[FloatArray], anchored: Sequence[tuple[int, Anchor]], dim: int
) -> list[tuple[FloatArray, float]]:
    """Least-squares rows (row, value) of the anchored pieces' sources against their prior
    positions, plus the priors' frame offset (the last two unknowns)."""
    out = []
    for piece, anchor in anchored:
        weight = 1.0 / max(anchor.sigma, 1e-6)
        for c in range(2):
            # (t + x + offset - prior) / sigma along coordinate c, for the piece's source.
            row = np.zeros(dim)
            row[2 * piece + c] = row[dim - 2 + c] = weight
            out.append((row, float(anchor.position[c] - sites[piece][0][c]) * weight))
    return out


def _station_rows(
    sites: list[FloatArray], stations: Sequence[_Station], sigma: float, dim: int
) -> list[tuple[FloatArray, float]]:
    """Least-squares rows (row, value) making each station's two cameras coincide within
    ``sigma``, per coordinate, in the moves of the pieces' sources."""
    out = []
    for station in stations:
        gap = sites[station.i][0] + station.first - sites[station.k][0] - station.second
        for c in range(2):
            row = np.zeros(dim)
            row[2 * station.i + c] = 1.0 / sigma
            row[2 * station.k + c] = -1.0 / sigma
            out.append((row, -float(gap[c]) / sigma))
    return out


def _solve(problem: _Problem, keep: NDArray[np.bool_]) -> tuple[str, FloatArray | None]:
    """OSQP on the rows in ``keep``; the status is checked (an unsolved x is meaningless)."""
    dim = problem.J.shape[1]
    P = sparse.csc_matrix(problem.J.T @ problem.J + 1e-9 * np.eye(dim))
    if not (np.all(np.isfinite(problem.J)) and np.all(np.isfinite(problem.g))):
        return "invalid input (non-finite)", None
    solver = osqp.OSQP()
    solver.setup(
        P,
        -problem.J.T @ problem.g,
        sparse.csc_matrix(problem.A[keep]),
        problem.lo[keep],
        problem.hi[keep],
        verbose=False,
        eps_abs=1e-7,
        eps_rel=1e-7,
        max_iter=20000,
        polishing=True,
    )
    result = solver.solve(raise_error=False)  # an unsolved status is checked below
    status = str(result.info.status)
    if status not in ("solved", "solved inaccurate") or result.x is None:
        return status, None
    return status, np.asarray(result.x, dtype=np.float64)


def measured_shifts(
    pieces: Sequence[Piece],
    rotations: Sequence[int],
    measured: Mapping[tuple[str, str], float] | None = None,
) -> list[float | None]:
    """The overlap (negative) or gap along the wall at each straight junction of the loop
    (piece i to piece i + 1, the last to the first) where the two ends' structure pins it
    down; None elsewhere. ``measured``: the placement's measurements by ordered pair of ids
    (``Placement.measured``); without it the ends are registered here."""
    n = len(pieces)
    out: list[float | None] = []
    for i in range(n):
        a, b = pieces[i], pieces[(i + 1) % n]
        straight = (a.directions[-1] + rotations[i]) % 4 == (
            b.directions[0] + rotations[(i + 1) % n]
        ) % 4
        if not straight:
            out.append(None)
        elif measured is not None:
            out.append(measured.get((a.id, b.id)))
        else:
            match = register_ends(end_voxels(a, "target"), end_voxels(b, "source"))
            out.append(match.measured_shift)
    return out


def _measured_by_pair(
    pieces: Sequence[Piece], rotations: Sequence[int]
) -> dict[tuple[str, str], float]:
    """:func:`measured_shifts` registered here, by ordered pair of ids."""
    n = len(pieces)
    shifts = measured_shifts(pieces, rotations)
    return {
        (pieces[i].id, pieces[(i + 1) % n].id): shift
        for i, shift in enumerate(shifts)
        if shift is not None
    }


def refine_translations(
    pieces: Sequence[Piece],
    rotations: Sequence[int],
    translations: FloatArray,
    params: PlacementParams = PlacementParams(),
    measured: Mapping[tuple[str, str], float] | None = None,
    anchors: Sequence[Anchor | None] = (),
    shared: Sequence[int] = (),
) -> Refinement:
    """Refine the placement's translations with the constrained QP.

    When the paper's inequalities cannot all hold (measured wall lengths that do not fit
    the loop), the QP is solved again without them and the status says "relaxed"; when
    that fails too, the unrefined placement is kept and the status says "fallback".

    Parameters
    ----------
    pieces : pieces in loop order.
    rotations : quarter turns per piece, loop order.
    translations : (n, 2) site position of each piece's source from the placement.
    params : the junction displacement model.
    measured : the overlaps the placement measured (``Placement.measured``); None: measure.
    anchors : prior positions of the pieces' sources, loop order (None: no prior); used
        where two pieces or more have one.
    shared : per loop position, how many corners the piece shares with the one before
        (``PlacementCandidate.shared``): refined as a straight junction whose overlap is
        the earlier piece's wall after the last of them (:func:`corner_view`).
    """
    if any(shared):
        offsets = corner_offsets(pieces, rotations, shared)
        known = measured if measured is not None else _measured_by_pair(pieces, rotations)
        view, known = corner_view(pieces, shared, known)
        moved = [
            None if a is None else replace(a, position=a.position + offset)
            for a, offset in zip(anchors, offsets, strict=False)
        ]
        refined = refine_translations(view, rotations, translations + offsets, params, known, moved)
        return replace(refined, translations=refined.translations - offsets)
    n = len(pieces)
    if n < 2:
        return Refinement(translations.copy(), "solved", 0.0, 0.0)
    sites = [
        p.keypoints @ rot90(r).T + t
        for p, r, t in zip(pieces, rotations, translations, strict=True)
    ]
    noise = _refinement_noise(params)
    shifts = measured_shifts(pieces, rotations, measured)
    refined = _refine(sites, pieces, rotations, translations, noise, shifts, anchors)
    moves = refined.translations - translations
    missed = _missed_shifts(sites, moves, shifts)
    strays = stray_anchors(refined.translations, anchors)
    kept = [None if miss else shift for shift, miss in zip(shifts, missed, strict=True)]
    trusted = [None if stray else a for a, stray in zip(anchors, strays, strict=True)]

    def solve(stations: Sequence[_Station] = ()) -> Refinement:
        # The measurements and priors the first solve kept, and the stations given.
        return _refine(
            sites, pieces, rotations, translations, noise, kept, trusted,
            stations, params.station_sigma,
        )  # fmt: skip

    if any(missed) or any(strays):
        refined = solve()
    refined = _with_stations(refined, solve, pieces, rotations, params)
    return replace(refined, strays=tuple(strays))


def _with_stations(
    refined: Refinement,
    solve: Callable[[Sequence[_Station]], Refinement],
    pieces: Sequence[Piece],
    rotations: Sequence[int],
    params: PlacementParams,
) -> Refinement:
    """The refinement solved again with the cameras of one station made to coincide: the
    pairs ``refined`` puts within reach and those whose views share a camera
    (:func:`_stations`; no others: taking in pairs a first solve brings together chained
    distinct stations of one room into one), less any
    the solution still leaves apart, as long as it solves as the loop did without;
    ``refined`` itself when none is left."""
    if refined.status.startswith("fallback"):
        return refined  # nothing was refined: no camera was made to coincide
    stations = _stations(pieces, rotations, refined.translations, params.station_reach)
    while stations:
        solved = solve(stations)
        if solved.status != refined.status:
            return refined  # the solver fared otherwise with the station rows: keep the loop's
        kept = [s for s in stations if s.apart(solved.translations) <= params.station_outlier]
        if len(kept) == len(stations):
            return replace(solved, stations=tuple((s.i, s.k) for s in stations))
        stations = kept
    return refined


def turned_as_views_say(turn: int | None, rotation: int, other_rotation: int) -> bool:
    """Whether an assembly that turns a piece by ``rotation`` and another by
    ``other_rotation`` quarter turns turns them as their views say (``turn``: the other's
    entry in the piece's ``Piece.station_mates``; None: the views say nothing)."""
    return turn is not None and (other_rotation - rotation) % 4 == turn


def _stations(
    pieces: Sequence[Piece], rotations: Sequence[int], translations: FloatArray, reach: float
) -> list[_Station]:
    """Pairs of pieces taken for one station (loop order): those whose nearest cameras
    stand within ``reach`` of each other with the pieces' sources at ``translations``, and
    those whose views say they share their camera (``Piece.station_mates``) when the
    assembly turns them as their views do, however far apart the loop put them."""
    cameras = placed_cameras(pieces, rotations, np.zeros((len(pieces), 2)))
    mates = [dict(piece.station_mates) for piece in pieces]
    out = []
    for i, k in itertools.combinations(range(len(pieces)), 2):
        if not (len(cameras[i]) and len(cameras[k])):
            continue
        if turned_as_views_say(mates[i].get(pieces[k].id), rotations[i], rotations[k]):
            out.append(_Station(i, cameras[i][0], k, cameras[k][0]))  # single frames
            continue
        first = cameras[i] + translations[i]
        second = cameras[k] + translations[k]
        distance = np.linalg.norm(first[:, None, :] - second[None, :, :], axis=2)
        a, b = np.unravel_index(int(np.argmin(distance)), distance.shape)
        if distance[a, b] < reach:
            out.append(_Station(i, cameras[i][a], k, cameras[k][b]))
    return out


def placed_cameras(
    pieces: Sequence[Piece], rotations: Sequence[int], translations: FloatArray
) -> list[FloatArray]:
    """Per piece (loop order), (C, 2) its cameras in the site frame with its source at
    ``translations``."""
    return [
        p.cameras @ rot90(r).T + t for p, r, t in zip(pieces, rotations, translations, strict=True)
    ]


def prior_anchors(
    hints: SiteHints, cand: PlacementCandidate, translations: FloatArray
) -> list[Anchor | None]:
    """The prior position of each piece's source in the site frame (loop order; None
    without a prior), through the hints' frame fitted to the unrefined assembly; none with
    fewer than two priors (one says where the room is, not how it is shaped)."""
    if len(hints.priors) < 2:
        return []
    rotations = dict(zip(cand.order, cand.rotations, strict=True))
    sources = {fid: translations[k] for k, fid in enumerate(cand.order)}
    positions = priors_in_site_frame(hints.priors, rotations, sources)
    return [
        Anchor(positions[fid], hints.priors[fid].source_sigma) if fid in positions else None
        for fid in cand.order
    ]


def translation_spread(
    pieces: Sequence[Piece],
    rotations: Sequence[int],
    params: PlacementParams = PlacementParams(),
    measured: Mapping[tuple[str, str], float] | None = None,
    prior_sigmas: Mapping[str, float] | None = None,
    shared: Sequence[int] = (),
) -> float:
    """How far the junctions (and priors) leave the pieces free to move: the root mean
    square, over the pieces in loop order (the first fixed), of the standard deviation of
    each one's position under the QP's rows (m; inequalities left out).

    Where every junction hides an unseen stretch and none is measured, the loop's closure
    may fix only the sum of those stretches: the pieces can slide along a wall, and the
    room's length is then a guess of the model's (two pieces cut mid-wall on opposite
    walls, or meeting at hidden corners). A result resting on such a guess is no surer of
    its floorplan than this spread allows, however few rival assemblies there are.

    ``prior_sigmas``: the standard deviation (m) of each hinted piece's prior position by
    id. Two priors or more pin the pieces relative to each other (the hints' frame itself
    is free), whatever the junctions leave loose. ``shared``: see :func:`refine_translations`.
    """
    n = len(pieces)
    if n < 2:
        return 0.0
    covariance = _covariance(pieces, rotations, params, measured, prior_sigmas, shared)
    return float(np.sqrt(np.trace(covariance) / n))


def widest_slide(
    pieces: Sequence[Piece],
    rotations: Sequence[int],
    params: PlacementParams = PlacementParams(),
    measured: Mapping[tuple[str, str], float] | None = None,
    prior_sigmas: Mapping[str, float] | None = None,
    shared: Sequence[int] = (),
) -> FloatArray:
    """(n, 2) the move of every piece (the first stays) one standard deviation along the
    direction the junction model leaves the loosest: how the room most likely differs
    from the refined one when its size is a guess (see :func:`translation_spread`;
    ``shared``: see :func:`refine_translations`)."""
    n = len(pieces)
    if n < 2:
        return np.zeros((n, 2))
    covariance = _covariance(pieces, rotations, params, measured, prior_sigmas, shared)
    values, vectors = np.linalg.eigh(covariance)
    move = vectors[:, -1] * np.sqrt(max(float(values[-1]), 0.0))
    return np.vstack([np.zeros(2), move.reshape(n - 1, 2)])


def _covariance(
    pieces: Sequence[Piece],
    rotations: Sequence[int],
    params: PlacementParams,
    measured: Mapping[tuple[str, str], float] | None,
    prior_sigmas: Mapping[str, float] | None = None,
    shared: Sequence[int] = (),
) -> FloatArray:
    """(2n - 2, 2n - 2) covariance of the pieces' positions after the first under the
    junction model (the QP's least-squares rows; the first piece is the frame) and the
    hinted pieces' prior positions. The priors' frame is an unknown offset of its own, so a
    lone prior pins nothing; its yaw is taken as known (a linearisation: the priors'
    angles are far surer than what they say of a piece's position)."""
    if any(shared):
        known = measured if measured is not None else _measured_by_pair(pieces, rotations)
        pieces, measured = corner_view(pieces, shared, known)
    sites = [p.keypoints @ rot90(r).T for p, r in zip(pieces, rotations, strict=True)]
    shifts = measured_shifts(pieces, rotations, measured)
    sigmas = prior_sigmas or {}
    # Only the rows' weights matter here, not where the priors are.
    anchors = [Anchor(np.zeros(2), sigmas[p.id]) if p.id in sigmas else None for p in pieces]
    noise = _refinement_noise(params)
    problem = _junction_rows(sites, pieces, rotations, noise, shifts, anchors)
    free = problem.J[:, 2:]
    dim = 2 * len(pieces) - 2
    return np.asarray(np.linalg.inv(free.T @ free))[:dim, :dim]


def stray_anchors(translations: FloatArray, anchors: Sequence[Anchor | None]) -> list[bool]:
    """Per piece: a prior position the sources miss by more than ``_ANCHOR_OUTLIER``
    standard deviations, once the priors' frame offset is taken out: a prior the scans
    contradict. The offset is the weighted mean misfit of the priors still trusted, the
    worst one dropped at a time, so one prior far off does not drag the others out."""
    out = [False] * len(anchors)
    trusted = [(k, a) for k, a in enumerate(anchors) if a is not None]
    while len(trusted) >= 2:
        misfit = np.array([a.position - translations[k] for k, a in trusted])
        weights = np.array([1.0 / max(a.sigma, 1e-6) ** 2 for _, a in trusted])
        offset = (weights[:, None] * misfit).sum(axis=0) / weights.sum()
        scaled = np.linalg.norm(misfit - offset, axis=1) / np.array(
            [max(a.sigma, 1e-6) for _, a in trusted]
        )
        worst = int(np.argmax(scaled))
        if scaled[worst] <= _ANCHOR_OUTLIER:
            return out
        out[trusted[worst][0]] = True
        del trusted[worst]
    # A lone prior left is checked against nothing: it pins nothing either.
    return out


def _missed_shifts(
    sites: list[FloatArray], moves: FloatArray, shifts: Sequence[float | None]
) -> list[bool]:
    """Per junction: a measured overlap the refined joint misses by more than the outlier
    distance (the registration locked onto look-alike structure)."""
    n = len(sites)
    out = []
    for i, shift in enumerate(shifts):
        if shift is None:
            out.append(False)
            continue
        q, q_prev = sites[i][-1] + moves[i], sites[i][-2] + moves[i]
        p = sites[(i + 1) % n][0] + moves[(i + 1) % n]
        travel = (q - q_prev) / max(float(np.linalg.norm(q - q_prev)), 1e-9)
        out.append(abs(float(travel @ (p - q)) - shift) > _SHIFT_OUTLIER)
    return out


def _refine(
    sites: list[FloatArray],
    pieces: Sequence[Piece],
    rotations: Sequence[int],
    translations: FloatArray,
    noise: JunctionNoise,
    shifts: Sequence[float | None],
    anchors: Sequence[Anchor | None] = (),
    stations: Sequence[_Station] = (),
    station_sigma: float = 1.0,
) -> Refinement:
    """One solve of the QP (relaxed, or falling back, as :func:`refine_translations` says)."""
    n = len(pieces)
    problem = _junction_rows(
        sites, pieces, rotations, noise, shifts, anchors, stations, station_sigma
    )
    everything = np.ones(len(problem.lo), dtype=bool)
    before = _violation(problem, everything, np.zeros(problem.J.shape[1]))
    status, x = _solve(problem, everything)
    label = "solved"
    if x is None:
        relaxed = ~problem.ordering
        status, x = _solve(problem, relaxed)
        label = "relaxed: junction inequalities dropped"
        if x is None:
            return Refinement(translations.copy(), f"fallback: {status}", before, before)
        after = _violation(problem, relaxed, x)
    else:
        after = _violation(problem, everything, x)
    return Refinement(translations + x[: 2 * n].reshape(n, 2), label, before, after)


def _violation(problem: _Problem, keep: NDArray[np.bool_], x: FloatArray) -> float:
    """Largest amount by which the kept rows of A x leave [lo, hi] (gauge included)."""
    ax = problem.A[keep] @ x
    return float(max(0.0, np.max(problem.lo[keep] - ax), np.max(ax - problem.hi[keep])))
