"""Global placement: a rotation and a loop position for every fragment (paper 3.2).

Each fragment's wall chain is a piece of the room's counter-clockwise boundary loop. The
pieces are concatenated end to end (source of one at the target of the previous); a
placement chooses their order and each piece's rotation (one of four after up alignment).
The energy is E_l + E_c + E_b: layout complexity (corners plus convex-hull edges), closure
gap (Manhattan distance, meters) and boundary mismatch between neighbours.

Search is depth-first branch and bound. What a simple rectilinear counter-clockwise loop
implies cuts the tree: a junction continues the wall or turns by 90 degrees (never folds
back), so a rotation follows from the junction's turn; the turns of the loop add up to one
full turn (+4 quarter turns); walls may not cross or overlap; and the closure gap can only
shrink by as much as the pieces still to place can reach, direction by direction. Quick
first passes that expand only the best one, two, three children per node (iterative
broadening) find good loops across the whole tree before the full pass, whose pruning then
starts tight.
"""

from __future__ import annotations

import heapq
import itertools
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree
from scipy.special import erf

from schemas.params import PlacementParams
from services.geometry import distance_to_polygon, points_in_polygon
from services.types import FloatArray, LocalLayout

__all__ = [
    "Piece",
    "Placement",
    "PlacementCandidate",
    "evaluate_placement",
    "make_piece",
    "place_pieces",
    "rot90",
]

_TURNS = (0, 1, -1)  # continue, turn left (convex corner), turn right (concave corner)
_CROSS_EPS = 0.05  # m, walls may touch within this distance but not cross
_UNPLACED_PENALTY = 100.0  # energy per piece left out of an open chain
_HULL_TOLERANCE = 0.35  # m, hull vertices closer than this to their chord are dropped
# Directions u (max-norm 1) of the closure bound: the gap left is at least u . (-end) less
# what the pieces still to place can reach along u (L1 distance to a convex set, by duality).
_CLOSURE_DIRECTIONS = np.array(
    [d for t in (-1.0, -0.5, 0.0, 0.5) for d in ((1.0, t), (-1.0, -t), (-t, 1.0), (t, -1.0))]
)
_BROADENING = (1, 2, 3)  # children per node in the search's quick first passes
_MAX_FOOTPRINT_CELLS = 128  # per piece, for the outside-share term
_BEHIND_WALL = 0.3  # m, footprint cells further behind the piece's own wall are dropped


def rot90(quarter_turns: int) -> FloatArray:
    """2x2 rotation by ``quarter_turns`` * 90 degrees counter-clockwise."""
    c, s = [(1, 0), (0, 1), (-1, 0), (0, -1)][quarter_turns % 4]
    return np.array([[c, -s], [s, c]], dtype=np.float64)


def _direction_index(v: FloatArray) -> int:
    """0: +x, 1: +y, 2: -x, 3: -y for an axis-parallel vector."""
    if abs(v[0]) >= abs(v[1]):
        return 0 if v[0] > 0 else 2
    return 1 if v[1] > 0 else 3


@dataclass(frozen=True)
class Piece:
    """One fragment's chain prepared for placement, aligned frame with the source at 0.

    keypoints: (K, 2) float64, source first (at the origin), interior on the left.
    directions: (K-1,) int, direction index of each wall.
    source_boundary, target_boundary: (M, 3) float64, boundary points relative to the
    source / target keypoint, floor at z = 0.
    footprint: (F, 2) float64, scanned floor-plan cells relative to the source.
    """

    id: str
    keypoints: FloatArray
    directions: tuple[int, ...]
    source_boundary: FloatArray
    target_boundary: FloatArray
    footprint: FloatArray

    @cached_property
    def turning(self) -> int:
        """Signed quarter turns inside the chain (left +1, right -1)."""
        steps = np.diff(np.asarray(self.directions)) % 4
        return int(np.sum(steps == 1) - np.sum(steps == 3))

    @cached_property
    def corners(self) -> int:
        return len(self.keypoints) - 2

    @cached_property
    def reach(self) -> FloatArray:
        """(D,) support of the piece's source->target vector over its four rotations, in
        each of the closure bound's directions: how far it can move the loop's end."""
        ends = np.stack([rot90(r) @ self.keypoints[-1] for r in range(4)])
        support: FloatArray = (_CLOSURE_DIRECTIONS @ ends.T).max(axis=1)
        return support

    @cached_property
    def rotated_footprint(self) -> tuple[FloatArray, ...]:
        """Per quarter turn r: the footprint cells rotated by r."""
        return tuple(self.footprint @ rot90(r).T for r in range(4))

    @cached_property
    def rotated(self) -> tuple[tuple[FloatArray, FloatArray], ...]:
        """Per quarter turn r: the rotated keypoints and their walls (see ``_walls``)."""
        out = []
        for r in range(4):
            pts = self.keypoints @ rot90(r).T
            out.append((pts, _walls(pts)))
        return tuple(out)


