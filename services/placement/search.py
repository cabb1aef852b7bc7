"""Global placement search: loop order and rotations of the pieces (paper 3.2).

Depth-first branch and bound. The first piece is fixed (rotation 0, source at the origin);
each step appends a piece at the previous one's target (or, between RGB-D frames that both
saw one corner, with its first corner on the previous one's last: a shared corner,
:mod:`services.placement.corners`). What a simple rectilinear counter-clockwise loop implies
cuts the tree: a junction continues the wall or turns by 90 degrees (never folds back), so
a rotation follows from the junction's turn; the turns add up to one full turn; walls may
not cross or overlap (but where a shared corner makes them). A child's lower bound adds what its
junction costs, the cheapest way into every piece still to place, the turns still owed and
the closure gap the remaining pieces cannot make up. Up to 16 pieces the junctions and turns
still to come are bounded by the cheapest tour through the pieces left instead, where that
is more (a table over every subset of pieces, built once per search: the cheapest ways into
each piece may all come from one piece, a tour cannot); in a small site, with two pieces or
fewer left after it, every way to finish the loop is tried instead (exact but for crossing
walls, the hull and free space), so that fewer nodes near the leaves expand nothing. Quick
first passes that expand only the best one, two, three children per node (iterative
broadening) find good loops early, so the full pass prunes tight. Bounds are computed for
many states at once (a beam layer, or a few siblings placed together), since a node's cost
is mostly numpy's per-call overhead.

The search keeps the ``top_k`` best assemblies, and its budget is a number of nodes, never a
time: the same input gives the same answer on any machine. A search that runs out of nodes
is searched again from another first piece (:func:`_restart`) and its best loop is polished
(:func:`_polish`), each within a node budget of its own.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import InitVar, dataclass, field, replace
from functools import cached_property
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from schemas.params import PlacementParams
from services.placement.corners import MOST_SHARED, corner_shift, shared_turn, sharings
from services.placement.energy import (
    FEATURES,
    JunctionNoise,
    closure_nll,
    feature_weights,
    hull_edges,
    junction_displacement,
    outside_area,
)
from services.placement.evidence import boundary_mismatch, end_voxels, register_ends
from services.placement.pieces import (
    SAMPLE_SPACING,
    UNIT,
    Box,
    Piece,
    open_end_count,
    rot90,
    shift_walls,
)
from services.placement.priors import (
    FrameEstimate,
    HintPair,
    SiteHints,
    frame_estimate,
    frame_yaw_fit,
    position_costs,
    position_costs_batch,
    robust_cost,
    wrap_angle,
)
from services.types import FloatArray

__all__ = [
    "Placement",
    "PlacementCandidate",
    "evaluate_placement",
    "loop_frame_yaw",
    "place_pieces",
    "translations_of",
]

_TURNS = (0, 1, -1)  # continue, turn left (convex corner), turn right (concave corner)
_CROSS_EPS = 0.05  # m, walls may touch within this distance but not cross
_UNPLACED_PENALTY = 100.0  # energy per piece left out of an open chain
_SAME_PIECE = 1e6  # a piece never follows itself (unless it is the only one)
# Directions u (max-norm 1) of the closure bound: the gap left is at least u . (-end) less
# what the pieces still to place can reach along u (L1 distance to a convex set, by duality).
_CLOSURE_DIRECTIONS = np.array(
    [d for t in (-1.0, -0.5, 0.0, 0.5) for d in ((1.0, t), (-1.0, -t), (-t, 1.0), (t, -1.0))]
)
_AWAY_FROM_START = -_CLOSURE_DIRECTIONS.T  # an end's distance from the start along each u
_BROADENING = (1, 2, 3)  # children per node in the search's quick first passes
_DFS_GROUP = 8  # children the depth-first search places at once (see _dfs)
_BEAM_SPARE = 32  # children tested beyond what a beam layer still takes (crossing, a key seen)
_LOOKAHEAD = 2  # pieces left after a child when its bound tries every way to finish (<= 2)
_TOUR_PIECES = 16  # up to this many pieces the bounds hold the cheapest tour (2^15 x 16 x 4 table)
_F = {name: k for k, name in enumerate(FEATURES)}
_XYXY = np.array([0, 1, 0, 1])  # a position's columns in the order of a box's
# A junction's turn from the quarter turns between the headings it joins (mod 4); 2 folds
# back, which no loop has.
_TURN_OF = np.array([0, 1, 2, -1])


_PairEvidence = tuple[FloatArray, FloatArray, dict[tuple[str, str], float]]


@dataclass(frozen=True)
class PlacementCandidate:
    """A complete placement, its energy and the features it is the weighted sum of.

    order: piece ids in loop order (the first is the fixed piece); rotations: quarter turns
    per piece, loop order; missing: pieces left out (open chains only); shared: per loop
    position, how many corners that piece shares with the one before
    (:mod:`services.placement.corners`; position 0: at the junction closing the loop), empty
    when none does.
    """

    energy: float
    order: tuple[str, ...]
    rotations: tuple[int, ...]
    features: Mapping[str, float]
    missing: int = 0
    violated_pairs: tuple[HintPair, ...] = ()
    shared: tuple[int, ...] = ()


@dataclass(frozen=True)
class Placement:
    """The best placements found.

    best: the lowest energy; alternatives: the runners-up, lowest energy first.
    translations: (n, 2) float64, site position of each of best's pieces' source, loop order.
    closed: True when the pieces form one simple counter-clockwise loop (turns add up to a
    full turn); the gap left at its end is closed by the refinement.
    exhaustive: the search finished within its node budget (the best is optimal).
    measured: overlap (negative) or gap along the wall, m, of each ordered pair of pieces
    (a's target, b's source, by id) whose ends' structure pins it down; the refinement takes
    it from here instead of registering the ends again.
    frame_yaw: with prior poses, the yaw (radians) of the site frame in the hints frame that
    the candidates' prior terms were scored with (see :func:`place_pieces`); else None.
    """

    best: PlacementCandidate
    translations: FloatArray
    alternatives: tuple[PlacementCandidate, ...]
    nodes_searched: int
    exhaustive: bool
    closed: bool
    measured: Mapping[tuple[str, str], float] = field(default_factory=dict)
    frame_yaw: float | None = None  # the hints frame's yaw the priors were scored in

    @property
    def candidates(self) -> tuple[PlacementCandidate, ...]:
        """Best first, then the alternatives."""
        return (self.best, *self.alternatives)


@dataclass
class _Search:
    """The fixed data of one search and its running results."""

    pieces: list[Piece]
    params: PlacementParams
    hints: SiteHints
    require_closed: bool
    # Structure scores, boundary mismatches and measured overlaps of the ordered pairs (see
    # _pair_evidence): given when another search of the same pieces has them already.
    evidence: InitVar[_PairEvidence | None] = None
    # The hints frame's yaw when an assembly has told it (see place_pieces); None: the
    # priors' own estimate.
    frame_yaw: InitVar[float | None] = None
    weights: FloatArray = field(init=False)
    noise: JunctionNoise = field(init=False)
    structure: FloatArray = field(init=False)  # [a, b]: structure score of b after a
    measured: dict[tuple[str, str], float] = field(init=False)  # see Placement.measured
    boundary: FloatArray = field(init=False)  # [a, b]: boundary mismatch of b after a
    junction: FloatArray = field(init=False)  # [a, b]: weighted cost of the two
    frame: FrameEstimate | None = field(init=False)  # the hints frame's yaw, from priors
    frame_turn: tuple[float, float] = field(init=False)  # cos and sin of the frame's yaw
    rotation_cost: FloatArray = field(init=False)  # [j, r]: prior cost of rotation r
    # [j, r, q]: that cost with the frame turned q more quarter turns (see _State.anchors)
    turned_rotation_cost: FloatArray = field(init=False)
    rotation_floor: FloatArray = field(init=False)  # [j]: least prior cost of j's rotations
    reach: FloatArray = field(init=False)  # [j, d]: piece j's reach along direction d
    # Shared corners (services.placement.corners): [a, b, k] whether b may follow a
    # sharing k corners (k = 0 never); [b, k] that junction's turn, and b's corner k at
    # rotation r ([b, r, k], (2,)); each piece's last wall's length; how much further than
    # ``reach`` a piece may reach when shared junctions cut walls off either end
    # (``reach_far``), its target alone (``back_reach``); how far the loop's start moves
    # at most when its closing junction shares the first piece's corners (``close_reach``);
    # and the most a junction may turn (``turn_reach``: 2 where two corners turning alike
    # may be shared, else 1).
    sharing: NDArray[np.bool_] = field(init=False)
    shares_any: bool = field(init=False)  # whether any junction may share corners
    shared_turn: NDArray[np.intp] = field(init=False)
    corner_at: FloatArray = field(init=False)
    last_len: FloatArray = field(init=False)
    reach_far: FloatArray = field(init=False)
    back_reach: FloatArray = field(init=False)
    close_reach: float = field(init=False)
    turn_reach: int = field(init=False)
    # The least spread a junction adds to one axis beyond its keypoint noise (a straight
    # junction's, or a shared corner's measured one where corners may be shared).
    least_spread: float = field(init=False)
    chain_ends: FloatArray = field(init=False)  # [j, r]: piece j's target at rotation r
    # [j]: piece j's quarter turns along its chain, directions of its first and last walls.
    turning: NDArray[np.intp] = field(init=False)
    first_direction: NDArray[np.intp] = field(init=False)
    last_direction: NDArray[np.intp] = field(init=False)
    # (4, 4, 2, 2) [heading in, heading out]: mean (2,) and variance (2,) of a junction's
    # displacement.
    step: FloatArray = field(init=False)
    # (2,) variance of a shared corner's displacement (its mean is 0): both corners' noise.
    corner_var: FloatArray = field(init=False)
    # Per piece: its prior's source (n, 2), that source's variance (n,), whether it has one.
    prior_source: FloatArray = field(init=False)
    prior_variance: FloatArray = field(init=False)
    has_prior: np.ndarray = field(init=False)
    free_boxes: FloatArray = field(init=False)  # [j, r]: (4,) piece j's free space's box
    # [j, r]: (W, 4) piece j's walls at rotation r (walls_of), rows past its count all NaN
    wall_table: FloatArray = field(init=False)
    wall_count: NDArray[np.intp] = field(init=False)  # [j]: piece j's walls
    top: list[tuple[float, int, PlacementCandidate]] = field(default_factory=list)
    breadth: int | None = None
    lowest: float = np.inf  # energy of the best leaf so far
    truncated: bool = False
    # Children's bounds try every way to finish the loop (small sites, see _children).
    finish_exactly: bool = field(init=False)
    nodes: int = 0
    counter: itertools.count[int] = field(default_factory=itertools.count)

    def __post_init__(self, evidence: _PairEvidence | None, frame_yaw: float | None) -> None:
        n = len(self.pieces)
        self.finish_exactly = self.require_closed and n < self.params.large_site_pieces
        self.weights = feature_weights(self.params, self.pieces)
        self.noise = JunctionNoise.from_params(self.params)
        if evidence is None:
            evidence = _pair_evidence(self.pieces, self.params)
        self.structure, self.boundary, self.measured = evidence
        cost = self.weights[_F["structure"]] * self.structure
        cost = cost + self.weights[_F["boundary"]] * self.boundary
        if n > 1:
            np.fill_diagonal(cost, _SAME_PIECE)
        self.junction = cost
        self.frame = frame_estimate(self.pieces[0].id, self.hints.priors) if self.pieces else None
        if self.frame is not None and frame_yaw is not None:
            self.frame = FrameEstimate(frame_yaw, self.frame.variance)
        yaw = 0.0 if self.frame is None else self.frame.yaw
        self.frame_turn = (math.cos(yaw), math.sin(yaw))
        self.rotation_cost = _rotation_costs(self.pieces, self.hints, self.frame)
        quarters = (np.arange(4)[:, None] + np.arange(4)[None, :]) % 4  # [r, q] -> r + q
        self.turned_rotation_cost = self.rotation_cost[:, quarters]
        self.rotation_floor = self.rotation_cost.min(axis=1)
        self.turning = np.array([p.turning for p in self.pieces], dtype=np.intp)
        self.first_direction = np.array([p.directions[0] for p in self.pieces], dtype=np.intp)
        self.last_direction = np.array([p.directions[-1] for p in self.pieces], dtype=np.intp)
        self.step = np.array(
            [
                [junction_displacement(self.noise, h_in, h_out) for h_out in range(4)]
                for h_in in range(4)
            ]
        )
        self.corner_var = np.full(2, self.noise.keypoint_sigma**2 + self.noise.measured_sigma**2)
        priors = [self.hints.priors.get(p.id) for p in self.pieces]
        self.has_prior = np.array([prior is not None for prior in priors], dtype=bool)
        self.prior_source = np.array(
            [np.zeros(2) if prior is None else prior.source for prior in priors]
        ).reshape(-1, 2)
        self.prior_variance = np.array(
            [1.0 if prior is None else prior.source_sigma**2 for prior in priors]
        )
        ends = [np.stack([rot90(r) @ p.keypoints[-1] for r in range(4)]) for p in self.pieces]
        self.reach = np.array([(_CLOSURE_DIRECTIONS @ e.T).max(axis=1) for e in ends])
        self.reach = self.reach.reshape(n, len(_CLOSURE_DIRECTIONS))
        self._share_corners()
        # Open ends (services.open_ends) each widen their junction's hidden displacement
        # alike on both axes; every assembly joins every end, so the search starts with it.
        self.open_var = open_end_count(self.pieces) * self.noise.open_sigma**2
        self.chain_ends = np.array(
            [[p.rotated[r][0][-1] for r in range(4)] for p in self.pieces]
        ).reshape(-1, 4, 2)
        self.free_boxes = np.array(
            [[p.rotated_free[r].box for r in range(4)] for p in self.pieces]
        ).reshape(-1, 4, 4)
        self.wall_table = _padded([walls for p in self.pieces for _, walls, _ in p.rotated])
        self.wall_table = self.wall_table.reshape(n, 4, *self.wall_table.shape[1:])
        self.wall_count = np.array([len(p.rotated[0][1]) for p in self.pieces], dtype=np.intp)

    def _share_corners(self) -> None:
        """The shared-corner tables (see the fields)."""
        n, most = len(self.pieces), MOST_SHARED + 1
        self.sharing = np.zeros((n, n, most), dtype=bool)
        if self.params.share_corners:
            for (a, pa), (b, pb) in itertools.product(enumerate(self.pieces), repeat=2):
                self.sharing[a, b, list(sharings(pa, pb))] = True
        self.shared_turn = np.zeros((n, most), dtype=np.intp)
        self.corner_at = np.zeros((n, 4, most, 2))
        entered = np.zeros(n)  # the most a piece's source moves when entered at a corner
        for j, piece in enumerate(self.pieces):
            for k in np.flatnonzero(self.sharing[:, j].any(axis=0)).tolist():
                self.shared_turn[j, k] = shared_turn(piece, k)
                self.corner_at[j, :, k] = [pts[k] for pts, _, _ in piece.rotated]
                entered[j] = max(entered[j], float(piece.wall_lengths[:k].sum()))
        self.last_len = np.array([p.wall_lengths[-1] for p in self.pieces]).reshape(n)
        # A direction u of the closure bound has max-norm 1: cutting walls of length L off
        # a chain moves its end by at most L along u.
        self.back_reach = np.where(self.sharing.any(axis=(1, 2)), self.last_len, 0.0)
        self.reach_far = self.reach + (self.back_reach + entered)[:, None]
        self.close_reach = float(entered[0]) if n else 0.0
        turned = np.abs(self.shared_turn)[self.sharing.any(axis=0)]
        self.turn_reach = max(1, int(turned.max(initial=0)))
        self.least_spread = self.noise.straight_sigma**2
        self.shares_any = bool(self.sharing.any())
        if self.shares_any:
            self.least_spread = min(self.least_spread, self.noise.measured_sigma**2)

    def pair_evidence(self, led: Sequence[int]) -> _PairEvidence:
        """The pair evidence of the pieces ``led`` (indices), in that order."""
        pairs = np.ix_(led, led)
        return self.structure[pairs], self.boundary[pairs], self.measured

    @cached_property
    def index(self) -> dict[str, int]:
        return {p.id: k for k, p in enumerate(self.pieces)}

    @cached_property
    def finishing(self) -> _Finishing:
        return _finishing(self)

    @cached_property
    def tour(self) -> FloatArray | None:
        """See :func:`_tour`; None where it would be too large or is not needed."""
        n = len(self.pieces)
        if not self.require_closed or not 3 <= n <= _TOUR_PIECES:
            return None
        return _tour(self)

    @cached_property
    def pairs(self) -> list[tuple[int, int, bool]]:
        """The hints' pair constraints by piece index (those naming absent pieces drop)."""
        ix = self.index
        return [(ix[p.a], ix[p.b], p.directed) for p in self.hints.pairs if {p.a, p.b} <= ix.keys()]

    def out_of_budget(self) -> bool:
        """True once the node budget is spent (the best found so far is then returned)."""
        budget = self.params.max_search_nodes if self.require_closed else self.params.max_open_nodes
        if self.nodes >= budget:
            self.truncated = True
        return self.truncated

    def threshold(self) -> float:
        """Energy a new leaf must beat: that of the k-th best kept, and at most the best's
        plus the energy window (an assembly that much less likely is worth nothing)."""
        window = self.lowest + self.params.energy_window
        if len(self.top) < self.params.top_k:
            return window
        return min(-self.top[0][0], window)

    def record(self, cand: PlacementCandidate) -> None:
        key = (cand.order, cand.rotations, cand.shared)
        if any((c.order, c.rotations, c.shared) == key for _, _, c in self.top):
            return  # found again by a later, wider pass
        self.lowest = min(self.lowest, cand.energy)
        item = (-cand.energy, next(self.counter), cand)
        if len(self.top) < self.params.top_k:
            heapq.heappush(self.top, item)
        elif cand.energy < -self.top[0][0]:
            heapq.heapreplace(self.top, item)
        while len(self.top) > 1 and -self.top[0][0] > self.lowest + self.params.energy_window:
            heapq.heappop(self.top)


