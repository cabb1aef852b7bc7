"""Wall estimation graph, source/target choice and the minimum-cost wall chain (paper 3.1).

Nodes are candidate keypoints: ends of candidate wall segments, corners deduced where two
perpendicular walls would meet, and the ends of deduced walls across occluded stretches
between misaligned parallel walls. Edges join nodes on a common wall line, directed so the
interior stays on the left, with the paper's weight ``(L - H) / H + lambda``.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra, minimum_spanning_tree

from schemas.params import LayoutParams
from services.frustum import CameraView, in_any_view
from services.geometry import cross
from services.types import FloatArray
from services.wall_lines import MAX_DOORWAY, MAX_OPEN_ABOVE, WallLine, run_axis

__all__ = ["FRONT_DEPTH", "WallChain", "find_wall_chain", "side_by_side_depth"]

_CORNER_REACH = 3.0  # m, how far past a segment's end a deduced corner may lie
_OCCLUSION_REACH = 3.0  # m, longest gap the ST-graph links across on one line
_MAX_OPEN_GAP = 0.5  # m, longest stretch a wall may run with nothing scanned beside it
_CORNER_METERS = 0.3  # covered wall a corner must add to a cloud's chain to be worth it, m
_COST_METERS = 0.1  # tie-break: meters of covered wall per unit of path cost
_SNAP_CELLS = 2.0  # a segment end this close to a deduced corner is merged into it
_END_MATCH = 0.05  # m, a line this close to a chain's end wall is that wall's line
_FOLLOW_MARGIN = 1.0  # m, more wall a frame's best-explaining chain must cover to be taken
_MIN_UNSEEN = 0.5  # m, unseen wall an edge bridges to be left out of the second search
_ON_SEGMENT = 0.01  # m, a node this close to an edge's segment lies on it
_LOW_WALL_SHARE = 0.5  # how much a cell with wall points but not the wall's full height covers
_UNKNOWN_COST = 0.5  # what a cell showing neither wall nor space behind it costs a chain
_MOUTH_STANDING = 0.5  # share of an opening's mouth where the wall stands (whole or lintel)
FRONT_DEPTH = 1.05  # m, deepest furniture (a sofa) a frame's cheapest chain may run along
_STANDING_OVER = 0.5  # share of a front's stretch the wall behind it shows over
_SIDE_BY_SIDE = 0.2  # m, two chains' walls overlapping by more than this run side by side


@dataclass(frozen=True)
class WallChain:
    """The estimated wall chain of a fragment, aligned frame.

    keypoints: (K, 2) float64, source to target, interior on the left.
    cost: total edge weight of the chain.
    runner_up: frames only: (K', 2) the other of the frame's two candidate chains (the
        frustum's path and the path explaining the most wall) where they differ, else None.
    """

    keypoints: FloatArray
    cost: float
    runner_up: FloatArray | None = None


@dataclass
class _Nodes:
    """Candidate keypoints and, per line, the run coordinates of the nodes on it."""

    points: list[FloatArray]
    on_line: dict[int, dict[int, float]]  # line index -> {node index: run coordinate}
    _index: dict[tuple[int, int], int]

    def add(self, point: FloatArray, memberships: list[tuple[int, float]]) -> None:
        key = (round(float(point[0]) * 100), round(float(point[1]) * 100))
        node = self._index.get(key)
        if node is None:
            node = len(self.points)
            self._index[key] = node
            self.points.append(point)
        for line, run in memberships:
            self.on_line.setdefault(line, {})[node] = run


def _span_gap(span: FloatArray, run: float) -> float:
    """Distance from a run coordinate to a segment span (0 inside it)."""
    return float(max(span[0] - run, run - span[1], 0.0))


def _add_corners(lines: list[WallLine], nodes: _Nodes) -> None:
    for i, a in enumerate(lines):
        for j, b in enumerate(lines):
            if a.axis != 0 or b.axis != 1:
                continue
            # a runs along x at y = a.offset; b runs along y at x = b.offset.
            near_a = min(_span_gap(seg, b.offset) for seg in a.segments)
            near_b = min(_span_gap(seg, a.offset) for seg in b.segments)
            # A deduced wall spans exactly the step it bridges: no corner past its ends.
            reach_a = _SNAP_CELLS * a.cell_size if a.virtual else _CORNER_REACH
            reach_b = _SNAP_CELLS * b.cell_size if b.virtual else _CORNER_REACH
            if near_a <= reach_a and near_b <= reach_b:
                corner = np.array([b.offset, a.offset])
                nodes.add(corner, [(i, b.offset), (j, a.offset)])


def _build_nodes(lines: list[WallLine]) -> _Nodes:
    nodes = _Nodes(points=[], on_line={}, _index={})
    _add_corners(lines, nodes)
    for i, line in enumerate(lines):
        taken = np.fromiter(nodes.on_line.get(i, {}).values(), float)
        for run in line.segments.ravel():
            # A segment end next to a deduced corner is that corner, blurred by noise.
            if not np.any(np.abs(taken - run) < _SNAP_CELLS * line.cell_size):
                nodes.add(line.point(float(run)), [(i, float(run))])
    for i, line in enumerate(lines):
        if not line.virtual:
            continue
        for j, other in enumerate(lines):
            if other.axis != line.axis and not other.virtual:
                lo, hi = line.segments[0]
                if lo - 1e-6 <= other.offset <= hi + 1e-6:
                    nodes.add(other.point(line.offset), [(i, other.offset), (j, line.offset)])
    return nodes


def _edges(
    lines: list[WallLine], nodes: _Nodes, penalty: float
) -> tuple[csr_matrix, csr_matrix, FloatArray, FloatArray]:
    """Directed WE-graph weights, undirected ST-graph lengths, and per directed edge the
    wall it explains and the length of it where nothing was seen (m, see :func:`_best_path`).

    The ST-graph joins only neighbouring nodes along a line (across gaps up to the
    occlusion reach), so its spanning forest follows the walls instead of jumping back.
    """
    n = len(nodes.points)
    we: dict[tuple[int, int], float] = {}
    st: dict[tuple[int, int], float] = {}
    cover = np.zeros((n, n))
    unseen = np.zeros((n, n))
    # How many lines each node lies on: more than one makes it a corner.
    memberships = np.bincount(
        [node for members in nodes.on_line.values() for node in members], minlength=n
    )
    for li, members in nodes.on_line.items():
        line = lines[li]
        ordered = sorted(members.items(), key=lambda kv: kv[1] * line.travel)
        for a in range(len(ordered)):
            for b in range(a + 1, len(ordered)):
                (u, ru), (v, rv) = ordered[a], ordered[b]
                length, high = line.evidence(ru, rv)
                if b == a + 1:
                    corner = bool(memberships[u] > 1 or memberships[v] > 1)
                    if _st_link(line, (ru, rv), length, high, corner):
                        st[(min(u, v), max(u, v))] = max(length * line.cell_size, 1e-6)
                if (
                    high == 0
                    or length <= 0
                    or line.open_gap(ru, rv) > _MAX_OPEN_GAP
                    or line.crossing_gap(ru, rv) > MAX_DOORWAY
                    or line.open_above_gap(ru, rv) > MAX_OPEN_ABOVE
                ):
                    continue
                # Cells are counted whole, so H may exceed the fractional L by a rounding.
                weight = max(length - high, 0.0) / high + penalty
                if weight < we.get((u, v), np.inf):
                    we[(u, v)] = weight
                    occupied, unknown = line.wall_cells(ru, rv)
                    low = max(occupied - high, 0)
                    cover[u, v] = (
                        min(high, length) + _LOW_WALL_SHARE * low - _UNKNOWN_COST * unknown
                    ) * line.cell_size
                    unseen[u, v] = unknown * line.cell_size
    return _sparse(we, n), _sparse(st, n), cover, unseen


def _st_link(
    line: WallLine, runs: tuple[float, float], length: float, high: int, corner: bool
) -> bool:
    """Neighbours on a line are linked when mostly evidenced, across an inner gap, or
    across a short occluded stretch that ends at a deduced corner."""
    if high >= 0.5 * length:
        return True
    if length * line.cell_size > _OCCLUSION_REACH:
        return False
    if corner and length * line.cell_size <= _CORNER_REACH:
        return True
    lo, hi = sorted(runs)
    start, end = line.origin, line.origin + len(line.high) * line.cell_size
    return line.evidence(start, lo)[1] > 0 and line.evidence(hi, end)[1] > 0


def _sparse(weights: dict[tuple[int, int], float], n: int) -> csr_matrix:
    if not weights:
        return csr_matrix((n, n))
    rows, cols = np.array(list(weights)).T
    return csr_matrix((np.fromiter(weights.values(), float), (rows, cols)), shape=(n, n))


def _forest_ends(st: csr_matrix) -> tuple[int, int] | None:
    """The paper's rule: ends of the longest path in the minimal spanning forest."""
    forest = minimum_spanning_tree(st)
    forest = forest + forest.T
    best: tuple[float, int, int] | None = None
    for start in np.flatnonzero(np.asarray((forest != 0).sum(axis=1)).ravel()):
        dist = dijkstra(forest, indices=int(start))
        far = int(np.argmax(np.where(np.isfinite(dist), dist, -1.0)))
        if best is None or dist[far] > best[0]:
            best = (float(dist[far]), int(start), far)
    return None if best is None else (best[1], best[2])


def _forest_path(we: csr_matrix, st: csr_matrix) -> tuple[list[int], float] | None:
    """Min-cost path between the spanning-forest ends, in whichever direction exists."""
    ends = _forest_ends(st)
    if ends is None:
        return None
    found = []
    for source, target in (ends, ends[::-1]):
        dist, pred = dijkstra(we, directed=True, indices=source, return_predecessors=True)
        if np.isfinite(dist[target]):
            path = [target]
            while path[-1] != source:
                path.append(int(pred[path[-1]]))
            found.append((path[::-1], float(dist[target])))
    return min(found, key=lambda pc: pc[1]) if found else None


def _best_path(
    we: csr_matrix,
    cover: FloatArray,
    unseen: FloatArray,
    points: FloatArray,
    corner_price: float,
) -> tuple[list[int], float] | None:
    """The directed simple path that explains the most wall (:func:`_most_wall_path`).

    That search keeps one path per state, and a path through a state can block a better
    one (it already holds the nodes the better one goes on to). The case that matters: a
    scan that saw the room all around, where a path bridging the stretch the scan saw
    nothing of holds the corner that the path opening at that stretch must start from; the
    chain then opens in front of a cabinet, or short of a corner. So when edges bridge
    ``_MIN_UNSEEN`` or more of unseen wall, the search runs again without them, and the path
    explaining the most wall of the two wins (the same score: the chain is never worse by
    it). corner_price: covered wall a corner must add, m.
    """
    found = _most_wall_path(we, cover, points, corner_price)
    coo = we.tocoo()
    bridges = unseen[coo.row, coo.col] >= _MIN_UNSEEN
    if found is None or not bridges.any():
        return None if found is None else (found[0], found[1])
    keep = ~bridges
    unbridged = csr_matrix((coo.data[keep], (coo.row[keep], coo.col[keep])), shape=we.shape)
    other = _most_wall_path(unbridged, cover, points, corner_price)
    best = other if other is not None and other[2] > found[2] + 1e-9 else found
    return best[0], best[1]


def _most_wall_path(
    we: csr_matrix, cover: FloatArray, points: FloatArray, corner_price: float
) -> tuple[list[int], float, float] | None:
    """The directed simple path that explains the most wall: (nodes, paper's cost, score).

    Score of a path: covered high-evidence length, half the length where the wall shows only
    low (a cabinet hides its foot), less half the length where the scan saw neither wall nor
    space behind it (where a scan that saw the room all around ended: its chain opens there,
    not in front of the cabinet), less a price per corner (a spurious extension through a
    deduced corner adds little wall), less a small share of the paper's path cost as a
    tie-break. A min-cost path would rather skip a stretch of walls along one long, partly
    evidenced line than follow them; this score follows them. A door costs nothing and a
    cabinet in front of a wall only half its length, so a chain is not cut short before the last
    stretch of wall; edges never run far through space seen on both sides of their line
    (see :meth:`WallLine.crossing_gap`), nor where a frame's camera saw through the line
    higher than a door's top (:meth:`WallLine.open_above_gap`: no lintel, so no door). The
    paper instead takes the two ends of the longest path in a spanning forest of the
    keypoints (``source_target="spanning_forest"``).

    The search is label-correcting over states, one best simple path per state: a state
    is a node and the axis the path arrived along, numbered ``2 * node + axis`` (axis 0: x,
    1: y). A fragment may see closed loops of walls (a recess seen whole), so the path's
    own nodes are excluded from its extensions, and so are the nodes its edges pass over
    (an edge joins any two nodes of a line): a chain never runs along the same stretch of
    wall twice, counting its wall twice.

    cover: (n, n) high-evidence wall length of each edge, m; points: (n, 2) node
    coordinates.
    """
    n = we.shape[0]
    coo = we.tocoo()
    if n < 2 or coo.nnz == 0:
        return None
    u, v = coo.row.astype(np.int64), coo.col.astype(np.int64)  # each edge's tail and head
    step = np.abs(points[v] - points[u])
    axis = (step[:, 1] > step[:, 0]).astype(np.int64)
    gain = cover[u, v] - _COST_METERS * coo.data
    head_state = 2 * v + axis  # the state an edge leads into
    edges = np.arange(len(u))
    # (E, n): the nodes on each edge's segment, its ends included.
    along, across = points.T[axis], points.T[1 - axis]
    lo = np.minimum(along[edges, u], along[edges, v])[:, None] - _ON_SEGMENT
    hi = np.maximum(along[edges, u], along[edges, v])[:, None] + _ON_SEGMENT
    span = (
        (np.abs(across - across[edges, u][:, None]) < _ON_SEGMENT) & (along >= lo) & (along <= hi)
    )
    beyond_tail = span.copy()
    beyond_tail[edges, u] = False
    value = np.full(2 * n, -np.inf)  # per state: score of its best path so far
    on_path = np.zeros((2 * n, n), dtype=bool)  # per state: the nodes its path holds or passes
    paths: list[list[int]] = [[] for _ in range(2 * n)]
    start_here = 0  # option column 0: the path starts at the edge's tail
    for _ in range(2 * n + 1):
        # Each edge: start the path at its tail (column 0), or extend the path arriving
        # there along x (column 1) or y (column 2), a turn costing a corner, unless that
        # path already holds the head.
        options = np.zeros((len(u), 3))
        for arrival in (0, 1):
            tail_state = 2 * u + arrival
            extend = value[tail_state] - corner_price * (axis != arrival)
            blocked = (on_path[tail_state] & beyond_tail).any(axis=1)
            options[:, arrival + 1] = np.where(blocked, -np.inf, extend)
        choice = np.argmax(options, axis=1)
        candidate = options[edges, choice] + gain
        # Ascending: the best candidate per state lands last. Stable: among equal ones the
        # last edge, on any machine (numpy's default sort orders ties by its SIMD level).
        order = np.argsort(candidate, kind="stable")
        best = np.full(2 * n, -np.inf)
        best[head_state[order]] = candidate[order]
        edge_of = np.full(2 * n, -1)
        edge_of[head_state[order]] = order
        changed = np.flatnonzero(best > value + 1e-9)
        if len(changed) == 0:
            break
        # Paths of the previous round: an update must not read a path changed in this one.
        taken = edge_of[changed]
        extended = choice[taken] != start_here
        prefix_states = 2 * u[taken] + choice[taken] - 1
        prefixes = [
            paths[state] if extends else [int(u[e])]
            for e, state, extends in zip(taken, prefix_states, extended, strict=True)
        ]
        covered = span[taken] | (on_path[prefix_states] & extended[:, None])
        for updated, prefix, e in zip(changed, prefixes, taken, strict=True):
            paths[updated] = [*prefix, int(v[e])]
        on_path[changed] = covered
        value[changed] = best[changed]
    final = int(np.argmax(value))
    if not np.isfinite(value[final]):
        return None
    path, score = _extended_ends(paths[final], float(value[final]), we, cover, points, corner_price)
    cost = float(sum(we[a, b] for a, b in itertools.pairwise(path)))
    return path, cost, score


def _extended_ends(
    path: list[int],
    score: float,
    we: csr_matrix,
    cover: FloatArray,
    points: FloatArray,
    corner_price: float,
) -> tuple[list[int], float]:
    """The path grown edge by edge at either end while an edge adds to its score (the
    search's score: wall covered, a corner's price at a turn), over no node the path holds
    or passes; and that score.

    The search keeps one path per state, and on a scan that saw its room nearly all
    around, the best path into a state can be one that already holds a node the overall
    best path needs: the chain then starts a corner late and drops a whole wall it saw
    (5.6 m of a U room's notch, seen). Growing the ends afterwards recovers it.
    """
    into, out_of = we.tocsc(), we.tocsr()
    while len(path) >= 2:
        held = _nodes_passed(path, points)
        best: tuple[float, int, bool] | None = None
        for at_start in (True, False):
            end, inner = (path[0], path[1]) if at_start else (path[-1], path[-2])
            end_axis = run_axis(points[end] - points[inner])
            edges = into[:, end] if at_start else out_of[end]
            for other in edges.indices:
                tail, head = (int(other), end) if at_start else (end, int(other))
                passed = _segment_nodes(points, tail, head)
                passed[end] = False
                if (passed & held).any():
                    continue
                turn = run_axis(points[head] - points[tail]) != end_axis
                gain = cover[tail, head] - _COST_METERS * we[tail, head] - corner_price * turn
                if gain > 1e-9 and (best is None or gain > best[0]):
                    best = (gain, int(other), at_start)
        if best is None:
            break
        gain, other, at_start = best
        path = [other, *path] if at_start else [*path, other]
        score += gain
    return path, score


def _segment_nodes(points: FloatArray, a: int, b: int) -> NDArray[np.bool_]:
    """(n,) the nodes on the axis-parallel segment from node ``a`` to node ``b``, both ends
    included (within :data:`_ON_SEGMENT`)."""
    axis = run_axis(points[b] - points[a])
    along, across = points[:, axis], points[:, 1 - axis]
    lo, hi = sorted((along[a], along[b]))
    return (  # type: ignore[no-any-return]
        (np.abs(across - across[a]) < _ON_SEGMENT)
        & (along >= lo - _ON_SEGMENT)
        & (along <= hi + _ON_SEGMENT)
    )


def _nodes_passed(path: list[int], points: FloatArray) -> NDArray[np.bool_]:
    """(n,) the nodes a path holds or its edges pass over."""
    held = np.zeros(len(points), dtype=bool)
    held[path] = True
    for a, b in itertools.pairwise(path):
        held |= _segment_nodes(points, a, b)
    return held


def _corners_only(points: FloatArray) -> FloatArray:
    """Drop chain nodes that lie on a straight stretch (no turn)."""
    if len(points) <= 2:
        return points
    d_prev = points[1:-1] - points[:-2]
    d_next = points[2:] - points[1:-1]
    keep = np.concatenate([[True], np.abs(cross(d_prev, d_next)) > 1e-6, [True]])
    kept: FloatArray = points[keep]
    return kept


def _frustum_path(
    we: csr_matrix, points: FloatArray, views: Sequence[CameraView]
) -> tuple[list[int], float] | None:
    """The paper's rule for RGB-D frames: source and target are the two candidate keypoints
    inside the cameras' view with the widest angle seen from the camera (the mean of the
    centres), joined by a path; the min-cost path between them. Ties go to the cheaper path.
    A pair whose path shows the camera no wall's inner face (:func:`_faces`) is passed over
    for the next widest.
    """
    if len(points) < 2:
        return None
    inside = np.flatnonzero(in_any_view(views, points))
    if len(inside) < 2:
        return None
    centre = np.mean([view.centre[:2] for view in views], axis=0)
    heading = np.mean([view.forward for view in views], axis=0)
    offset = points[inside] - centre
    bearing = np.arctan2(offset[:, 1], offset[:, 0]) - np.arctan2(heading[1], heading[0])
    bearing = np.angle(np.exp(1j * bearing))
    dist, pred = dijkstra(we, directed=True, indices=inside, return_predecessors=True)
    reach = dist[:, inside]
    spread = np.abs(bearing[:, None] - bearing[None, :])
    # Widest angle first; among (nearly) equal angles the cheaper path.
    score = np.where(np.isfinite(reach) & (reach > 0), spread - 1e-3 * reach, -np.inf)
    ranked = np.argsort(-score, axis=None, kind="stable")
    for flat in ranked[np.isfinite(score.ravel()[ranked])]:
        a, b = np.unravel_index(int(flat), score.shape)
        source, target = int(inside[a]), int(inside[b])
        path = [target]
        while path[-1] != source:
            path.append(int(pred[a, path[-1]]))
        path.reverse()
        if _faces(points[path], centre):
            return path, float(reach[a, b])
    return None


def _faces(chain: FloatArray, centre: FloatArray) -> bool:
    """Whether a chain (K, 2), interior on the left, shows ``centre`` the inner face of at
    least one wall: a camera in the room sees no wall from behind (a wall facing away can
    be one hidden behind a step, never the only kind a chain holds).

    >>> wall = np.array([[-1.0, 2.0], [1.0, 2.0]])
    >>> _faces(wall, np.zeros(2)), _faces(wall[::-1], np.zeros(2))
    (False, True)
    """
    return bool(np.any(cross(np.diff(chain, axis=0), centre - chain[:-1]) > 0.0))


def find_wall_chain(
    lines: list[WallLine], params: LayoutParams, views: Sequence[CameraView] = ()
) -> WallChain | None:
    """Choose source and target and return the minimum-cost chain between them.

    Parameters
    ----------
    lines : candidate wall lines of one fragment, aligned frame.
    params : the complexity penalty lambda and the source/target rule.
    views : the cameras of an RGB-D frame (aligned frame): source and target are then the
        widest pair of keypoints seen from the camera (paper supplement), replacing the rule
        of ``params.source_target``; when no pair in view is joined, that rule decides.

    Returns
    -------
    WallChain or None when the fragment shows no wall.
    """
    if not lines:
        return None
    nodes = _build_nodes(lines)
    we, st, cover, unseen = _edges(lines, nodes, params.complexity_penalty)
    node_points = np.asarray(nodes.points)
    found = _frustum_path(we, node_points, views) if views else None
    corner_price = params.frame.corner_price if views else _CORNER_METERS
    other: tuple[list[int], float] | None = None
    if found is not None:
        best = _best_path(we, cover, unseen, node_points, corner_price)
        chosen = _closer_to_the_walls(found, best, cover, node_points, lines)
        if best is not None and best[0] != found[0]:
            other = found if chosen is best else best
        found = chosen
    if found is None and params.source_target == "spanning_forest":
        found = _forest_path(we, st)
    elif found is None:
        found = _best_path(we, cover, unseen, node_points, corner_price)
    if found is None:
        return None
    order, cost = found
    points = _corners_only(np.array([nodes.points[i] for i in order]))
    if not views:
        points = _across_openings(points, lines)
    runner_up = None
    if other is not None:
        runner_up = _ends_along_high_wall(
            _corners_only(np.array([nodes.points[i] for i in other[0]])), lines
        )
    return WallChain(keypoints=_ends_along_high_wall(points, lines), cost=cost, runner_up=runner_up)


def _across_openings(points: FloatArray, lines: Sequence[WallLine]) -> FloatArray:
    """The chain kept inside the room where it ran out through a door or window.

    Through an opening a scan sees the next room's floor and its far wall, and the chain
    that explains the most wall runs out through it, along that far wall and back onto the
    wall it left (a notch: right turn, left, left, right), or on to the next wall past the
    corner beyond the opening (right, left, left; where the opening is in the wall after
    the corner: on past the corner, left, left, right). Where the opening's wall stands
    across the mouth (high evidence, or seen only high up: a lintel) over half of it, the
    excursion is what the scan saw through the opening, and the chain runs along that wall
    instead: across a notch no wider than a doorway, or on to the corner. An alcove open
    to the ceiling or a step in the room shows no wall across its mouth and keeps its
    walls.
    """
    out = points
    i = 1
    while i + 3 < len(out):  # out[i - 1 : i + 4] at least: a wall before and after
        if i + 4 < len(out) and _doorway_notch(out[i - 1 : i + 5], lines):
            out = np.delete(out, slice(i, i + 4), axis=0)
            continue
        corner = _past_corner(out[i - 1 : i + 4], lines)
        if corner is not None:
            out = np.vstack([out[:i], corner[None, :], out[i + 3 :]])
            continue
        i += 1
    return out


def _units(points: FloatArray) -> FloatArray | None:
    """Unit steps between consecutive keypoints, or None when two coincide."""
    steps = np.diff(points, axis=0)
    lengths = np.linalg.norm(steps, axis=1)
    if np.any(lengths < 1e-9):
        return None
    unit: FloatArray = steps / lengths[:, None]
    return unit


def _right_of(a: FloatArray, b: FloatArray) -> bool:
    """Whether direction b is a right turn from direction a."""
    return bool(cross(a, b) < -0.5)


def _wall_stands(
    lines: Sequence[WallLine], through: FloatArray, direction: FloatArray, a: float, b: float
) -> bool:
    """Whether the wall line through ``through`` running along ``direction`` (interior on
    the left) stands over half of its stretch between run coordinates a and b."""
    axis = int(abs(direction[1]) > abs(direction[0]))
    travel = 1 if direction[axis] > 0 else -1
    return any(
        line.standing_share(a, b) >= _MOUTH_STANDING
        for line in _lines_on(lines, axis, travel, float(through[1 - axis]))
    )


def _doorway_notch(six: FloatArray, lines: Sequence[WallLine]) -> bool:
    """Whether keypoints ``six`` (the wall before, the notch's four corners, the wall after)
    hold a notch out through a doorway (see :func:`_across_openings`)."""
    unit = _units(six)
    if unit is None:
        return False
    before, out, across, back, after = unit
    if not (
        _right_of(before, out)
        and np.allclose(across, before)
        and np.allclose(after, before)
        and np.allclose(back, -out)
        and float(np.linalg.norm(six[3] - six[2])) <= MAX_DOORWAY
    ):
        return False
    axis = int(abs(before[1]) > abs(before[0]))
    if abs(six[4, 1 - axis] - six[1, 1 - axis]) > _END_MATCH:
        return False  # the wall after the notch is not the one before it
    return _wall_stands(lines, six[1], before, float(six[1, axis]), float(six[4, axis]))


def _past_corner(five: FloatArray, lines: Sequence[WallLine]) -> FloatArray | None:
    """The corner the chain ``five`` (its keypoints around an excursion) should have taken
    instead of running out through an opening next to it (see :func:`_across_openings`),
    or None."""
    unit = _units(five)
    if unit is None:
        return None
    u0, u1, u2, u3 = unit
    if _right_of(u0, u1) and np.allclose(u2, u0) and np.allclose(u3, -u1):
        # Along the wall, out, along the far wall, back in on the next wall.
        axis = int(abs(u0[1]) > abs(u0[0]))
        corner = five[1] + float((five[3] - five[1]) @ u0) * u0
        inside = float((five[4] - five[1]) @ u1) < -_END_MATCH
        mouth = (float(five[1, axis]), float(corner[axis]))
        wall, along = five[1], u0
    elif _right_of(u1, u0) and np.allclose(u2, -u0) and np.allclose(u3, u1):
        # Along the wall before the corner on past it, along the far wall, back in, along
        # the wall that holds the opening.
        axis = int(abs(u3[1]) > abs(u3[0]))
        corner = five[0] + float((five[3] - five[0]) @ u0) * u0
        inside = float((five[0] - five[3]) @ u0) < -_END_MATCH
        mouth = (float(corner[axis]), float(five[3, axis]))
        wall, along = five[3], u3
    else:
        return None
    if not inside or not _wall_stands(lines, wall, along, *mouth):
        return None
    found: FloatArray = corner
    return found


def _closer_to_the_walls(
    frustum: tuple[list[int], float],
    best: tuple[list[int], float] | None,
    cover: FloatArray,
    points: FloatArray,
    lines: Sequence[WallLine],
) -> tuple[list[int], float]:
    """A frame's chain: the frustum's widest pair joined by the cheapest path, unless the
    path explaining the most wall covers ``_FOLLOW_MARGIN`` more and runs along a wall of
    the frustum's path (the same chain, following a recess or step the cheap path cuts
    across), or behind a wall of it that stands seen over it (the cheap path ran along a
    wardrobe's front, see :func:`_fronts_of`). Without either it may be another room seen
    through a door."""
    if best is None:
        return frustum

    def covered(path: list[int]) -> float:
        return float(sum(cover[a, b] for a, b in itertools.pairwise(path)))

    ahead = covered(best[0]) > covered(frustum[0]) + _FOLLOW_MARGIN
    if ahead and (
        _path_walls(best[0], points) & _path_walls(frustum[0], points)
        or _fronts_of(frustum[0], best[0], points, lines)
    ):
        return best
    return frustum


def _path_walls(path: list[int], points: FloatArray) -> set[tuple[int, int]]:
    """The walls a path runs along, as (axis, offset key): axis 0 for a wall along x, the
    offset rounded to ``_END_MATCH``."""
    return {(e.axis, int(np.rint(e.offset / _END_MATCH))) for e in _path_edges(path, points)}


@dataclass(frozen=True)
class _Edge:
    """A path's edge on its wall: axis (0 along x), travel (+1 or -1 along it), the wall's
    offset and the run coordinates of the edge's ends, in path order."""

    axis: int
    travel: int
    offset: float
    ends: tuple[float, float]


def _path_edges(path: list[int], points: FloatArray) -> list[_Edge]:
    """A path's edges on their walls, in path order."""
    edges = []
    for a, b in itertools.pairwise(path):
        axis = run_axis(points[b] - points[a])
        ends = float(points[a, axis]), float(points[b, axis])
        travel = 1 if ends[1] > ends[0] else -1
        edges.append(_Edge(axis, travel, float(points[a, 1 - axis]), ends))
    return edges


def _fronts_of(
    front: list[int], back: list[int], points: FloatArray, lines: Sequence[WallLine]
) -> bool:
    """Whether a wall of path ``front`` stands before a wall of path ``back`` (parallel,
    the same way round, up to ``FRONT_DEPTH`` nearer the room's inside), and the wall
    behind shows over most of the front's stretch, whole or seen only high up: the camera
    saw the room's wall over a wardrobe or a sofa, which a wall of the room would hide (a
    wall seen through a door shows nowhere over the door's wall)."""
    backs = _path_edges(back, points)
    for edge in _path_edges(front, points):
        inward = edge.travel if edge.axis == 0 else -edge.travel  # the room's side, across
        for other in backs:
            depth = (edge.offset - other.offset) * inward
            if (other.axis, other.travel) != (edge.axis, edge.travel) or not (
                _END_MATCH < depth <= FRONT_DEPTH
            ):
                continue
            if any(
                line.standing_share(*edge.ends) >= _STANDING_OVER
                for line in _lines_on(lines, edge.axis, edge.travel, other.offset)
            ):
                return True
    return False


def side_by_side_depth(chain: FloatArray, other: FloatArray) -> float:
    """How far apart (m) two chains' (K, 2) walls stand where they run the same way side by
    side (parallel, the same direction of travel, overlapping by more than
    ``_SIDE_BY_SIDE``): the largest such offset, 0 where none do.

    A front taken for the wall behind it stands at most a wardrobe's or sofa's depth
    before it; a chain that instead cuts across a notch or an alcove the other follows
    stands the notch's depth away.

    >>> notch = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.5], [3.0, 1.5], [3.0, 0.0], [5.0, 0.0]])
    >>> side_by_side_depth(notch, np.array([[0.0, 0.0], [5.0, 0.0]]))
    1.5
    """
    apart = 0.0
    for edge in _path_edges(list(range(len(chain))), chain):
        for twin in _path_edges(list(range(len(other))), other):
            if (twin.axis, twin.travel) != (edge.axis, edge.travel):
                continue
            overlap = min(max(edge.ends), max(twin.ends)) - max(min(edge.ends), min(twin.ends))
            if overlap > _SIDE_BY_SIDE:
                apart = max(apart, abs(edge.offset - twin.offset))
    return apart


def _lines_on(lines: Sequence[WallLine], axis: int, travel: int, offset: float) -> list[WallLine]:
    """The candidate lines a chain's wall (axis, direction of travel, offset) runs on,
    within ``_END_MATCH``."""
    return [
        line
        for line in lines
        if line.axis == axis and line.travel == travel and abs(line.offset - offset) < _END_MATCH
    ]


def _ends_along_high_wall(points: FloatArray, lines: Sequence[WallLine]) -> FloatArray:
    """The chain with each end carried on along wall seen only high up (``WallLine.lintel``).

    A scan that ends inside a doorway sees its jamb, and past it the lintel over the opening
    with the next room's floor behind it; the wall runs on through the opening, as far as
    the lintel was seen. A wardrobe against the wall hides its lower part the same way
    (:meth:`WallLine.high_wall_beyond`). Without wall above (space seen on both sides of the
    line) the line runs on through the room past a corner: no extension.
    """
    out = points.copy()
    for end, inner in ((0, 1), (-1, -2)):
        step = out[end] - out[inner]
        axis = run_axis(step)
        outward = 1 if step[axis] > 0 else -1
        travel = outward if end == -1 else -outward  # the chain's direction along the wall
        reach = max(
            (
                line.high_wall_beyond(float(out[end, axis]), outward)
                for line in _lines_on(lines, axis, travel, float(out[end, 1 - axis]))
            ),
            default=0.0,
        )
        out[end, axis] += outward * reach
    return out