def make_piece(fragment_id: str, layout: LocalLayout) -> Piece:
    """Prepare a local layout (with at least one wall) for placement."""
    kp = layout.keypoints - layout.keypoints[0]
    dirs = tuple(_direction_index(d) for d in np.diff(kp, axis=0))
    floor = np.array([0.0, 0.0, layout.frame.floor_z])
    src = layout.source_boundary - np.concatenate([layout.keypoints[0], [0.0]]) - floor
    tgt = layout.target_boundary - np.concatenate([layout.keypoints[-1], [0.0]]) - floor
    footprint = _in_front_of_walls(layout.footprint, layout.keypoints) - layout.keypoints[0]
    # The outside share is scored at every search leaf that could win: a spread sample of
    # the cells estimates it well enough.
    stride = max(1, -(-len(footprint) // _MAX_FOOTPRINT_CELLS))
    return Piece(fragment_id, kp, dirs, src, tgt, footprint[::stride])


def _in_front_of_walls(cells: FloatArray, keypoints: FloatArray) -> FloatArray:
    """The cells not behind one of the chain's own walls.

    Space a scan saw behind its own walls (through a door or window) is outside the room by
    the scan's own evidence: it cannot tell one placement from another, so it is left out.
    """
    if len(cells) == 0 or len(keypoints) < 2:
        return cells
    start, end = keypoints[:-1], keypoints[1:]
    along = end - start
    length = np.linalg.norm(along, axis=1)
    unit = along / np.maximum(length, 1e-9)[:, None]
    rel = cells[:, None, :] - start[None]
    t = (rel * unit[None]).sum(-1)
    left = unit[None, :, 0] * rel[..., 1] - unit[None, :, 1] * rel[..., 0]
    behind = (t > 0) & (t < length[None]) & (left < -_BEHIND_WALL)
    kept: FloatArray = cells[~behind.any(axis=1)]
    return kept


@dataclass(frozen=True)
class PlacementCandidate:
    """A complete placement and its energy terms."""

    energy: float
    order: tuple[str, ...]
    rotations: tuple[int, ...]  # quarter turns per piece, in loop order
    complexity: float
    closure: float
    boundary: float
    free_space: float = 0.0


@dataclass(frozen=True)
class Placement:
    """The best placement, its translations, and the runners-up.

    translations: (n, 2) float64, site position of each piece's source, loop order.
    closed: True when the pieces form one simple counter-clockwise loop (turns add up to a
    full turn); the gap left at its end is closed by the refinement.
    """

    best: PlacementCandidate
    translations: FloatArray
    alternatives: tuple[PlacementCandidate, ...]
    nodes_searched: int
    exhaustive: bool
    closed: bool


def _boundary_mismatch(a: Piece, b: Piece, params: PlacementParams) -> float:
    """Supplementary's mismatch score of b's head placed after a's tail.

    Each cross-section is read in its own cutting plane: offset from its own wall towards
    the interior, and height. A junction that turns (the cut fell at a corner) compares the
    two profiles the same way as a straight one; the corner itself is priced by E_l.
    """
    if min(len(a.target_boundary), len(b.source_boundary)) < params.min_boundary_points:
        return 0.5
    # Each piece's end wall along +x, the chain end at the origin, the interior towards +y.
    ra = rot90(-a.directions[-1])
    rb = rot90(-b.directions[0])
    pa = np.column_stack([a.target_boundary[:, :2] @ ra.T, a.target_boundary[:, 2]])
    pb = np.column_stack([b.source_boundary[:, :2] @ rb.T, b.source_boundary[:, 2]])
    # Compare the cross-sections in the cutting plane (offset from the wall, height): the
    # distance along the wall within the band is sampling, not shape.
    d_ab, _ = cKDTree(pb[:, 1:]).query(pa[:, 1:])
    d_ba, _ = cKDTree(pa[:, 1:]).query(pb[:, 1:])
    # Phi(d/sigma) - Phi(-d/sigma) = erf(d / (sigma sqrt 2)).
    scores = erf(np.concatenate([d_ab, d_ba]) / (params.boundary_sigma * np.sqrt(2.0)))
    return float(scores.mean())


def _hull_edges(points: FloatArray) -> int:
    """Edges of the convex hull (collinear points dropped), monotone chain."""
    pts = np.unique(np.round(points, 3), axis=0)
    if len(pts) < 3:
        return len(pts)

    def half(seq: FloatArray) -> list[FloatArray]:
        out: list[FloatArray] = []
        for p in seq:
            while len(out) >= 2:
                o, a = out[-2], out[-1]
                if (a[0] - o[0]) * (p[1] - o[1]) - (a[1] - o[1]) * (p[0] - o[0]) > 1e-9:
                    break
                out.pop()
            out.append(p)
        return out

    hull = np.array(half(pts)[:-1] + half(pts[::-1])[:-1])
    # Unrefined chains leave small gaps; a hull vertex barely off the line through its
    # neighbours is such a gap, not an edge of the room.
    while len(hull) > 3:
        prev, nxt = np.roll(hull, 1, axis=0), np.roll(hull, -1, axis=0)
        chord = nxt - prev
        lever = hull - prev
        off = np.abs(chord[:, 0] * lever[:, 1] - chord[:, 1] * lever[:, 0])
        off /= np.maximum(np.linalg.norm(chord, axis=1), 1e-9)
        weakest = int(np.argmin(off))
        if off[weakest] >= _HULL_TOLERANCE:
            break
        hull = np.delete(hull, weakest, axis=0)
    return len(hull)


@dataclass
class _Search:
    pieces: list[Piece]
    params: PlacementParams
    mismatch: list[list[float]]  # [a][b]: boundary mismatch of b following a
    successor: dict[int, int]
    predecessor: dict[int, int]
    require_closed: bool
    reach: FloatArray = field(init=False)  # (n, D) each piece's reach (Piece.reach)
    top: list[tuple[float, int, PlacementCandidate]] = field(default_factory=list)
    deadline: float = float("inf")
    breadth: int | None = None  # children expanded per node; None: all
    truncated: bool = False
    nodes: int = 0
    counter: itertools.count[int] = field(default_factory=itertools.count)

    def __post_init__(self) -> None:
        self.reach = np.array([p.reach for p in self.pieces]).reshape(len(self.pieces), -1)

    def out_of_budget(self) -> bool:
        """True once the node or time budget is spent (the best so far is then returned)."""
        if self.nodes >= self.params.max_search_nodes or (
            self.nodes % 256 == 0 and time.monotonic() > self.deadline
        ):
            self.truncated = True
        return self.truncated

    def weights(self) -> tuple[float, float, float]:
        p = self.params
        return (float(p.use_complexity), float(p.use_closure), float(p.use_boundary))

    def bound(self) -> float:
        if len(self.top) < self.params.top_k:
            return np.inf
        return -self.top[0][0]

    def record(self, cand: PlacementCandidate) -> None:
        if any(c.order == cand.order and c.rotations == cand.rotations for _, _, c in self.top):
            return  # found again by a later, wider pass
        item = (-cand.energy, next(self.counter), cand)
        if len(self.top) < self.params.top_k:
            heapq.heappush(self.top, item)
        elif cand.energy < -self.top[0][0]:
            heapq.heapreplace(self.top, item)


def _walls(points: FloatArray) -> FloatArray:
    """(W, 4) rows (axis, offset, lo, hi) of an axis-parallel chain."""
    a, b = points[:-1], points[1:]
    along_x = np.abs(b[:, 0] - a[:, 0]) >= np.abs(b[:, 1] - a[:, 1])
    offset = np.where(along_x, a[:, 1], a[:, 0])
    lo = np.where(along_x, np.minimum(a[:, 0], b[:, 0]), np.minimum(a[:, 1], b[:, 1]))
    hi = np.where(along_x, np.maximum(a[:, 0], b[:, 0]), np.maximum(a[:, 1], b[:, 1]))
    return np.column_stack([np.where(along_x, 0.0, 1.0), offset, lo, hi])


def _shift_walls(walls: FloatArray, shift: FloatArray) -> FloatArray:
    """Walls (axis, offset, lo, hi) translated by ``shift`` (2,)."""
    along_x = walls[:, 0] == 0.0
    out = walls.copy()
    out[:, 1] += np.where(along_x, shift[1], shift[0])
    run = np.where(along_x, shift[0], shift[1])
    out[:, 2] += run
    out[:, 3] += run
    return out


def _crosses(new: FloatArray, placed: FloatArray) -> bool:
    """True when a new wall crosses or overlaps a placed one (touching is allowed)."""
    if len(placed) == 0 or len(new) == 0:
        return False
    a = new[:, None, :]
    b = placed[None, :, :]
    perpendicular = a[..., 0] != b[..., 0]
    inside_a = (b[..., 1] > a[..., 2] + _CROSS_EPS) & (b[..., 1] < a[..., 3] - _CROSS_EPS)
    inside_b = (a[..., 1] > b[..., 2] + _CROSS_EPS) & (a[..., 1] < b[..., 3] - _CROSS_EPS)
    overlap = np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 2], b[..., 2])
    collinear = ~perpendicular & (np.abs(a[..., 1] - b[..., 1]) < 2 * _CROSS_EPS)
    return bool(
        np.any(perpendicular & inside_a & inside_b) or np.any(collinear & (overlap > _CROSS_EPS))
    )


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