def _pair_evidence(pieces: Sequence[Piece], params: PlacementParams) -> _PairEvidence:
    """Structure scores and boundary mismatches of every ordered pair [a, b] (b after a),
    and the overlaps their ends' structure measures."""
    n = len(pieces)
    targets = [end_voxels(p, "target") for p in pieces]
    sources = [end_voxels(p, "source") for p in pieces]
    structure, boundary = np.zeros((n, n)), np.zeros((n, n))
    measured: dict[tuple[str, str], float] = {}
    for a, b in itertools.product(range(n), repeat=2):
        if a != b or n == 1:
            match = register_ends(targets[a], sources[b])
            structure[a, b] = match.score
            boundary[a, b] = boundary_mismatch(pieces[a], pieces[b], params)
            if match.measured_shift is not None:
                measured[pieces[a].id, pieces[b].id] = match.measured_shift
    return structure, boundary, measured


def _rotation_costs(
    pieces: Sequence[Piece], hints: SiteHints, frame: FrameEstimate | None
) -> FloatArray:
    """[j, r]: prior cost of piece j at rotation r in the site frame (the first piece's
    too: which quarter turn the frame has is the assembly's to say, see _State.anchors)."""
    costs = np.zeros((len(pieces), 4))
    if frame is None:
        return costs
    for j, piece in enumerate(pieces):
        prior = hints.priors.get(piece.id)
        if prior is None:
            continue
        variance = prior.sigma_yaw**2 + frame.variance
        for r in range(4):
            residual = wrap_angle(prior.yaw - frame.yaw - r * np.pi / 2)
            costs[j, r] = robust_cost(residual**2 / variance)
    return costs


def _anchor(
    search: _Search,
    j: int,
    source: FloatArray,
    drift_mean: FloatArray,
    drift_var: FloatArray,
) -> tuple[float, float, float, float, float] | None:
    """Piece j's prior against its placed source (site frame), for :func:`position_costs`;
    None without a prior. The row :func:`_anchor_rows` gives for one piece, to the last bit
    (the same operations on floats: one piece at a time, numpy's overhead would dominate)."""
    if search.frame is None or not search.has_prior[j]:
        return None
    c, s = search.frame_turn
    sx, sy = source.tolist()
    mx, my = drift_mean.tolist()
    vx, vy = drift_var.tolist()
    x, y = sx + mx, sy + my
    px, py = search.prior_source[j].tolist()
    variance = float(search.prior_variance[j]) + (sx * sx + sy * sy) * search.frame.variance
    variance = variance + (vx + vy) / 2
    return (px, py, x * c - y * s, x * s + y * c, 1.0 / variance)


def _anchor_rows(
    search: _Search,
    js: NDArray[np.intp],
    source: FloatArray,
    drift_mean: FloatArray,
    drift_var: FloatArray,
) -> FloatArray:
    """(m, 5) anchors (prior source, placed source turned into the hints frame, 1 / variance)
    of pieces ``js``, each with a prior, whose sources lie at ``source`` ((2,) or (m, 2)).

    ``source`` is where the end-to-end concatenation puts it; the junctions on the way
    hide displacements (overlaps, gaps) that add up to ``drift_mean`` and ``drift_var``
    ((m, 2), per axis), so the source really lies there give or take that much.
    """
    frame = search.frame
    assert frame is not None
    c, s = search.frame_turn
    # Elementwise, not a matrix product: a row is then the same whatever the batch.
    source = np.broadcast_to(source, drift_mean.shape)
    x, y = source[:, 0] + drift_mean[:, 0], source[:, 1] + drift_mean[:, 1]
    # The frame's yaw is uncertain: the further from the first piece, the more it moves.
    reach = source[:, 0] * source[:, 0] + source[:, 1] * source[:, 1]
    variance = search.prior_variance[js] + reach * frame.variance
    variance = variance + (drift_var[:, 0] + drift_var[:, 1]) / 2  # isotropic: axes turn
    return np.column_stack([search.prior_source[js], x * c - y * s, x * s + y * c, 1.0 / variance])


@dataclass(frozen=True)
class _State:
    order: tuple[int, ...]
    rotations: tuple[int, ...]
    sources: FloatArray  # (m, 2) site position of each placed piece's source
    end: FloatArray
    heading: int
    turning: int
    features: FloatArray  # running feature sums (turns, structure, boundary, conflict, prior)
    mean: FloatArray  # (2,) hidden junction displacement so far, mean
    var: FloatArray  # (2,) and variance
    walls: FloatArray
    vertices: FloatArray
    samples: FloatArray  # (S, 2) site-frame wall samples of the placed pieces
    # With prior poses (for the conflict test): the hidden displacement at each placed
    # piece's source, mean and variance, (m, 2) each.
    drift_means: FloatArray
    drift_vars: FloatArray
    owners: NDArray[np.intp]  # (S,) each sample's piece's place in the order (priors only)
    box: Box  # their bounds (x_lo, y_lo, x_hi, y_hi)
    # Each placed piece's free-space box (x_lo, y_lo, x_hi, y_hi) at its source: the
    # conflict test's first filter without prior poses (with them the boxes move with the
    # drift), kept as the loop grows rather than gathered per child; plain floats, since a
    # loop over at most 16 boxes costs less than numpy's per-call overhead.
    free_at: tuple[Box, ...]
    violated: tuple[int, ...] = ()  # indices of broken hint pairs
    resolved: frozenset[int] = frozenset()  # hint pairs already decided
    # The priors' costs per quarter turn q of the frame: the frame estimate takes its turn
    # from the first piece's prior, which may be off by more than 45 degrees; the assembly
    # with most priors on its side decides. (4,) cost of the placed pieces' rotations:
    rotation_prior: FloatArray = field(default_factory=lambda: np.zeros(4))
    anchors: tuple[tuple[float, float, float, float, float], ...] = ()  # priors.position_costs
    position: FloatArray = field(default_factory=lambda: np.zeros(4))  # their costs, (4,)
    shared: tuple[int, ...] = (0,)  # per placed piece: corners shared with the one before

    def energy(self, weights: FloatArray) -> float:
        return float(weights @ self.features)