@dataclass(frozen=True)
class _State:
    order: tuple[int, ...]
    rotations: tuple[int, ...]
    end: FloatArray
    heading: int
    turning: int
    corners: int
    boundary: float
    walls: FloatArray
    vertices: FloatArray


def _extend(search: _Search, state: _State, j: int, turn: int) -> _State | None:
    piece = search.pieces[j]
    rotation = (state.heading + turn - piece.directions[0]) % 4
    local_pts, local_walls = piece.rotated[rotation]
    pts = local_pts + state.end
    walls = _shift_walls(local_walls, state.end)
    if _crosses(walls, state.walls):
        return None
    return _State(
        order=(*state.order, j),
        rotations=(*state.rotations, rotation),
        end=pts[-1],
        heading=(piece.directions[-1] + rotation) % 4,
        turning=state.turning + turn + piece.turning,
        corners=state.corners + (turn != 0) + piece.corners,
        boundary=state.boundary + search.mismatch[state.order[-1]][j],
        walls=np.vstack([state.walls, walls]),
        vertices=np.vstack([state.vertices, pts]),
    )


def _close(search: _Search, state: _State) -> None:
    first = search.pieces[0]
    turn = (first.directions[0] - state.heading) % 4
    turn = {0: 0, 1: 1, 3: -1}.get(turn, 2)
    closed_ok = turn != 2 and state.turning + turn == 4
    if search.require_closed and not closed_ok:
        return
    w_l, w_c, w_b = search.weights()
    corners = state.corners + (turn not in (0, 2))
    closure = float(np.abs(state.end).sum())
    closing = search.mismatch[state.order[-1]][0]
    boundary = state.boundary + closing
    missing = len(search.pieces) - len(state.order)
    if missing:
        # A partial chain (open search): nothing closes, so no closing junction to score.
        corners, closure, boundary = state.corners, 0.0, state.boundary
    penalty = _UNPLACED_PENALTY * missing
    # The hull has at least 4 edges: skip computing it when even that cannot win.
    if w_l * (corners + 4) + w_c * closure + w_b * boundary + penalty >= search.bound():
        return
    complexity = corners + _hull_edges(state.vertices)
    energy = w_l * complexity + w_c * closure + w_b * boundary + penalty
    free_space = 0.0
    if search.params.use_free_space and not missing and energy < search.bound():
        free_space = _outside_share(search, state)
        energy += search.params.free_space_weight * free_space
    ids = tuple(search.pieces[i].id for i in state.order)
    search.record(
        PlacementCandidate(energy, ids, state.rotations, complexity, closure, boundary, free_space)
    )


def _outside_share(search: _Search, state: _State) -> float:
    """Summed share of each piece's footprint that falls outside the placed loop.

    Footprint cells just outside a wall (within the margin) count as inside: wall
    thickness, noise and the unrefined junctions put a few there. All pieces' cells are
    tested in one batch: this runs at every leaf that could win.
    """
    polygon = state.vertices
    cells, owners, sizes = [], [], np.zeros(len(state.order))
    end = np.zeros(2)
    for slot, (index, rotation) in enumerate(zip(state.order, state.rotations, strict=True)):
        piece = search.pieces[index]
        footprint = piece.rotated_footprint[rotation]
        cells.append(footprint + end)
        owners.append(np.full(len(footprint), slot))
        sizes[slot] = len(footprint)
        end = end + piece.rotated[rotation][0][-1]
    all_cells = np.concatenate(cells)
    if len(all_cells) == 0:
        return 0.0
    outside = ~points_in_polygon(all_cells, polygon)
    if not outside.any():
        return 0.0
    far = distance_to_polygon(all_cells[outside], polygon) > search.params.free_space_margin
    counts = np.bincount(np.concatenate(owners)[outside][far], minlength=len(sizes))
    return float(np.sum(counts[sizes > 0] / sizes[sizes > 0]))


def _dfs(search: _Search, state: _State, remaining: tuple[int, ...]) -> None:
    """Expand ``state``: children in order of their lower bound, cut at the bound. Only a
    child that is visited pays for its geometry (the crossing test)."""
    search.nodes += 1
    if not remaining or not search.require_closed:
        # An open search also keeps partial chains: the best one is placed when no
        # arrangement of all pieces exists (walls would cross).
        _close(search, state)
        if not remaining:
            return
    pieces = search.pieces
    w_l, w_c, w_b = search.weights()
    turning = state.turning + sum(pieces[i].turning for i in remaining)
    corners = state.corners + sum(pieces[i].corners for i in remaining)
    # Cheapest way into each piece left (and into the loop's start) from a piece that can
    # still precede it: a lower bound for every child at once.
    sources = (state.order[-1], *remaining)
    entry = {b: min(search.mismatch[a][b] for a in sources if a != b) for b in (*remaining, 0)}
    entry_total = sum(entry.values())
    options = _options(search, state, remaining)
    if not options:
        return
    # Closure bound of every child at once: its end, and what the others left can reach.
    reach = search.reach[list(remaining)].sum(axis=0)
    rotations = [(state.heading + turn - pieces[j].directions[0]) % 4 for j, turn in options]
    ends = state.end + np.array(
        [pieces[j].rotated[r][0][-1] for (j, _), r in zip(options, rotations, strict=True)]
    )
    others = reach[None, :] - search.reach[[j for j, _ in options]]
    closures = np.maximum(0.0, (-(ends @ _CLOSURE_DIRECTIONS.T) - others).max(axis=1))
    ranked = []
    for (j, turn), closure in zip(options, closures.tolist(), strict=True):
        owed = abs(4 - turning - turn) if search.require_closed else 0
        joined = state.boundary + search.mismatch[state.order[-1]][j]
        bound = (
            w_l * (corners + (turn != 0) + owed + 4)
            + w_c * closure
            + w_b * (joined + entry_total - entry[j])
        )
        ranked.append((bound, j, turn))
    ranked.sort(key=lambda item: item[0])
    expanded = 0
    for bound, j, turn in ranked:
        if bound >= search.bound() or search.out_of_budget():
            return
        child = _extend(search, state, j, turn)
        if child is not None:
            _dfs(search, child, tuple(i for i in remaining if i != j))
            expanded += 1
            if search.breadth is not None and expanded >= search.breadth:
                return