def _crosses(new: FloatArray, placed: FloatArray) -> bool:
    """True when a new wall crosses or overlaps a placed one (touching is allowed)."""
    if len(placed) == 0 or len(new) == 0:
        return False
    return bool(_crossing(new.T[:, :, None], placed.T).any())  # (W, 1) against (P,)


def _crosses_closed(search: _Search, state: _State, walls: FloatArray, end: FloatArray) -> bool:
    """Whether the walls of a piece appended to ``state`` (``walls`` where it lies, its
    target at ``end``) cross the placed ones even where the loop's closing gap is taken up:
    the last piece of a closed search is also tried moved onto the first piece's source.

    Laid end to end, a loop carries every junction's overlap or gap to its last junction
    (a metre and more over six real junctions), where the refinement closes it; the last
    piece then lies that far off and may cross the first's walls. Which piece is last
    depends only on which is fixed first, so without this a loop could be valid or not by
    the fragments' names or priors. Pieces before the last are tested where they lie.
    """
    closing = search.require_closed and len(state.order) + 1 == len(search.pieces)
    return not closing or _crosses(shift_walls(walls, -end), state.walls)


def _crossing(new: FloatArray, placed: FloatArray) -> NDArray[np.bool_]:
    """Which new walls cross or overlap which placed ones: ``new`` and ``placed`` hold
    (axis, offset, lo, hi) along their first dimension, the rest broadcast together."""
    axis, offset, lo, hi = new
    p_axis, p_offset, p_lo, p_hi = placed
    # Perpendicular: each wall's line passes strictly inside the other's run.
    crossing = (p_offset > lo + _CROSS_EPS) & (p_offset < hi - _CROSS_EPS)
    crossing &= (offset > p_lo + _CROSS_EPS) & (offset < p_hi - _CROSS_EPS)
    # Parallel: on one line, their runs overlapping by more than touching.
    overlap = np.minimum(hi, p_hi) - np.maximum(lo, p_lo)
    overlapping = (np.abs(offset - p_offset) < 2 * _CROSS_EPS) & (overlap > _CROSS_EPS)
    out: NDArray[np.bool_] = np.where(axis == p_axis, overlapping, crossing)
    return out


def _padded(rows: Sequence[FloatArray]) -> FloatArray:
    """(len(rows), R, 4): the wall arrays stacked, each padded with NaN rows to the
    longest (a NaN wall compares false: it crosses nothing and nothing crosses it)."""
    out = np.full((len(rows), max((len(r) for r in rows), default=0), 4), np.nan)
    for k, r in enumerate(rows):
        out[k, : len(r)] = r
    return out


class _Placed(NamedTuple):
    """A batch of states' placed walls, (K, P, 4) padded with NaN rows."""

    walls: FloatArray

    @classmethod
    def of(cls, states: Sequence[_State]) -> _Placed:
        return cls(_padded([s.walls for s in states]))


def _children_walls(
    search: _Search, placed: _Placed, children: _Children, rows: NDArray[np.intp] | slice
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """:func:`_crosses` for many children at once, those ``rows`` of ``children`` (of the
    states ``placed``): child c places piece[c] at rotation[c] after the state parent[c],
    its source at source[c] (past a shared corner: :func:`_past_corner`). Returns (C, W, 4)
    each child's walls where it lies (NaN rows past the piece's count; the same numbers as
    ``shift_walls`` and :func:`_past_corner`) and (C,) whether they cross their parent's
    placed walls. One set of array operations instead of one per child: the test's cost is
    mostly per call."""
    parent, piece, rotation = children.parent[rows], children.piece[rows], children.rotation[rows]
    source, overlap = children.source[rows], children.overlap[rows]
    walls = search.wall_table[piece, rotation]  # (C, W, 4), a copy (fancy indexing)
    along_x = walls[:, :, 0] == 0.0
    sx, sy = source[:, 0:1], source[:, 1:2]
    walls[:, :, 1] += np.where(along_x, sy, sx)
    run = np.where(along_x, sx, sy)
    walls[:, :, 2] += run
    walls[:, :, 3] += run
    corners = children.corners[rows]
    for c in np.flatnonzero(corners).tolist():
        j, count, k = int(piece[c]), int(search.wall_count[piece[c]]), int(corners[c])
        corner = search.corner_at[j, rotation[c], k] + source[c]
        kept = _past_corner(walls[c, :count], corner, float(overlap[c]), k)
        walls[c] = np.nan
        walls[c, : count - k] = kept
    others = placed.walls[parent]  # (C, P, 4)
    # (C, W, 1) against (C, 1, P)
    crosses = _crossing(walls.transpose(2, 0, 1)[..., None], others.transpose(2, 0, 1)[:, :, None])
    return walls, np.asarray(crosses.any(axis=(1, 2)), dtype=bool)


def _trim_start(walls: FloatArray, start: FloatArray, length: float) -> FloatArray:
    """Shorten the loop's first wall at its start: the closing piece may overshoot it by
    up to ``length`` (neighbouring scans overlap) without counting as a crossing."""
    out = walls.copy()
    axis, _, lo, hi = out[0]
    run = start[0] if axis == 0 else start[1]
    if abs(run - lo) <= abs(run - hi):
        out[0, 2] = min(lo + length, hi)
    else:
        out[0, 3] = max(hi - length, lo)
    return out


def _walls_clear(
    search: _Search, state: _State, j: int, rotation: int, source: FloatArray, shared: int
) -> FloatArray | None:
    """Piece j's walls at ``rotation`` with its source at ``source`` (sharing ``shared``
    corners as :func:`_past_corner` cuts them), or None when they cross the state's walls
    (:func:`_crosses_closed` for the piece that closes the loop)."""
    pts, local_walls, _ = search.pieces[j].rotated[rotation]
    walls = shift_walls(local_walls, source)
    if shared:
        overlap = float(search.last_len[state.order[-1]])
        walls = _past_corner(walls, pts[shared] + source, overlap, shared)
    if _crosses(walls, state.walls) and _crosses_closed(search, state, walls, pts[-1] + source):
        return None
    return walls


def _past_corner(walls: FloatArray, corner: FloatArray, overlap: float, corners: int) -> FloatArray:
    """The walls of a piece that shares ``corners`` corners with the last one, as tested
    for crossing: those before its last shared ``corner`` (on the last piece's walls)
    dropped, the next cut where the last piece's wall after that corner ends, ``overlap``
    past it."""
    return _trim_start(walls[corners:], corner, overlap)


def _conflict(
    search: _Search,
    state: _State,
    j: int,
    rotation: int,
    samples: FloatArray,
    box: Box,
    drift: tuple[FloatArray, FloatArray],
    source: FloatArray,
) -> float:
    """Meters of wall through space another scan saw empty, for piece j joining the state
    with its source at ``source``.

    j's walls (``samples``, site frame, bounded by ``box``) are tested against every placed
    piece's free space and the placed walls against j's, each in the piece's own frame
    (rotate back, shift back). ``drift``: mean and variance (2,) of the junctions' hidden
    displacement at j's source. With prior poses, two pieces many junctions apart on the
    loop are placed less surely relative to each other: each is moved by the mean drift
    between them, and a wall counts only deeper than ``conflict_drift_sigmas`` of that
    drift's spread inside the other's free space: end to end from the most certain prior's
    piece, a true room's far walls can drift meters deep into seen space. Without priors
    every wall counts where the end-to-end loop puts it; forgiving the drift there lost
    rooms, refitted weights or not (README, *Accuracy and speed*).
    """
    hits = 0
    free_at: Sequence[Sequence[float]] = state.free_at
    at, margins = state.sources, np.zeros(len(state.order))
    shifts = None
    if search.frame is not None:
        # Each placed piece relative to j: moved by the mean drift between them, and its
        # walls or free space counted only beyond a margin of that drift's spread.
        mean_j, var_j = drift
        shifts = state.drift_means - mean_j
        spread = np.sqrt(np.maximum(var_j - state.drift_vars, 0.0).max(axis=1))
        margins = search.params.conflict_drift_sigmas * spread
        at = state.sources + shifts
        free_at = (search.free_boxes[state.order, state.rotations] + at[:, _XYXY]).tolist()
    # j's walls in the placed pieces' free spaces: only those whose box meets j's walls'.
    for k, free_box in enumerate(free_at):
        if not _meets(box, free_box):
            continue
        free = search.pieces[state.order[k]].rotated_free[state.rotations[k]]
        hits += free.hits(samples - at[k], float(margins[k]))
    free = search.pieces[j].rotated_free[rotation]
    placed_samples = state.samples
    placed_margins: FloatArray | float = 0.0  # a float: the plain free-cell test
    pad = 0.0  # how far a placed sample moves at most
    if shifts is not None:
        placed_samples = state.samples + shifts[state.owners]
        placed_margins = margins[state.owners]
        pad = float(np.abs(shifts).max())
    x0, y0, x1, y1 = state.box
    ex, ey = source.tolist()
    if _meets((x0 - pad, y0 - pad, x1 + pad, y1 + pad), _shifted(free.box, ex, ey)):
        hits += free.hits(placed_samples - source, placed_margins)
    return hits * SAMPLE_SPACING


def _meets(a: Sequence[float], b: Sequence[float]) -> bool:
    """True when the boxes (x_lo, y_lo, x_hi, y_hi) overlap (touching counts)."""
    return a[0] <= b[2] and a[2] >= b[0] and a[1] <= b[3] and a[3] >= b[1]


def _shifted(box: Box, dx: float, dy: float) -> Box:
    return (box[0] + dx, box[1] + dy, box[2] + dx, box[3] + dy)


def _union(a: Box, b: Box) -> Box:
    return (min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3]))


def _resolve_pairs(
    search: _Search, state: _State, follows: Mapping[int, int]
) -> tuple[tuple[int, ...], frozenset[int]]:
    """Hint pairs decided once the successors in ``follows`` are known (a -> b)."""
    succ = dict(zip(state.order[:-1], state.order[1:], strict=True)) | dict(follows)
    pred = {b: a for a, b in succ.items()}
    violated, resolved = list(state.violated), set(state.resolved)
    for k, (a, b, directed) in enumerate(search.pairs):
        if k in resolved:
            continue
        if directed:
            if a in succ:
                resolved.add(k)
                if succ[a] != b:
                    violated.append(k)
            continue
        for x, y in ((a, b), (b, a)):
            if x in succ and x in pred:  # both of x's neighbours are known
                resolved.add(k)
                if y not in (succ[x], pred[x]):
                    violated.append(k)
                break
    return tuple(violated), frozenset(resolved)


def _extend(
    search: _Search,
    state: _State,
    j: int,
    turn: int,
    position: FloatArray | None = None,
    walls: FloatArray | None = None,
    shared: int = 0,
) -> _State | None:
    """The state with piece j appended after a junction that turns by ``turn``, or None
    when its walls would cross the placed ones (:func:`_crosses_closed` for the piece that
    closes the loop). ``position``: the child's position costs when already known
    (:func:`_children`); ``walls``: the child's walls where it lies, when already known to
    cross nothing (:func:`_children_walls`); ``shared``: how many corners the junction
    shares with the last piece (:mod:`services.placement.corners`)."""
    piece = search.pieces[j]
    prev = state.order[-1]
    rotation = (state.heading + turn - piece.directions[0]) % 4
    local_pts, _, local_samples = piece.rotated[rotation]
    source = state.end
    if shared:
        last = search.pieces[prev]
        source = source + corner_shift(last, state.rotations[-1], piece, rotation, shared)
    pts = local_pts + source
    if walls is None:
        walls = _walls_clear(search, state, j, rotation, source, shared)
        if walls is None:
            return None
    samples = local_samples + source
    heading_out = (piece.directions[0] + rotation) % 4
    mean, var = search.step[state.heading, heading_out]
    if shared:
        mean, var = np.zeros(2), search.corner_var
    drift_mean, drift_var = state.mean + mean, state.var + var  # hidden displacement so far
    features = state.features.copy()
    features[_F["turns"]] += abs(turn)  # a shared junction turns back by all its corners
    features[_F["structure"]] += search.structure[prev, j]
    features[_F["boundary"]] += search.boundary[prev, j]
    # Shifting every sample by the source shifts their bounds by it (rounding is monotone).
    ex, ey = source.tolist()
    box = _shifted(piece.sample_boxes[rotation], ex, ey)
    drift = (drift_mean, drift_var)
    features[_F["conflict"]] += _conflict(search, state, j, rotation, samples, box, drift, source)
    rotations_cost = state.rotation_prior + search.turned_rotation_cost[j, rotation]
    anchor = _anchor(search, j, source, drift_mean, drift_var)
    anchors = state.anchors if anchor is None else (*state.anchors, anchor)
    if anchor is None:
        position = state.position
    elif position is None:
        position = position_costs(anchors)
    if search.frame is not None:
        features[_F["prior"]] = float((rotations_cost + position).min())
    drift_means, drift_vars, owners = state.drift_means, state.drift_vars, state.owners
    if search.frame is not None:  # only the priors' conflict test reads them
        drift_means = np.concatenate([drift_means, drift_mean[None]])
        drift_vars = np.concatenate([drift_vars, drift_var[None]])
        owners = np.concatenate([owners, np.full(len(samples), len(state.order))])
    child = _State(
        order=(*state.order, j),
        rotations=(*state.rotations, rotation),
        sources=np.concatenate([state.sources, source[None]]),
        end=pts[-1],
        heading=(piece.directions[-1] + rotation) % 4,
        turning=state.turning + turn + piece.turning,
        features=features,
        mean=drift_mean,
        var=drift_var,
        walls=np.concatenate([state.walls, walls]),
        vertices=np.concatenate([state.vertices, pts]),
        samples=np.concatenate([state.samples, samples]),
        drift_means=drift_means,
        drift_vars=drift_vars,
        owners=owners,
        box=_union(state.box, box),
        free_at=(*state.free_at, _shifted(piece.rotated_free[rotation].box, ex, ey)),
        violated=state.violated,
        resolved=state.resolved,
        rotation_prior=rotations_cost,
        anchors=anchors,
        position=position,
        shared=(*state.shared, shared),
    )
    if search.pairs:
        violated, resolved = _resolve_pairs(search, child, {})
        child = replace(child, violated=violated, resolved=resolved)
    return child


def _close(search: _Search, state: _State) -> None:
    """Score the state as a leaf: a closed loop (all pieces), or a partial open chain."""
    leaf = _leaf(search, state, search.threshold())
    if leaf is not None:
        search.record(leaf)


def _leaf(search: _Search, state: _State, cap: float = np.inf) -> PlacementCandidate | None:
    """The state as a leaf, or None when it is not one (an open chain in a closed search)
    or its energy reaches ``cap`` (known before its hull is computed)."""
    missing = len(search.pieces) - len(state.order)
    closing = _closings(search, state)
    if search.require_closed and not closing:
        return None
    features = state.features.copy()
    violated = state.violated
    closes_shared = 0
    if not missing and closing:
        last = state.order[-1]
        weights = search.weights
        turns, closure, closes_shared = min(
            closing, key=lambda c: weights[_F["turns"]] * c[0] + weights[_F["closure"]] * c[1]
        )
        features[_F["turns"]] += turns
        features[_F["structure"]] += search.structure[last, 0]
        features[_F["boundary"]] += search.boundary[last, 0]
        features[_F["closure"]] = closure
        if search.pairs:
            violated, _ = _resolve_pairs(search, state, {last: 0})
    penalty = _UNPLACED_PENALTY * missing + search.params.hint_pair_cost * len(violated)
    weights = search.weights
    # The hull has at least 4 edges: skip computing it when even that cannot win.
    if weights @ features + weights[_F["hull"]] * 4 + penalty >= cap:
        return None
    features[_F["hull"]] = hull_edges(state.vertices)
    energy = float(weights @ features) + penalty
    ids = tuple(search.pieces[i].id for i in state.order)
    pairs = tuple(search.hints.pairs[k] for k in violated) if search.hints.pairs else ()
    named = dict(zip(FEATURES, features.tolist(), strict=True))
    shared = (closes_shared, *state.shared[1:])
    return PlacementCandidate(
        energy, ids, state.rotations, named, missing, pairs, shared if any(shared) else ()
    )


def _closings(search: _Search, state: _State) -> list[tuple[int, float, int]]:
    """The ways a complete state's loop closes into the first piece: (turns counted, the
    closure feature, corners shared) for a plain junction and for each that shares the
    first piece's first corners with the last piece; empty when none closes (the turns do
    not add up, or the junction would fold back)."""
    first, last = search.pieces[0], state.order[-1]
    turn = int(_TURN_OF[(first.directions[0] - state.heading) % 4])
    out = []
    if turn != 2 and state.turning + turn == 4:
        mean, var = search.step[state.heading, first.directions[0]]
        out.append((abs(turn), closure_nll(state.end, state.mean + mean, state.var + var), 0))
    for corners in np.flatnonzero(search.sharing[last, 0]).tolist():
        turn = int(search.shared_turn[0, corners])
        if (first.directions[0] - state.heading - turn) % 4 or state.turning + turn != 4:
            continue
        # The last piece's last corner is the first piece's corner ``corners``: the loop
        # ends that corner's way along the last wall.
        end = state.end - (state.vertices[-1] - state.vertices[-2]) - first.keypoints[corners]
        out.append(
            (abs(turn), closure_nll(end, state.mean, state.var + search.corner_var), corners)
        )
    return out


def _dfs(
    search: _Search,
    state: _State,
    remaining: tuple[int, ...],
    children: _Children | None = None,
) -> None:
    """Expand ``state``: children in order of their lower bound (the least energy any leaf
    below them can have, :func:`_children`), cut where that reaches the search's threshold
    (the energy a new leaf must beat, :meth:`_Search.threshold`). Only a child that is
    visited pays for its geometry (crossing and free-space tests). A state is a partial
    loop: the pieces placed in order with their quarter turns and where its end lies;
    ``remaining`` holds the indices of the pieces still to place; ``children``: the
    state's children when already bounded."""
    search.nodes += 1
    if not remaining or not search.require_closed:
        # An open search also keeps partial chains: the best one is placed when no
        # arrangement of all pieces exists (walls would cross).
        _close(search, state)
        if not remaining:
            return
    if children is None:
        children = _children(search, [state])
    queue = np.lexsort((children.turn, children.piece, children.bound)).tolist()
    bounds, pieces = children.bound.tolist(), children.piece.tolist()
    expanded = 0
    while queue:
        # The next few children under the threshold are placed together, so that their own
        # children are bounded in one batch; each is checked again before it is expanded.
        wanted = _DFS_GROUP if search.breadth is None else search.breadth - expanded
        group, queue, cut = _place_group(search, state, children, queue, min(wanted, _DFS_GROUP))
        batch = None
        if group and len(remaining) > 1:
            batch = _children(search, [child for _, child in group])
        for g, (c, child) in enumerate(group):
            if bounds[c] >= search.threshold() or search.out_of_budget():
                return
            rest = tuple(i for i in remaining if i != pieces[c])
            _dfs(search, child, rest, None if batch is None else batch.of(g))
            expanded += 1
            if search.breadth is not None and expanded >= search.breadth:
                return
        if cut:
            return


def _place_group(
    search: _Search, state: _State, children: _Children, queue: list[int], size: int
) -> tuple[list[tuple[int, _State]], list[int], bool]:
    """Place the next ``size`` children of ``queue`` (indices into ``children``) whose
    walls cross nothing, while their bounds are under the threshold and the budget lasts.
    Returns those children (index, state), the rest of the queue, and whether the
    threshold or the budget cut it."""
    group: list[tuple[int, _State]] = []
    for taken, c in enumerate(queue):
        if len(group) == size:
            return group, queue[taken:], False
        if children.bound[c] >= search.threshold() or search.out_of_budget():
            return group, queue[taken:], True
        position = None if children.position is None else children.position[c]
        shared = int(children.corners[c])
        child = _extend(
            search, state, int(children.piece[c]), int(children.turn[c]), position, None, shared
        )
        if child is not None:
            group.append((c, child))
    return group, [], False


def _beam(search: _Search, root: _State, width: int) -> None:
    """Breadth-first search keeping the ``width`` children of lowest bound per loop position.

    Children that reach the same pieces, last piece, heading and end (to 10 cm) are one:
    the beam keeps different partial loops, not copies of one.
    """
    layer = [root]
    for _ in range(1, len(search.pieces)):
        children = _children(search, layer)
        ranked = np.lexsort((children.turn, children.piece, children.parent, children.bound))
        parents = children.parent.tolist()
        pieces, turns = children.piece.tolist(), children.turn.tolist()
        headings = children.heading.tolist()
        ends = np.round(children.end, 1).tolist()
        states, layer = layer, []
        seen: set[tuple[object, ...]] = set()
        # The threshold does not move while a layer is laid (no leaf is recorded); the
        # children's walls are tested in chunks of about as many as the layer still takes.
        ranked = ranked[children.bound[ranked] < search.threshold()]
        walls, crosses, first, checked = np.empty((0, 0, 4)), np.empty(0, dtype=bool), 0, 0
        placed = _Placed.of(states)
        for i, c in enumerate(ranked.tolist()):
            if len(layer) >= width or search.out_of_budget():
                break
            search.nodes += 1
            state, j = states[parents[c]], pieces[c]
            key = (frozenset((*state.order, j)), j, headings[c], *ends[c])
            if key in seen:
                continue  # known before paying for its geometry
            if i >= checked:
                chunk = ranked[i : i + width - len(layer) + _BEAM_SPARE]
                walls, crosses = _children_walls(search, placed, children, chunk)
                first, checked = i, i + len(chunk)
            shared = int(children.corners[c])
            own = walls[i - first, : search.wall_count[j] - shared]
            if crosses[i - first] and _crosses_closed(search, state, own, children.end[c]):
                continue
            position = None if children.position is None else children.position[c]
            child = _extend(search, state, j, turns[c], position, own, shared)
            assert child is not None  # its walls cross nothing
            seen.add(key)
            layer.append(child)
    for state in layer:
        _close(search, state)


@dataclass(frozen=True)
class _Children:
    """The children of a batch of states: child c appends piece[c] to the state parent[c]
    after a junction that turns by turn[c]; arrays of shape (C,) unless noted."""

    parent: NDArray[np.intp]
    piece: NDArray[np.intp]
    turn: NDArray[np.intp]
    rotation: NDArray[np.intp]  # the piece's quarter turns
    heading: NDArray[np.intp]  # of the piece's last wall
    end: FloatArray  # (C, 2) the piece's target
    bound: FloatArray  # the least energy any leaf below the child can have
    position: FloatArray | None  # with priors: (C, 4) position costs (see _child_priors)
    source: FloatArray  # (C, 2) the piece's source
    corners: NDArray[np.intp]  # corners shared with the last piece (0: none)
    # Sharing corners: how far the last piece's wall runs past the last of them; else NaN.
    overlap: FloatArray

    def of(self, k: int) -> _Children:
        """The children of the batch's k-th state, as a batch of its own."""
        lo, hi = np.searchsorted(self.parent, [k, k + 1]).tolist()
        return _Children(
            self.parent[lo:hi] - k,
            self.piece[lo:hi],
            self.turn[lo:hi],
            self.rotation[lo:hi],
            self.heading[lo:hi],
            self.end[lo:hi],
            self.bound[lo:hi],
            None if self.position is None else self.position[lo:hi],
            self.source[lo:hi],
            self.corners[lo:hi],
            self.overlap[lo:hi],
        )