def _options(search: _Search, state: _State, remaining: tuple[int, ...]) -> list[tuple[int, int]]:
    """(piece, junction turn) pairs allowed next by the user constraints and the turning
    number of a closed loop."""
    k = len(remaining)
    prev = state.order[-1]
    fixed = state.turning + sum(search.pieces[i].turning for i in remaining)
    options = []
    for j in remaining:
        if search.successor.get(prev, j) != j or search.predecessor.get(j, prev) != prev:
            continue
        for turn in _TURNS:
            # The loop's turns add up to +4; the k junctions after this one give +-1 each.
            if search.require_closed and abs(4 - fixed - turn) > k:
                continue
            options.append((j, turn))
    return options


def _all_mismatches(pieces: Sequence[Piece], params: PlacementParams) -> list[list[float]]:
    """Boundary mismatch of every ordered pair: [a][b] for b following a. The score does
    not depend on the junction's turn. A piece never follows itself (1.0, the worst score)
    unless it is the only one, closing its own loop."""
    n = len(pieces)
    return [
        [
            _boundary_mismatch(pieces[a], pieces[b], params) if a != b or n == 1 else 1.0
            for b in range(n)
        ]
        for a in range(n)
    ]


def _root(first: Piece, params: PlacementParams) -> _State:
    """The search's root: the first piece fixed at the origin with rotation 0."""
    return _State(
        order=(0,),
        rotations=(0,),
        end=first.keypoints[-1].copy(),
        heading=first.directions[-1],
        turning=first.turning,
        corners=first.corners,
        boundary=0.0,
        walls=_trim_start(_walls(first.keypoints), first.keypoints[0], params.closure_overshoot),
        vertices=first.keypoints.copy(),
    )


def _constraint_maps(
    ids: list[str], order_hint: Sequence[str] | None, neighbours: Sequence[tuple[str, str]]
) -> tuple[dict[int, int], dict[int, int]]:
    index = {fid: i for i, fid in enumerate(ids)}
    pairs = list(neighbours)
    if order_hint:
        pairs += list(itertools.pairwise(order_hint))
    successor = {index[a]: index[b] for a, b in pairs if a in index and b in index}
    predecessor = {b: a for a, b in successor.items()}
    return successor, predecessor


def place_pieces(
    pieces: Sequence[Piece],
    params: PlacementParams = PlacementParams(),
    order_hint: Sequence[str] | None = None,
    neighbours: Sequence[tuple[str, str]] = (),
) -> Placement | None:
    """Find the minimum-energy placement of the pieces in one counter-clockwise loop.

    Parameters
    ----------
    pieces : chains with at least one wall each; the first is fixed (rotation 0, loop
        position 0, source at the site origin), which removes the global symmetry.
    params : energy switches, sigma, top-k.
    order_hint : optional known loop order of (some) fragment ids.
    neighbours : optional known (a, b) pairs: b follows a in the loop.

    Returns
    -------
    Placement or None when no placement exists (not even an open one).
    """
    if not pieces:
        return None
    n = len(pieces)
    mismatch = _all_mismatches(pieces, params)
    successor, predecessor = _constraint_maps([p.id for p in pieces], order_hint, neighbours)
    root = _root(pieces[0], params)
    nodes = 0
    deadline = time.monotonic() + params.max_search_seconds  # shared by both searches
    for require_closed in (True, False):
        search = _Search(list(pieces), params, mismatch, successor, predecessor, require_closed)
        search.deadline = deadline
        # Iterative broadening: cheap passes that follow only the most promising children
        # spread good incumbents over the whole tree, so the full pass prunes early.
        for breadth in (*_BROADENING, None):
            search.breadth = breadth
            _dfs(search, root, tuple(range(1, n)))
            if search.truncated:
                break
        nodes += search.nodes
        if search.top:
            break
    if not search.top:
        return None
    ranked = [c for _, _, c in sorted(search.top, key=lambda item: -item[0])]
    best = ranked[0]
    return Placement(
        best=best,
        translations=_translations(pieces, best),
        alternatives=tuple(ranked[1:]),
        nodes_searched=nodes,
        exhaustive=not search.truncated,
        closed=require_closed,
    )


def _translations(pieces: Sequence[Piece], cand: PlacementCandidate) -> FloatArray:
    """Site position of each piece's source after end-to-end concatenation."""
    by_id: Mapping[str, Piece] = {p.id: p for p in pieces}
    end = np.zeros(2)
    out = []
    for fid, rotation in zip(cand.order, cand.rotations, strict=True):
        out.append(end.copy())
        end = end + by_id[fid].keypoints[-1] @ rot90(rotation).T
    return np.asarray(out)


def evaluate_placement(
    pieces: Sequence[Piece],
    order: Sequence[str],
    rotations: Sequence[int],
    params: PlacementParams = PlacementParams(),
) -> PlacementCandidate | None:
    """Energy of one given placement, or None when it is not a valid closed loop.

    The same energy the search minimises; used to check the search against brute force
    and to score a placement a user proposes.
    """
    by_id = {p.id: i for i, p in enumerate(pieces)}
    if order[0] != pieces[0].id or rotations[0] != 0 or sorted(order) != sorted(by_id):
        return None
    params = params.model_copy(update={"top_k": 1})
    search = _Search(list(pieces), params, _all_mismatches(pieces, params), {}, {}, True)
    state = _root(pieces[0], params)
    for fid, rotation in zip(order[1:], rotations[1:], strict=True):
        j = by_id[fid]
        turn = {0: 0, 1: 1, 3: -1}.get((rotation + pieces[j].directions[0] - state.heading) % 4)
        child = None if turn is None else _extend(search, state, j, turn)
        if child is None:
            return None
        state = child
    _close(search, state)
    return search.top[0][2] if search.top else None