def _children(search: _Search, states: Sequence[_State]) -> _Children:
    """Every child a closed loop's turning number allows (a piece not placed yet, after a
    junction that continues or turns), with its lower bound, for a batch of states."""
    pieces, weights, noise = search.pieces, search.weights, search.noise
    n, count = len(pieces), len(states)
    remaining = np.ones((count, n), dtype=bool)
    remaining[:, 0] = False
    for k, state in enumerate(states):
        remaining[k, list(state.order)] = False
    # Per state: heading, turning so far, last piece, pieces left; end, drift mean and
    # variance, energy so far.
    facts = np.array(
        [(s.heading, s.turning, s.order[-1], n - len(s.order)) for s in states], dtype=np.intp
    ).reshape(-1, 4)
    heading, turned, last, left = facts.T
    values = np.array(
        [[*s.end.tolist(), *s.mean.tolist(), *s.var.tolist(), s.energy(weights)] for s in states]
    ).reshape(-1, 7)
    ends, mean, var, energy = values[:, 0:2], values[:, 2:4], values[:, 4:6], values[:, 6]
    turning = turned + (remaining @ search.turning).astype(np.intp)  # with the pieces left
    turn_options = np.array(_TURNS)
    # The loop's turns add up to +4; the junctions after this one give at most turn_reach
    # either way each (+-1 but where two corners may be shared).
    most = (left * search.turn_reach)[:, None]
    if search.require_closed:
        turn_allowed = np.abs(4 - turning[:, None] - turn_options) <= most
        allowed = remaining[:, :, None] & turn_allowed[:, None, :]
    else:
        allowed = np.repeat(remaining[:, :, None], len(_TURNS), axis=2)
    parent, piece, option = np.nonzero(allowed)
    turn = turn_options[option]
    parent, piece, turn, corners = _with_shared(
        search, remaining, last, turning, most, parent, piece, turn
    )
    shared = corners > 0
    rotation = (heading[parent] + turn - search.first_direction[piece]) % 4
    heading_in = (heading[parent] + turn) % 4
    back = np.where(shared, search.last_len[last[parent]], 0.0)
    overlap = np.where(shared, back, np.nan)
    # Shared corners: back along the last piece's last wall, then along the child's chain
    # from its last shared corner to its source.
    source = ends[parent] - back[:, None] * UNIT[heading[parent]]
    source -= search.corner_at[piece, rotation, corners]
    child_end = source + search.chain_ends[piece, rotation]
    child_heading = (search.last_direction[piece] + rotation) % 4
    # The hidden displacement up to each child's source, with its junction's.
    entering = search.step[heading[parent], heading_in]
    entering[shared, 0], entering[shared, 1] = 0.0, search.corner_var
    drift_mean, drift_var = mean[parent] + entering[:, 0], var[parent] + entering[:, 1]

    # Cheapest way into each piece left and into the loop's start, from a piece that can
    # still precede it (the current last piece or another one left).
    sources = remaining.copy()
    sources[np.arange(count), last] = True
    into = np.where(sources[:, :, None], search.junction[None], np.inf).min(axis=1)
    targets = remaining.copy()
    targets[:, 0] = True
    entry_total = np.where(targets, into, 0.0).sum(axis=1)
    # Rotation costs are all zero without priors: skip the reduction.
    rotation_floor = (
        np.where(remaining, search.rotation_floor, 0.0).sum(axis=1)
        if search.frame is not None
        else np.zeros(count)
    )

    # Closure: the gap the pieces left cannot make up (L1, by duality), against the largest
    # variance the remaining junctions could add (Cauchy-Schwarz: |r|_1^2 <= sum r^2/v sum v).
    # Shared corners still to come may each cut a wall off a piece: its far reach.
    reach = np.where(remaining[:, :, None], search.reach_far[None], 0.0).sum(axis=1)
    others = reach[parent] - search.reach_far[piece] + search.back_reach[piece, None]
    others = others + search.close_reach
    gaps = np.maximum(0.0, (child_end @ _AWAY_FROM_START - others).max(axis=1))
    junctions_left = left + 1
    shift = max(abs(noise.straight_mean), 2 * abs(noise.turn_mean))
    slack = np.abs(mean).sum(axis=1) + junctions_left * shift
    worst = max(noise.straight_sigma**2, 2 * noise.turn_sigma**2) + 2 * noise.keypoint_sigma**2
    total_var = var.sum(axis=1) + junctions_left * worst
    closure = 0.5 * np.maximum(0.0, gaps - slack[parent]) ** 2 / total_var[parent]
    # Every junction left adds the keypoint noise to both axes and at least a straight
    # junction's spread to one of them (a shared corner's measured spread, where corners may
    # be shared); log is concave, so the least sum of logs puts all of the latter on one axis.
    vx = var[:, 0] + junctions_left * noise.keypoint_sigma**2
    vy = var[:, 1] + junctions_left * noise.keypoint_sigma**2
    spread = junctions_left * search.least_spread
    spread_cost = np.minimum(np.log(vx + spread) + np.log(vy), np.log(vx) + np.log(vy + spread))
    closure += 0.5 * spread_cost[parent]

    base = energy + weights[_F["hull"]] * 4 + weights[_F["prior"]] * rotation_floor
    turn_cost = np.abs(turn).astype(np.float64)
    if search.require_closed:
        turn_cost += np.abs(4 - turning[parent] - turn)  # turns still owed
    # The junction into the piece replaces the cheapest way into it counted in entry_total.
    ahead = weights[_F["turns"]] * turn_cost
    ahead += search.junction[last[parent], piece] + entry_total[parent] - into[parent, piece]
    tour = search.tour
    if tour is not None:
        # The cheapest tour through the pieces left after the child and back to the start
        # (junctions and turns), a bound of its own: the larger of the two holds.
        bits = 1 << np.arange(n - 1)
        after = (remaining[:, 1:] @ bits)[parent] & ~bits[piece - 1]
        through = weights[_F["turns"]] * np.abs(turn) + search.junction[last[parent], piece]
        through += tour[after, piece, child_heading]
        ahead = np.maximum(ahead, through)
    if search.require_closed:
        ahead += weights[_F["closure"]] * closure
    if search.finish_exactly:
        # Near the loop's end every way to finish it is few enough to try: turns, junctions
        # and closure exactly (walls that would cross are not checked, so it stays a bound).
        near = np.flatnonzero(left[parent] <= _LOOKAHEAD + 1)
        if len(near):
            p, j, t = parent[near], piece[near], turn[near]
            after = np.column_stack([child_heading[near], turned[p] + t + search.turning[j], j])
            where = np.column_stack([child_end[near], drift_mean[near], drift_var[near]])
            left_after = remaining[p]
            left_after[np.arange(len(near)), j] = False
            finish = _finishing_cost(search, after, where, left_after)
            finish += weights[_F["turns"]] * np.abs(t) + search.junction[last[p], j]
            ahead = np.maximum(ahead, finish)
    bound = base[parent] + ahead
    position = None
    if search.frame is not None:
        # The child's own prior is known exactly: it replaces the state's and the floor
        # counted for its piece's rotation.
        prior_so_far = np.array([s.features[_F["prior"]] for s in states])
        floor_of_piece = search.rotation_floor[piece]

        def with_own(own: FloatArray, rows: NDArray[np.intp] | slice = slice(None)) -> FloatArray:
            """The bound of children ``rows`` with prior feature ``own``: it replaces the
            state's and the floor counted for the piece's rotation."""
            counted = prior_so_far[parent[rows]]
            out: FloatArray = bound[rows] + weights[_F["prior"]] * (
                own - counted - floor_of_piece[rows]
            )
            return out

        own, position = _child_priors(
            search, states, parent, piece, rotation, source, drift_mean, drift_var, with_own
        )
        bound = with_own(own)
    return _Children(
        parent, piece, turn, rotation, child_heading, child_end, bound, position, source,
        corners, overlap,
    )  # fmt: skip


def _with_shared(
    search: _Search,
    remaining: NDArray[np.bool_],
    last: NDArray[np.intp],
    turning: NDArray[np.intp],
    most: NDArray[np.intp],
    parent: NDArray[np.intp],
    piece: NDArray[np.intp],
    turn: NDArray[np.intp],
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
    """The children (parent, piece, turn) with those sharing corners added, and how many
    each shares (0: none); still sorted by parent (:meth:`_Children.of` slices by it). Per
    state: the pieces left (count, n), the last piece, the turns with the pieces left and
    the most the junctions after the child may still turn (count, 1). A junction sharing
    corners turns back by as much as they turn."""
    parents, pieces, turns, corners = [parent], [piece], [turn], [np.zeros(len(parent), np.intp)]
    if not search.shares_any:
        return parent, piece, turn, corners[0]
    for k in range(1, MOST_SHARED + 1):
        sharing = remaining & search.sharing[last, :, k]
        if search.require_closed:
            sharing &= np.abs(4 - turning[:, None] - search.shared_turn[None, :, k]) <= most
        s_parent, s_piece = np.nonzero(sharing)
        parents.append(s_parent)
        pieces.append(s_piece)
        turns.append(search.shared_turn[s_piece, k])
        corners.append(np.full(len(s_parent), k, dtype=np.intp))
    if len(parent) == sum(len(p) for p in parents):
        return parent, piece, turn, corners[0]
    by_parent = np.argsort(np.concatenate(parents), kind="stable")
    merged = [np.concatenate(a)[by_parent] for a in (parents, pieces, turns, corners)]
    return merged[0], merged[1], merged[2], merged[3]


def _tour(search: _Search) -> FloatArray:
    """[mask, l, h]: the least junction and turn energy of any tour that starts after piece
    l, heading h, places every piece of ``mask`` (bit k: piece k + 1) once and closes into
    the first piece; inf where none can. Walls crossing, closure and the turning number are
    left out, so it bounds the energy still to come. Dynamic programming over the subsets,
    by their number of pieces (a subset is reached from those one piece smaller)."""
    n, steps = len(search.pieces), search.finishing  # the headings and turns' costs per step
    close_cost = np.where(steps.close_gain == 99, np.inf, steps.close_cost)  # 99: folds back
    first = search.pieces[0].directions[0]
    for corners in np.flatnonzero(search.sharing[:, 0].any(axis=0)).tolist():
        # Closing by sharing the first piece's corners turns back by what they turn.
        turn = int(search.shared_turn[0, corners])
        h = (first - turn) % 4
        close_cost[h] = min(close_cost[h], search.weights[_F["turns"]] * abs(turn))
    masks = np.arange(1 << (n - 1))
    size = np.zeros(len(masks), dtype=np.intp)
    for k in range(n - 1):
        size += (masks >> k) & 1
    tour = np.full((len(masks), n, 4), np.inf)
    tour[0] = search.junction[:, 0, None] + close_cost[None, :]
    for count in range(1, n):
        layer = masks[size == count]
        best = np.full((len(layer), n, 4), np.inf)
        for k in range(n - 1):
            rows = np.flatnonzero((layer >> k) & 1)  # the subsets holding piece j = k + 1
            j = k + 1
            # Entering j at heading h and turn t, then the cheapest tour of the rest, (m, 4, 3).
            after = tour[layer[rows] ^ (1 << k), j][:, steps.heading[:, j]] + steps.cost[j]
            into = search.junction[:, j, None] + after.min(axis=2)[:, None, :]  # (m, n, 4)
            best[rows] = np.minimum(best[rows], into)
        tour[layer] = best
    return tour


@dataclass(frozen=True)
class _Finishing:
    """What each step of a loop's last few junctions adds, by the heading h before it, the
    piece k it appends and its junction t: an index into _TURNS, or 2 + c for one sharing c
    corners (:mod:`services.placement.corners`; its shift leaves out the last piece's last
    wall, which :func:`_finishing_cost` adds); piece index n is "no piece", a step that
    changes nothing (t = 0 only), so that loops with fewer pieces left share the arrays."""

    shift: FloatArray  # (4, n + 1, T, 2) the piece's end offset plus the junction's mean
    var: FloatArray  # (4, n + 1, T, 2) the junction's variance
    heading: NDArray[np.intp]  # (4, n + 1, T) heading after the piece
    gain: NDArray[np.intp]  # (n + 1, T) quarter turns the junction and the piece add
    cost: FloatArray  # (n + 1, T) the turn's energy (inf where there is no such step)
    junction: FloatArray  # (n + 1, n + 1) search.junction; 0 into "no piece"
    # Closing the loop into the first piece from heading h: (4, 2) mean, (4, 2) variance,
    # (4,) quarter turns (99 where it would fold back) and (4,) the turn's energy.
    close_shift: FloatArray
    close_var: FloatArray
    close_gain: NDArray[np.intp]
    close_cost: FloatArray


# A _Finishing step's junction: its index and the corners it shares (0: none).
_STEP_CORNERS = np.array([0] * len(_TURNS) + list(range(1, MOST_SHARED + 1)))


def _finishing(search: _Search) -> _Finishing:
    n, w_turn = len(search.pieces), search.weights[_F["turns"]]
    k, steps = np.arange(n), len(_STEP_CORNERS)
    turns = np.zeros((n, steps), dtype=np.intp)
    turns[:, : len(_TURNS)] = _TURNS
    turns[:, len(_TURNS) :] = search.shared_turn[:, 1:]
    heading_in = (np.arange(4)[:, None, None] + turns[None]) % 4  # (4, n, T)
    rotation = (heading_in - search.first_direction[k, None]) % 4
    step = search.step[np.arange(4)[:, None, None], heading_in]  # (4, n, T, 2, 2)
    shared = _STEP_CORNERS > 0
    step[:, :, shared, 0], step[:, :, shared, 1] = 0.0, search.corner_var
    shift = np.zeros((4, n + 1, steps, 2))
    shift[:, :n] = search.chain_ends[k[:, None], rotation] + step[..., 0, :]
    shift[:, :n] -= search.corner_at[k[:, None], rotation, _STEP_CORNERS]
    var = np.zeros((4, n + 1, steps, 2))
    var[:, :n] = step[..., 1, :]
    heading = np.repeat(np.arange(4)[:, None, None], n + 1, axis=1).repeat(steps, axis=2)
    heading[:, :n] = (search.last_direction[k, None] + rotation) % 4
    gain = np.zeros((n + 1, steps), dtype=np.intp)
    gain[:n] = turns + search.turning[:, None]
    cost = np.full((n + 1, steps), np.inf)
    cost[:n] = w_turn * np.abs(turns)
    entered = np.asarray(search.sharing.any(axis=0))[:, _STEP_CORNERS]  # (n, T): into k so
    cost[:n] = np.where(shared & ~entered, np.inf, cost[:n])
    cost[n, 0] = 0.0
    junction = np.zeros((n + 1, n + 1))
    junction[:n, :n] = search.junction
    first = search.pieces[0].directions[0]
    closing = (first - np.arange(4)) % 4  # 0 continue, 1 left, 3 right, 2 folds back
    close_gain = np.array([0, 1, 99, -1])[closing]
    close_step = search.step[np.arange(4), first]
    return _Finishing(
        shift,
        var,
        heading,
        gain,
        cost,
        junction,
        close_step[:, 0],
        close_step[:, 1],
        close_gain,
        w_turn * (closing != 0),
    )


def _finishing_cost(
    search: _Search,
    facts: NDArray[np.intp],
    values: FloatArray,
    left: NDArray[np.bool_],
) -> FloatArray:
    """(C,) the least cost of turns, junctions and closure over every way to finish each
    child's loop (both orders and every junction of the at most two pieces left; inf when
    none closes), as :func:`_extend` and :func:`_close` add them up from the child's end on.
    Walls are not tested for crossing, so it is a lower bound of the energy still to come.

    facts: (C, 3) heading, turns so far and last piece; values: (C, 6) end, mean and
    variance of the hidden displacement (per axis); left: (C, n) the pieces still to place.
    """
    table, n, steps = search.finishing, len(search.pieces), len(_STEP_CORNERS)
    padded = np.sort(np.where(left, np.arange(n), n), axis=1)[:, :2]  # n >= 2 (a child exists)
    orders = padded[:, [[0, 1], [1, 0]]]  # (C, 2 orders, 2 steps)
    k1, k2 = orders[:, :, 0, None, None], orders[:, :, 1, None, None]  # (C, 2, 1, 1)
    t1, t2 = np.arange(steps)[:, None], np.arange(steps)  # (T, 1) and (T,)
    h0 = facts[:, 0, None, None, None]
    h1 = table.heading[h0, k1, t1]  # (C, 2, T, 1)
    h2 = table.heading[h1, k2, t2]  # (C, 2, T, T)
    last0 = facts[:, 2, None, None, None]
    last1 = np.where(k1 == n, last0, k1)
    last2 = np.where(k2 == n, last1, k2)
    gain = table.gain[k1, t1] + table.gain[k2, t2] + facts[:, 1, None, None, None]
    cost = table.cost[k1, t1] + table.cost[k2, t2]
    cost = cost + table.junction[last0, k1] + table.junction[last1, k2]
    cost = cost + search.junction[last2, 0]
    start = values[:, None, None, None, 0:2] + values[:, None, None, None, 2:4]
    residual = start + table.shift[h0, k1, t1] + table.shift[h1, k2, t2]
    var = values[:, None, None, None, 4:6] + table.var[h0, k1, t1] + table.var[h1, k2, t2]
    share = np.zeros((n + 1, n + 1, MOST_SHARED + 1), dtype=bool)
    share[:n, :n] = search.sharing
    back = np.append(search.last_len, 0.0)
    if search.sharing.any():
        # A step sharing corners also goes back along the last piece's last wall, and only
        # follows a piece it may share that many corners with.
        c1, c2 = _STEP_CORNERS[t1], _STEP_CORNERS[t2]
        residual = residual - np.where((c1 > 0)[..., None], back[last0][..., None] * UNIT[h0], 0.0)
        residual = residual - np.where((c2 > 0)[..., None], back[last1][..., None] * UNIT[h1], 0.0)
        cost = cost + np.where((c1 > 0) & ~share[last0, k1, c1], np.inf, 0.0)
        cost = cost + np.where((c2 > 0) & ~share[last1, k2, c2], np.inf, 0.0)
    # Closing into the first piece: a plain junction...
    closes = gain + table.close_gain[h2] == 4
    total = cost + table.close_cost[h2]
    closure = _closure_nll(residual + table.close_shift[h2], var + table.close_var[h2])
    total = np.where(closes, total + search.weights[_F["closure"]] * closure, np.inf)
    # ...or one sharing the first piece's first corners.
    first = search.pieces[0]
    for corners in np.flatnonzero(search.sharing[:, 0].any(axis=0)).tolist():
        turn = int(search.shared_turn[0, corners])
        closes = share[last2, 0, corners] & ((first.directions[0] - h2) % 4 == turn % 4)
        closes &= gain + turn == 4
        back_close = back[last2][..., None] * UNIT[h2] + first.keypoints[corners]
        closure = _closure_nll(residual - back_close, var + search.corner_var)
        shared_total = cost + search.weights[_F["turns"]] * abs(turn)
        shared_total = shared_total + search.weights[_F["closure"]] * closure
        total = np.where(closes, np.minimum(total, shared_total), total)
    least: FloatArray = total.reshape(len(total), -1).min(axis=1)
    return least


def _closure_nll(residual: FloatArray, var: FloatArray) -> FloatArray:
    """:func:`closure_nll` over the leading axes of (..., 2) residuals and variances."""
    nll: FloatArray = 0.5 * np.sum(residual**2 / var + np.log(var), axis=-1)
    return nll


def _child_priors(
    search: _Search,
    states: Sequence[_State],
    parent: NDArray[np.intp],
    piece: NDArray[np.intp],
    rotation: NDArray[np.intp],
    source: FloatArray,
    drift_mean: FloatArray,
    drift_var: FloatArray,
    bound: Callable[[FloatArray, NDArray[np.intp]], FloatArray] | None = None,
) -> tuple[FloatArray, FloatArray]:
    """The prior feature of each child (piece[c] at rotation[c], its source at source[c],
    the end of states[parent[c]], with the hidden displacement drift_mean[c] and
    drift_var[c] up to it), as :func:`_extend` computes it: rotation costs and position
    costs (see :func:`_anchor`), the least over the frame's quarter turns; and the position
    costs per quarter turn (C, 4).

    ``bound``: the bound of children (indices) given their prior feature. A child whose
    bound reaches the search's threshold even with its parent's position costs (lower
    bounds) is cut whatever its own are (the threshold never rises), so they are not
    fitted: its prior feature and costs are then those bounds."""
    rotation_prior = np.array([s.rotation_prior for s in states]).reshape(-1, 4)
    costs = rotation_prior[parent] + search.turned_rotation_cost[piece, rotation]
    position = np.array([s.position for s in states]).reshape(-1, 4)[parent]
    anchored = np.array([len(s.anchors) for s in states], dtype=np.intp)
    chosen = np.flatnonzero(search.has_prior[piece] & (anchored[parent] > 0))
    threshold = search.threshold()
    if bound is not None and len(chosen) and threshold < np.inf:
        least = (costs[chosen] + position[chosen]).min(axis=1)
        chosen = chosen[bound(least, chosen) < threshold]
    if len(chosen):
        # Every child's anchors in one (m, k + 1, 5) batch: a state's own anchors, rows of
        # zero weight (which cost nothing and move no fit) up to the most any state has,
        # then the child's.
        placed = np.zeros((len(states), int(anchored.max()), 5))
        for k, state in enumerate(states):
            placed[k, : len(state.anchors)] = state.anchors
        new = _anchor_rows(
            search, piece[chosen], source[chosen], drift_mean[chosen], drift_var[chosen]
        )
        anchors = np.concatenate([placed[parent[chosen]], new[:, None]], 1)
        position[chosen] = _least_position_costs(anchors, costs[chosen], position[chosen])
    return (costs + position).min(axis=1), position


def _least_position_costs(
    anchors: FloatArray, rotation: FloatArray, below: FloatArray
) -> FloatArray:
    """Position costs (m, 4) of m anchor sets (m, k, 5), exact wherever the least total over
    the frame's quarter turns may be: rotation costs (m, 4) plus position costs, of which
    ``below`` (the parents') are lower bounds (adding an anchor never lowers a cost).

    A quarter turn whose rotation cost and lower bound already reach an exact total keeps
    the bound: the least total is then the same as with every cost exact, and a later
    anchor's costs start from bounds again. The priors' 20 degrees rule out three quarter
    turns within a few pieces, so this is mostly one fit in four."""
    rows = np.arange(len(anchors))
    out = below.copy()
    first = np.argmin(rotation + below, axis=1)
    out[rows, first] = position_costs_batch(anchors, first)
    best = rotation[rows, first] + out[rows, first]
    may_be_least = rotation + below < best[:, None]
    may_be_least[rows, first] = False  # fitted already
    again, quarter = np.nonzero(may_be_least)
    if len(again):
        out[again, quarter] = position_costs_batch(anchors[again], quarter)
    return out


def _root(search: _Search) -> _State:
    """The search's root: the first piece fixed at the origin with rotation 0."""
    first = search.pieces[0]
    pts, walls, samples = first.rotated[0]
    trimmed = _trim_start(walls, pts[0], search.params.closure_overshoot)
    rotation_prior = search.turned_rotation_cost[0, 0].copy()
    features = np.zeros(len(FEATURES))
    features[_F["prior"]] = rotation_prior.min()
    return _State(
        order=(0,),
        rotations=(0,),
        sources=np.zeros((1, 2)),
        end=pts[-1].copy(),
        heading=first.directions[-1],
        turning=first.turning,
        features=features,
        mean=np.zeros(2),
        var=np.full(2, search.open_var),
        walls=trimmed,
        vertices=pts.copy(),
        samples=samples,
        drift_means=np.zeros((1, 2)),
        drift_vars=np.full((1, 2), search.open_var),
        owners=np.zeros(len(samples), dtype=np.intp),
        box=first.sample_boxes[0],
        free_at=(first.rotated_free[0].box,),  # the first source is the origin
        rotation_prior=rotation_prior,
        anchors=tuple(
            a for a in (_anchor(search, 0, np.zeros(2), np.zeros(2), np.zeros(2)),) if a is not None
        ),
    )


def place_pieces(
    pieces: Sequence[Piece],
    params: PlacementParams = PlacementParams(),
    hints: SiteHints | None = None,
) -> Placement | None:
    """Find the lowest-energy placements of the pieces in one counter-clockwise loop.

    Parameters
    ----------
    pieces : chains with at least one wall each; the first is fixed (rotation 0, loop
        position 0, source at the site origin), which removes the global symmetry. With
        prior poses, put a piece that has one first.
    params : energy weights, the displacement model, top-k and the node budget.
    hints : prior poses and pair constraints, by piece id.

    Returns
    -------
    Placement or None when no placement exists (not even an open one).

    With prior poses the search scores them in a hints frame whose yaw the priors alone
    tell only modulo a quarter turn, which a wide yaw prior (20 degrees) blurs: their
    estimate is then sometimes 20-30 degrees off, and every prior is read turned by that.
    The best closed loop found knows each piece's quarter turn, so it tells the yaw without
    that ambiguity: when it differs by more than ``params.frame_refit_deg``, the pieces are
    searched again in the refitted frame (up to three times, each search starting from the
    loops the last one found; within ``params.restart_nodes`` when the first was cut
    short), and the placement of lower energy is kept: the frame's yaw is fitted with the
    assembly, as its shift already is.
    """
    if not pieces:
        return None
    hints = hints or SiteHints()
    placement, search = _place(pieces, params, hints, None, None)
    if placement is None or search is None:
        return None
    for _ in range(_FRAME_REFITS):
        if not placement.closed or search.frame is None:
            break
        yaw = loop_frame_yaw(pieces, placement.best, hints)
        # The frame's quarter turn is the assembly's to choose: compare modulo one.
        change = wrap_angle(4.0 * (yaw - search.frame.yaw)) / 4.0
        if abs(change) <= math.radians(params.frame_refit_deg):
            break
        evidence = search.pair_evidence(range(len(pieces)))
        # A search cut short is searched again within the restart budget: it starts from
        # the loops already found, and a site of many pieces would spend the full budget
        # on every pass.
        budget = params
        if not placement.exhaustive:
            budget = params.model_copy(update={"max_search_nodes": params.restart_nodes})
        refit, again = _place(pieces, budget, hints, yaw, evidence, placement.candidates)
        if refit is None or again is None or not refit.closed:
            break
        nodes = placement.nodes_searched + refit.nodes_searched
        if refit.best.energy >= placement.best.energy:
            placement = replace(placement, nodes_searched=nodes)
            break
        placement, search = replace(refit, nodes_searched=nodes), again
    return placement


_FRAME_REFITS = 3  # searches again in a frame refitted from the best loop, at most


def loop_frame_yaw(pieces: Sequence[Piece], cand: PlacementCandidate, hints: SiteHints) -> float:
    """The hints frame's yaw at which a closed loop's priors cost least (its pieces' quarter
    turns and sources in the site frame, :func:`priors.frame_yaw_fit`)."""
    rotations = dict(zip(cand.order, cand.rotations, strict=True))
    sources = dict(zip(cand.order, translations_of(pieces, cand), strict=True))
    return frame_yaw_fit(hints.priors, rotations, sources)


def _place(
    pieces: Sequence[Piece],
    params: PlacementParams,
    hints: SiteHints,
    frame_yaw: float | None,
    evidence: _PairEvidence | None,
    known: Sequence[PlacementCandidate] = (),
) -> tuple[Placement | None, _Search | None]:
    """One search of the pieces, closed loops first, then open chains if none closes, with
    the hints frame at ``frame_yaw`` (None: the priors' estimate); also the search whose
    placements these are. ``known``: closed loops of an earlier search, scored in this one
    before it starts, so that it prunes against them from its first node."""
    n = len(pieces)
    search, nodes = _closed_then_open(pieces, params, hints, frame_yaw, evidence, known)
    if not search.top:
        return None, None
    if search.require_closed and search.truncated and search.frame is None:
        for j in _restart_roots(n, params.restart_roots):
            nodes += _restart(search, j)
    found = [c for _, _, c in search.top]
    if search.require_closed:
        found = [_with_outside(search, c) for c in found]
        if search.truncated:
            # An exhaustive search's best is optimal; one cut short may have passed loops a
            # move away from it that are better still.
            polished = _polish(search, min(found, key=lambda c: c.energy))
            seen = {(c.order, c.rotations) for c in polished}
            found = polished + [c for c in found if (c.order, c.rotations) not in seen]
    nodes += search.nodes
    ranked = sorted(found, key=lambda c: c.energy)
    placement = Placement(
        best=ranked[0],
        translations=translations_of(pieces, ranked[0]),
        alternatives=tuple(ranked[1:]),
        nodes_searched=nodes,
        exhaustive=not search.truncated,
        closed=search.require_closed,
        measured=search.measured,
        frame_yaw=None if search.frame is None else search.frame.yaw,
    )
    return placement, search


def _closed_then_open(
    pieces: Sequence[Piece],
    params: PlacementParams,
    hints: SiteHints,
    frame_yaw: float | None,
    evidence: _PairEvidence | None,
    known: Sequence[PlacementCandidate],
) -> tuple[_Search, int]:
    """The search for closed loops (``known`` scored first), or for open chains when no
    loop closes; and the nodes a closed search that found nothing spent."""
    nodes = 0
    search = None
    for require_closed in (True, False):
        # The open search (partial chains, when no closed loop was found) has a budget of
        # its own: what the closed one spent must not leave nothing to place.
        if search is not None:
            evidence = search.pair_evidence(range(len(pieces)))
        search = _Search(list(pieces), params, hints, require_closed, evidence, frame_yaw)
        if require_closed:
            for cand in known:
                order = [search.index[i] for i in cand.order]
                state = _placed_loop(search, order, cand.rotations, cand.shared)
                if state is not None:
                    _close(search, state)
        _explore(search)
        if search.top:
            break
        nodes += search.nodes
    assert search is not None
    return search, nodes


def _explore(search: _Search) -> None:
    """Search from the first piece within the node budget (see the module's docstring)."""
    n, params = len(search.pieces), search.params
    root = _root(search)
    if search.require_closed and params.beam_width > 0:
        # A beam over the loop positions finds good loops of many pieces early and evenly;
        # the depth-first passes then prune against them. It spends at most half the node
        # budget, so that a site of many pieces still ends with closed loops, and narrows
        # for small sites, whose depth-first search finishes anyway.
        width = min(
            params.beam_width // 3 ** max(0, params.large_site_pieces - n),
            params.max_search_nodes // (2 * max(n - 1, 1)),
        )
        _beam(search, root, max(width, 1))
    # Iterative broadening: cheap passes that follow only the most promising children
    # spread good incumbents over the whole tree, so the full pass prunes early.
    for breadth in (*_BROADENING, None):
        search.breadth = breadth
        _dfs(search, root, tuple(range(1, n)))
        if search.truncated:
            break


def _restart_roots(n: int, count: int) -> list[int]:
    """The pieces (indices) other searches start from: ``count`` spread evenly over the
    others."""
    return sorted({round(k * n / (count + 1)) for k in range(1, count + 1)} - {0})


def _restart(search: _Search, j: int) -> int:
    """Search the loop again starting from piece j (rotation 0 there) within the restart
    budget, and record what it found in ``search``, turned and shifted so that its first
    piece leads at rotation 0. Returns the nodes the other search spent.

    A search cut short keeps the partial loops its first junctions favour; where those
    mislead, a search entering the loop elsewhere does not share the same prefixes. Each
    loop is placed again in ``search`` (its nodes count there): pieces are laid end to end
    from the first, so the loop's closing gap, where walls are tested for crossing and
    pieces for conflicts, lies before another piece and the energy may differ (a loop
    whose walls then cross is dropped)."""
    led = [j, *(k for k in range(len(search.pieces)) if k != j)]  # piece j first
    pieces = [search.pieces[k] for k in led]
    params = search.params.model_copy(update={"max_search_nodes": search.params.restart_nodes})
    other = _Search(pieces, params, search.hints, True, search.pair_evidence(led))
    _explore(other)
    index, first = search.index, search.pieces[0].id
    for _, _, cand in sorted(other.top, key=lambda item: (-item[0], item[1])):
        k = cand.order.index(first)
        order = [index[fid] for fid in (*cand.order[k:], *cand.order[:k])]
        turns = cand.rotations[k:] + cand.rotations[:k]
        rotations = [(r - turns[0]) % 4 for r in turns]
        state = _placed_loop(search, order, rotations, cand.shared[k:] + cand.shared[:k])
        if state is not None:
            _close(search, state)
    return other.nodes


def _placed_loop(
    search: _Search, order: Sequence[int], rotations: Sequence[int], shared: Sequence[int] = ()
) -> _State | None:
    """The state of the pieces ``order`` (indices, the first piece first) at quarter turns
    ``rotations`` laid end to end (``shared``: see :attr:`PlacementCandidate.shared`; the
    closing junction's is the leaf's to choose), or None where a junction folds back or
    cannot share its corner, or walls cross."""
    root = _root(search)
    laid = _laid_after(search, root, order[1:], rotations[1:], shared[1:])
    return None if laid is None else (laid[-1] if laid else root)


def _laid_after(
    search: _Search,
    state: _State,
    order: Sequence[int],
    rotations: Sequence[int],
    shared: Sequence[int] = (),
) -> list[_State] | None:
    """The states of the pieces ``order`` (indices) at quarter turns ``rotations`` laid end
    to end after ``state`` (``shared``: per piece, how many corners it shares with the one
    before; empty: none), one per piece (each a search node), or None where a junction
    folds back or cannot share its corners, or walls cross."""
    laid = []
    shared = shared or (0,) * len(order)
    for j, rotation, at_corner in zip(order, rotations, shared, strict=True):
        extended = _extend_to(search, state, j, rotation, at_corner)
        if extended is None:
            return None
        laid.append(extended)
        state = extended
    return laid


def _polish(search: _Search, start: PlacementCandidate) -> list[PlacementCandidate]:
    """Local search from ``start`` (a closed loop with its ``outside`` counted): the best
    loop one move away (:func:`_moves`) while it is better, within the search's polish
    budget of pieces placed. Returns the better loops found (``outside`` counted); every
    loop placed is also recorded like a leaf of the search.

    Moves are tried in order of a lower bound of their energy (:func:`_loop_bounds`): one
    that cannot beat the best so far is never placed, and most cannot. A junction the move
    leaves alone keeps its shared corner; the bound leaves shared corners out."""
    index = search.index
    order = np.array([index[fid] for fid in start.order], dtype=np.intp)
    rotations = np.array(start.rotations, dtype=np.intp)
    shared = list(start.shared) or [0] * len(order)
    budget = search.nodes + search.params.polish_nodes
    best, better = start, []
    while search.nodes < budget:
        orders, turned = _moves(order, rotations)
        bounds = _loop_bounds(search, orders, turned)
        root = _root(search)
        laid = _laid_after(search, root, order[1:].tolist(), rotations[1:].tolist(), shared[1:])
        assert laid is not None  # a loop found before: its walls do not cross
        placed = zip(order[:-1].tolist(), rotations[:-1].tolist(), strict=True)
        kept = {
            (*key, int(order[k]), int(rotations[k])): shared[k]
            for k, key in enumerate(placed, 1)
            if shared[k]
        }
        prefix = [root, *laid]  # the current loop's states, one per piece placed
        moved = None
        for c in np.argsort(bounds, kind="stable").tolist():
            if bounds[c] >= best.energy or search.nodes >= budget:
                break
            first = int(np.flatnonzero((orders[c] != order) | (turned[c] != rotations))[0])
            pairs = zip(
                orders[c, first - 1 : -1].tolist(), turned[c, first - 1 : -1].tolist(), strict=True
            )
            flags = [
                kept.get((*pair, int(orders[c, k]), int(turned[c, k])), 0)
                for k, pair in enumerate(pairs, first)
            ]
            laid = _laid_after(
                search,
                prefix[first - 1],
                orders[c, first:].tolist(),
                turned[c, first:].tolist(),
                flags,
            )
            leaf = None if laid is None else _leaf(search, laid[-1])  # None: walls cross
            if leaf is None:
                continue
            search.record(leaf)
            leaf = _with_outside(search, leaf)
            if leaf.energy < best.energy:
                best, moved = leaf, c
        if moved is None:
            break
        better.append(best)
        order, rotations = orders[moved], turned[moved]
        shared = list(best.shared) or [0] * len(order)
    return better


def _extend_to(
    search: _Search, state: _State, j: int, rotation: int, shared: int = 0
) -> _State | None:
    """:func:`_extend` with piece j at a given quarter turn (counted as a search node),
    sharing ``shared`` corners with the last piece; None where its junction would fold
    back, or cannot share those corners."""
    search.nodes += 1
    heading_change = (rotation + search.pieces[j].directions[0] - state.heading) % 4
    if shared:
        turn = int(search.shared_turn[j, shared])
        if not search.sharing[state.order[-1], j, shared] or heading_change != turn % 4:
            return None
        return _extend(search, state, j, turn, shared=shared)
    turn = int(_TURN_OF[heading_change])
    return None if turn == 2 else _extend(search, state, j, turn)


def _moves(
    order: NDArray[np.intp], rotations: NDArray[np.intp]
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Every loop one move away from (order, rotations) (piece indices and quarter turns,
    loop order): a piece other than the first moved to any other place in the loop (or
    left where it is) at any quarter turn, the piece after it there at any quarter turn
    too. Returns (C, n) orders and rotations, each loop once, sorted, the given one left
    out; many are no loop at all (:func:`_loop_bounds` tells)."""
    n = len(order)
    axes = np.meshgrid(np.arange(1, n), np.arange(1, n), np.arange(4), np.arange(4), indexing="ij")
    moved, place, turn, next_turn = (a.ravel() for a in axes)
    k = np.arange(n)[None, :]
    # Position k of the new loop takes the old loop's piece: the moved one at its place,
    # the others in their order around it.
    rest = np.where(k < place[:, None], k, k - 1)
    source = np.where(rest < moved[:, None], rest, rest + 1)
    source = np.where(k == place[:, None], moved[:, None], source)
    new_order, new_rotations = order[source], rotations[source]
    rows = np.arange(len(moved))
    new_rotations[rows, place] = turn
    followed = place + 1 < n  # the first piece, after the last place, keeps its turn
    new_rotations[rows[followed], place[followed] + 1] = next_turn[followed]
    keep = followed | (next_turn == 0)
    loops = np.unique(np.concatenate([new_order, new_rotations], axis=1)[keep], axis=0)
    loops = loops[(loops != np.concatenate([order, rotations])).any(axis=1)]
    return loops[:, :n], loops[:, n:]


def _loop_bounds(
    search: _Search, orders: NDArray[np.intp], rotations: NDArray[np.intp]
) -> FloatArray:
    """(C,) a lower bound of each loop's energy (pieces and quarter turns (C, n), loop
    order), inf where they make no closed loop (a junction folds back, or the turns do not
    add up to one full turn): its turns, junctions, closure and priors as :func:`_extend`
    and :func:`_close` add them up, and the least hull. Walls crossing, free space and hint
    pairs are left out: each adds nothing or more."""
    heading_in = (search.first_direction[orders] + rotations) % 4  # of each piece's first wall
    heading_out = (search.last_direction[orders] + rotations) % 4  # and of its last
    before = heading_out  # junction k joins piece k to piece k + 1 (the last to the first)
    after = np.roll(heading_in, -1, axis=1)
    turns = _TURN_OF[(after - before) % 4]
    closed = (np.abs(turns) < 2).all(axis=1)
    closed &= turns.sum(axis=1) + search.turning[orders].sum(axis=1) == 4
    step = search.step[before, after]  # (C, n, 2 (mean, variance), 2)
    mean, var = step[:, :, 0].sum(axis=1), step[:, :, 1].sum(axis=1) + search.open_var
    end = search.chain_ends[orders, rotations].sum(axis=1)
    closure = 0.5 * (np.square(end + mean) / var + np.log(var)).sum(axis=1)
    junctions = search.junction[orders, np.roll(orders, -1, axis=1)].sum(axis=1)
    weights = search.weights
    bound = weights[_F["turns"]] * (turns != 0).sum(axis=1) + junctions
    bound += weights[_F["closure"]] * closure + weights[_F["hull"]] * 4
    out: FloatArray = np.where(closed, bound, np.inf)
    if search.frame is not None and closed.any():
        out[closed] += weights[_F["prior"]] * _loop_priors(
            search, orders[closed], rotations[closed], step[closed]
        )
    return out


def _loop_priors(
    search: _Search, orders: NDArray[np.intp], rotations: NDArray[np.intp], step: FloatArray
) -> FloatArray:
    """(C,) the prior feature of each loop (C, n), as :func:`_extend` adds it up: rotation
    costs plus position costs (:func:`_anchor_rows`), the least over the frame's quarter
    turns; step (C, n, 2, 2): each junction's displacement, mean and variance per axis."""
    rotation = search.turned_rotation_cost[orders, rotations].sum(axis=1)  # (C, 4)
    with_prior = search.has_prior[orders]  # the same count in every loop: all pieces
    if with_prior.sum(axis=1).max(initial=0) < 2:
        return np.asarray(rotation.min(axis=1), dtype=np.float64)
    # Each piece's source where the loop puts it end to end, and the hidden displacement
    # of the junctions before it.
    sources = np.cumsum(search.chain_ends[orders, rotations], axis=1)
    sources = np.concatenate([np.zeros_like(sources[:, :1]), sources[:, :-1]], axis=1)
    drift = np.cumsum(step, axis=1)
    drift = np.concatenate([np.zeros_like(drift[:, :1]), drift[:, :-1]], axis=1)
    rows, places = np.nonzero(with_prior)
    anchors = _anchor_rows(
        search,
        orders[rows, places],
        sources[rows, places],
        drift[rows, places, 0],
        drift[rows, places, 1],
    ).reshape(len(orders), -1, 5)
    least: FloatArray = (rotation + position_costs_batch(anchors)).min(axis=1)
    return least


def _with_outside(search: _Search, cand: PlacementCandidate) -> PlacementCandidate:
    """The closed candidate with the floor its pieces saw outside its loop counted in.

    Scored on the assemblies the search keeps, not inside it: the term is known only once
    the loop closes, so in the search it would only widen the gap between the children's
    bounds and the leaves, and prune less. Scoring every closed loop a large site's search
    reaches instead found no room more right on the benchmark's 9-16 fragment scenes and
    took up to half as long again."""
    weight = float(search.weights[_F["outside"]])
    if cand.missing or weight == 0.0:
        return cand
    order = tuple(search.index[fid] for fid in cand.order)
    sources = tuple(translations_of(search.pieces, cand))
    area = _outside(search, order, cand.rotations, sources, cand.shared)
    features = {**cand.features, "outside": area}
    return replace(cand, energy=cand.energy + weight * area, features=features)


def _outside(
    search: _Search,
    order: Sequence[int],
    rotations: Sequence[int],
    sources: Sequence[FloatArray],
    shared: Sequence[int] = (),
) -> float:
    """The ``outside`` feature of a closed loop: the pieces (indices, quarter turns, sources
    in loop order; ``shared``: see :attr:`PlacementCandidate.shared`) with the floor they
    saw. At a shared corner the loop goes from the corner on along the later piece: the
    earlier piece's target and the later one's source, either side of it, would cut the
    corner off."""
    cells, loop = [], []
    n = len(order)
    shared = shared or (0,) * n
    for k, (j, rotation, source) in enumerate(zip(order, rotations, sources, strict=True)):
        piece = search.pieces[j]
        cells.append(piece.rotated_free_centres[rotation] + source)
        first = shared[k]  # the points before its last shared corner lie on the last piece
        last = len(piece.keypoints) - (1 if shared[(k + 1) % n] else 0)
        loop.append(piece.rotated[rotation][0][first:last] + source)
    params = search.params
    cell = search.pieces[0].free.cell
    return outside_area(
        cells, cell, np.concatenate(loop), params.outside_margin, params.outside_cap
    )


def translations_of(pieces: Sequence[Piece], cand: PlacementCandidate) -> FloatArray:
    """(n, 2) site position of each piece's source after end-to-end concatenation (a piece
    that joins at a shared corner with that corner on the last piece's)."""
    by_id: Mapping[str, Piece] = {p.id: p for p in pieces}
    end = np.zeros(2)
    out = []
    shared = cand.shared or (0,) * len(cand.order)
    for k, (fid, rotation) in enumerate(zip(cand.order, cand.rotations, strict=True)):
        if k and shared[k]:
            prev, prev_rotation = by_id[cand.order[k - 1]], cand.rotations[k - 1]
            end = end + corner_shift(prev, prev_rotation, by_id[fid], rotation, shared[k])
        out.append(end.copy())
        end = end + by_id[fid].keypoints[-1] @ rot90(rotation).T
    return np.asarray(out).reshape(-1, 2)


def evaluate_placement(
    pieces: Sequence[Piece],
    order: Sequence[str],
    rotations: Sequence[int],
    params: PlacementParams = PlacementParams(),
    hints: SiteHints | None = None,
    frame_yaw: float | None = None,
    shared: Sequence[int] | None = None,
) -> PlacementCandidate | None:
    """Energy of one given closed placement, or None when it is not a valid closed loop.

    The same energy the search minimises; used to check the search against brute force,
    to score the truth in benchmarks and a placement a user proposes. frame_yaw: the hints
    frame's yaw to score prior poses in (:attr:`Placement.frame_yaw`); None: the priors'
    own estimate. shared: how many corners each junction shares (see
    :attr:`PlacementCandidate.shared`); None: the placement of least energy over every
    choice the pieces allow (at most ``_EVALUATED_SHARES`` junctions are tried every way).
    """
    by_id = {p.id: i for i, p in enumerate(pieces)}
    if order[0] != pieces[0].id or rotations[0] != 0 or sorted(order) != sorted(by_id):
        return None
    search = _Search(list(pieces), params, hints or SiteHints(), True, None, frame_yaw)
    led = [by_id[fid] for fid in order]
    if shared is not None:
        choices: list[Sequence[int]] = [shared]
    else:
        may = [k for k in range(1, len(led)) if search.sharing[led[k - 1], led[k]].any()]
        may = may[:_EVALUATED_SHARES]
        ways = [[0, *np.flatnonzero(search.sharing[led[k - 1], led[k]]).tolist()] for k in may]
        choices = []
        for picked in itertools.product(*ways):
            chosen = [0] * len(led)
            for k, corners in zip(may, picked, strict=True):
                chosen[k] = corners
            choices.append(chosen)
    best = None
    for flags in choices:
        state = _placed_loop(search, led, rotations, flags)
        leaf = None if state is None else _leaf(search, state)
        if leaf is not None:
            leaf = _with_outside(search, leaf)
            if best is None or leaf.energy < best.energy:
                best = leaf
    return best


_EVALUATED_SHARES = 8  # junctions evaluate_placement tries both ways, at most
