"""The placement search: against brute force, pruning, budgets, determinism and hints."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest

from schemas.params import PlacementParams
from services.geometry import distance_to_chain, points_in_polygon
from services.placement import (
    Piece,
    SiteHints,
    evaluate_placement,
    loop_frame_yaw,
    place_pieces,
    translations_of,
)
from services.placement import search as search_module
from services.placement.pieces import FreeSpace, shift_walls
from services.placement.priors import (
    HintPair,
    PiecePrior,
    frame_estimate,
    position_costs_batch,
    wrap_angle,
)
from tests.conftest import UNTUNED, bare_piece, chains_from_polygon, point_at_arc

pytestmark = pytest.mark.timeout(120)

# Pieces without end regions or free space: only the chains' geometry and the hints count.
GEOMETRY = UNTUNED.model_copy(
    update={"use_boundary": False, "use_structure": False, "use_free_space": False}
)
L_PERIMETER = 28.0
# The L room cut in the middle of walls of different lengths: every piece is distinct and
# every junction is straight.
DISTINCT_CUTS = [1.0, 9.5, 12.5, 20.0]
# Cuts that make two pieces swappable: p0 p2 p1 p3 closes as well as the truth (another
# room, same energy).
TIED_CUTS = [1.0, 9.5, 14.0, 20.0]
COMB = np.array(
    [
        [0, 0],
        [10, 0],
        [10, 6],
        [8, 6],
        [8, 3],
        [6, 3],
        [6, 6],
        [4, 6],
        [4, 3],
        [2, 3],
        [2, 6],
        [0, 6],
    ],
    dtype=np.float64,
)


def _random_cuts(rng: np.random.Generator, n: int) -> list[float]:
    """``n`` cut positions on the L room's loop, at least 0.5 m apart."""
    while True:
        cuts = sorted(rng.uniform(0.0, L_PERIMETER, size=n).tolist())
        if min(np.diff([*cuts, cuts[0] + L_PERIMETER])) > 0.5:
            return cuts


def _all_closed(pieces, params, hints=None, frame_yaw=None):
    """Every valid closed placement (brute force over orders and rotations), priors scored
    in a hints frame of yaw ``frame_yaw`` (None: the priors' estimate)."""
    rest = [p.id for p in pieces[1:]]
    found = []
    for perm in itertools.permutations(rest):
        for rots in itertools.product(range(4), repeat=len(rest)):
            order, rotations = (pieces[0].id, *perm), (0, *rots)
            cand = evaluate_placement(pieces, order, rotations, params, hints, frame_yaw)
            if cand is not None:
                found.append(cand)
    return found


def _key(cand):
    return (cand.order, tuple(cand.rotations))


def _cut_points(polygon, cuts):
    """Site positions of the cut points (sources of the pieces), relative to the first."""
    closed = np.vstack([polygon, polygon[:1]])
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    out = []
    for arc in cuts:
        i = int(np.searchsorted(cum, arc, side="right") - 1)
        t = (arc - cum[i]) / (cum[i + 1] - cum[i])
        out.append(closed[i] + t * (closed[i + 1] - closed[i]))
    return np.array(out)


# ---------------------------------------------------------------------------------------------
# Against brute force
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(6))
def test_search_finds_the_brute_force_minimum(l_room, seed):
    rng = np.random.default_rng(seed)
    n = 4 if seed % 2 else 3
    pieces = chains_from_polygon(l_room, _random_cuts(rng, n), rng.integers(0, 4, n).tolist())
    params = GEOMETRY.model_copy(update={"top_k": 500})
    placement = place_pieces(pieces, params)
    every = _all_closed(pieces, params)
    assert placement is not None and every
    assert placement.closed and placement.exhaustive
    lowest = min(c.energy for c in every)
    assert placement.best.energy == pytest.approx(lowest, abs=1e-9)
    # With room for all of them, the search keeps exactly the placements within the window.
    within = {_key(c) for c in every if c.energy <= lowest + params.energy_window}
    assert {_key(c) for c in placement.candidates} == within


@pytest.mark.parametrize("seed", range(3))
def test_search_with_priors_finds_the_brute_force_minimum(l_room, seed):
    # Priors near the truth, in a hints frame turned by 30 degrees: the prior costs enter
    # the bounds, which must stay lower bounds. In the frame the search settled on (the
    # priors' estimate, or the one its best loop refitted), its best is the least of all.
    rng = np.random.default_rng(100 + seed)
    cuts = _random_cuts(rng, 4)
    turns = rng.integers(0, 4, 4).tolist()
    pieces = chains_from_polygon(l_room, cuts, turns)
    hints = _truth_priors(l_room, cuts, turns, rng, noise=(0.8, 0.3))
    placement = place_pieces(pieces, GEOMETRY, hints)
    assert placement is not None and placement.exhaustive
    every = _all_closed(pieces, GEOMETRY, hints, placement.frame_yaw)
    assert placement.best.energy == pytest.approx(min(c.energy for c in every), abs=1e-9)
    assert placement.best.features["prior"] > 0.0  # the priors did take part


def _cut_with_priors(polygon, seed, n, noise):
    """The room cut into n turned pieces at random, and priors near the truth."""
    rng = np.random.default_rng(seed)
    cuts = _random_cuts(rng, n)
    turns = rng.integers(0, 4, n).tolist()
    pieces = chains_from_polygon(polygon, cuts, turns)
    return pieces, _truth_priors(polygon, cuts, turns, rng, noise=noise)


def test_priors_prune_the_search(l_room):
    # Each child's own prior cost enters its bound: with priors near the truth, children
    # far from their priors are cut before they are expanded.
    # (Without the beam, which fills its width whatever the bounds until a loop closes.)
    pieces, hints = _cut_with_priors(l_room, 7, 7, noise=(0.3, 0.05))
    depth_first = GEOMETRY.model_copy(update={"beam_width": 0})
    blind = place_pieces(pieces, depth_first)
    guided = place_pieces(pieces, depth_first, hints)
    assert blind is not None and guided is not None
    assert blind.exhaustive and guided.exhaustive
    assert guided.best.order == tuple(f"p{k}" for k in range(7))
    assert guided.nodes_searched < blind.nodes_searched / 2


def test_a_childs_bound_holds_its_own_prior_exactly(l_room):
    # The bound of a child counts the child's prior cost as its extension will: equal, so
    # the bound is as tight as it can be and still never above a leaf below it.
    pieces, hints = _cut_with_priors(l_room, 3, 6, noise=(0.8, 0.2))
    search = search_module._Search(pieces, GEOMETRY, hints, True)
    state = search_module._root(search)
    prior = search_module._F["prior"]
    for _ in range(3):
        children = search_module._children(search, [state])
        js, turns = children.piece, children.turn
        entering = search.step[state.heading, (state.heading + turns) % 4]
        own, positions = search_module._child_priors(
            search,
            [state],
            children.parent,
            js,
            children.rotation,
            np.tile(state.end, (len(js), 1)),
            state.mean + entering[:, 0],
            state.var + entering[:, 1],
        )
        assert children.position is not None and np.array_equal(positions, children.position)
        extended = [
            search_module._extend(search, state, j, t)
            for j, t in zip(js.tolist(), turns.tolist(), strict=True)
        ]
        valid = {k: child for k, child in enumerate(extended) if child is not None}
        assert valid
        for k, child in valid.items():
            assert own[k] == pytest.approx(child.features[prior], abs=1e-9)
            # Quarter turns that cannot be the least keep a lower bound (the parent's).
            assert np.all(positions[k] <= child.position + 1e-9)
            least = np.argmin(positions[k] + child.rotation_prior)
            assert positions[k][least] == pytest.approx(child.position[least], abs=1e-9)
            assert children.end[k] == pytest.approx(child.end, abs=1e-12)
            assert children.heading[k] == child.heading
            assert children.rotation[k] == child.rotations[-1]
        state = valid[min(valid, key=lambda k: own[k])]
    assert state.features[prior] > 0.0


def test_an_anchor_is_its_row_of_the_batch_to_the_last_bit(l_room):
    # One piece's anchor (each extension) and the batch's rows (each child's bound) must
    # agree exactly: the position costs of both are compared and stored as one.
    pieces, hints = _cut_with_priors(l_room, 3, 6, noise=(0.8, 0.2))
    search = search_module._Search(pieces, GEOMETRY, hints, True)
    rng = np.random.default_rng(5)
    js = np.arange(1, len(pieces))
    sources = rng.normal(0.0, 4.0, (len(js), 2))
    means, variances = rng.normal(0.0, 0.3, (len(js), 2)), rng.uniform(0.0, 0.4, (len(js), 2))
    rows = search_module._anchor_rows(search, js, sources, means, variances)
    for k, j in enumerate(js.tolist()):
        anchor = search_module._anchor(search, j, sources[k], means[k], variances[k])
        assert anchor == tuple(rows[k].tolist())


@pytest.mark.parametrize("seed", [3, 11])
def test_bounded_position_costs_leave_the_search_unchanged(l_room, seed, monkeypatch):
    # Quarter turns of the frame that cannot be a child's least, and children whose bound
    # reaches the threshold with their parent's costs, keep those costs as bounds instead
    # of being fitted: the search must return exactly what it returns with every quarter
    # turn of every child fitted, for fewer fits.
    pieces, hints = _cut_with_priors(l_room, seed, 7, noise=(1.5, math.radians(20.0)))
    fits = []

    def counted(anchors, quarters=None):
        fits.append(len(anchors) * (4 if quarters is None else 1))
        return position_costs_batch(anchors, quarters)

    monkeypatch.setattr(search_module, "position_costs_batch", counted)
    bounded = place_pieces(pieces, GEOMETRY, hints)
    bounded_fits, fits[:] = sum(fits), []
    child_priors = search_module._child_priors
    monkeypatch.setattr(search_module, "_child_priors", lambda *args: child_priors(*args[:8]))
    monkeypatch.setattr(
        search_module, "_least_position_costs", lambda anchors, *_: counted(anchors)
    )
    fitted = place_pieces(pieces, GEOMETRY, hints)
    assert bounded is not None and fitted is not None
    assert bounded.nodes_searched == fitted.nodes_searched
    assert [(c.order, c.rotations, c.energy) for c in bounded.candidates] == [
        (c.order, c.rotations, c.energy) for c in fitted.candidates
    ]
    assert bounded_fits < sum(fits) / 2


def _leaves_below(search, state, remaining):
    """Energies of every closed leaf below ``state`` (each order and turn of the pieces in
    ``remaining``), recorded in ``search``."""
    if not remaining:
        search_module._close(search, state)
        return
    for j, turn in itertools.product(remaining, search_module._TURNS):
        child = search_module._extend(search, state, j, turn)
        if child is not None:
            _leaves_below(search, child, tuple(i for i in remaining if i != j))


def _with_structure(search, structure):
    """``search`` with these structure scores between pieces (and its junction costs)."""
    search.structure = structure
    search.junction = search.weights[search_module._F["structure"]] * structure
    np.fill_diagonal(search.junction, search_module._SAME_PIECE)
    return search


@pytest.mark.parametrize("seed", range(3))
def test_a_childs_bound_near_the_loops_end_is_its_best_leaf(monkeypatch, seed):
    # With at most two pieces left after a child, its bound tries every way to finish the
    # loop. With walls never crossing and no hull term, that is the best leaf below the
    # child exactly (inf when none closes); random structure scores make every pair count.
    monkeypatch.setattr(search_module, "_crosses", lambda new, placed: False)
    rng = np.random.default_rng(seed)
    rect = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [0.0, 4.0]])
    pieces = chains_from_polygon(rect, [0.5, 3.0, 7.0, 11.0, 15.5], rng.integers(0, 4, 5).tolist())
    params = GEOMETRY.model_copy(
        update={"weight_hull": 0.0, "energy_window": 1e9, "top_k": 10_000, "use_structure": True}
    )
    structure = rng.uniform(-1.0, 0.0, (5, 5))
    search = _with_structure(search_module._Search(pieces, params, SiteHints(), True), structure)
    root = search_module._root(search)
    checked = 0
    for first, turn in itertools.product(range(1, 5), search_module._TURNS):
        state = search_module._extend(search, root, first, turn)
        if state is None:
            continue
        children = search_module._children(search, [state])
        for c in range(len(children.piece)):
            j = int(children.piece[c])
            child = search_module._extend(search, state, j, int(children.turn[c]))
            assert child is not None
            leaves = search_module._Search(pieces, params, SiteHints(), True)
            leaves = _with_structure(leaves, structure)
            _leaves_below(leaves, child, tuple(i for i in range(1, 5) if i not in (first, j)))
            best = min((-e for e, _, _ in leaves.top), default=np.inf)
            assert children.bound[c] == pytest.approx(best, abs=1e-9)
            checked += bool(np.isfinite(best))
    assert checked > 5


def _cheapest_tour(search, pieces_left, last, heading):
    """Brute force of the tour table's entry: every order and turn of ``pieces_left`` after
    piece ``last`` at ``heading``, junctions and turns only, closing into the first piece."""
    w_turn = search.weights[search_module._F["turns"]]
    first = search.pieces[0].directions[0]
    best = np.inf
    for order in itertools.permutations(pieces_left):
        for turns in itertools.product(search_module._TURNS, repeat=len(order)):
            cost, prev, h = 0.0, last, heading
            for j, t in zip(order, turns, strict=True):
                rotation = (h + t - search.first_direction[j]) % 4
                cost += search.junction[prev, j] + w_turn * (t != 0)
                prev, h = j, (search.last_direction[j] + rotation) % 4
            closing = (first - h) % 4
            if closing != 2:
                best = min(best, cost + search.junction[prev, 0] + w_turn * (closing != 0))
    return best


@pytest.mark.parametrize("seed", range(3))
def test_the_tour_table_holds_the_cheapest_tour(seed):
    # Random structure scores make every junction cost differently; each entry is checked
    # against every order and turn of its pieces.
    rng = np.random.default_rng(seed)
    rect = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [0.0, 4.0]])
    pieces = chains_from_polygon(rect, [0.5, 3.0, 7.0, 11.0, 15.5], rng.integers(0, 4, 5).tolist())
    params = GEOMETRY.model_copy(update={"use_structure": True})
    search = _with_structure(
        search_module._Search(pieces, params, SiteHints(), True), rng.uniform(-1.0, 0.0, (5, 5))
    )
    tour = search.tour
    assert tour is not None and tour.shape == (16, 5, 4)
    for mask in range(16):
        left = [k + 1 for k in range(4) if mask >> k & 1]
        for last in (k for k in range(5) if k not in left):
            for heading in range(4):
                expected = _cheapest_tour(search, left, last, heading)
                assert tour[mask, last, heading] == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_a_childs_bound_is_never_above_a_leaf_below_it(monkeypatch, seed):
    # Far from the loop's end the bound holds the cheapest tour of the pieces left: it must
    # stay a bound (each child against every closed leaf below it), and it must be the
    # part of the bound that decides for some children, or this tests nothing new.
    rng = np.random.default_rng(seed)
    rect = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [0.0, 4.0]])
    cuts = [0.5, 3.0, 6.5, 9.0, 12.5, 16.0]
    pieces = chains_from_polygon(rect, cuts, rng.integers(0, 4, len(cuts)).tolist())
    # One kept leaf, the best: what the bound is compared with.
    params = GEOMETRY.model_copy(update={"energy_window": 1e9, "top_k": 1, "use_structure": True})
    structure = rng.uniform(-1.0, 0.0, (len(cuts), len(cuts)))
    search = _with_structure(search_module._Search(pieces, params, SiteHints(), True), structure)
    without = _with_structure(search_module._Search(pieces, params, SiteHints(), True), structure)
    monkeypatch.setattr(without, "tour", None)
    root = search_module._root(search)
    children = search_module._children(search, [root])
    loose = search_module._children(without, [root]).bound
    assert np.all(children.bound >= loose - 1e-12)
    tighter = 0
    for c in range(len(children.piece)):
        j = int(children.piece[c])
        child = search_module._extend(search, root, j, int(children.turn[c]))
        if child is None:
            continue
        leaves = search_module._Search(pieces, params, SiteHints(), True)
        rest = tuple(i for i in range(1, len(cuts)) if i != j)
        _leaves_below(_with_structure(leaves, structure), child, rest)
        best = min((-e for e, _, _ in leaves.top), default=np.inf)
        assert children.bound[c] <= best + 1e-9
        tighter += bool(children.bound[c] > loose[c] + 1e-9)
    assert tighter > 0


# ---------------------------------------------------------------------------------------------
# Polishing a search cut short
# ---------------------------------------------------------------------------------------------


def _every_loop(n):
    """Every order and quarter turn of pieces 1..n-1 after piece 0 at rotation 0, as arrays."""
    loops = [
        ((0, *perm), (0, *rots))
        for perm in itertools.permutations(range(1, n))
        for rots in itertools.product(range(4), repeat=n - 1)
    ]
    orders, rotations = zip(*loops, strict=True)
    return np.array(orders), np.array(rotations)


def _placed_leaf(search, order, rotations):
    """The leaf of one loop (None where its walls cross or it does not close)."""
    state = search_module._placed_loop(search, order.tolist(), rotations.tolist())
    return None if state is None else search_module._leaf(search, state)


@pytest.mark.parametrize(("seed", "with_priors"), [(0, False), (1, False), (2, True)])
def test_a_loops_bound_is_its_energy_without_hull_or_free_space(seed, with_priors):
    # Turns, junctions, closure and priors are all a loop's energy holds here: the bound is
    # that energy exactly, for every order and turn; inf exactly where no closed loop is.
    rng = np.random.default_rng(seed)
    rect = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [0.0, 4.0]])
    cuts, turns = [0.5, 3.0, 7.0, 11.0, 15.5], rng.integers(0, 4, 5).tolist()
    pieces = chains_from_polygon(rect, cuts, turns)
    hints = _truth_priors(rect, cuts, turns, rng, (0.8, 0.2)) if with_priors else SiteHints()
    params = GEOMETRY.model_copy(update={"weight_hull": 0.0, "use_structure": True})
    search = search_module._Search(pieces, params, hints, True)
    search = _with_structure(search, rng.uniform(-1.0, 0.0, (5, 5)))
    orders, rotations = _every_loop(5)
    bounds = search_module._loop_bounds(search, orders, rotations)
    placed, priced = 0, 0.0
    for order, turns, bound in zip(orders, rotations, bounds.tolist(), strict=True):
        leaf = _placed_leaf(search, order, turns)
        if leaf is None:
            continue  # walls cross (the bound does not look at walls) or no loop
        placed += 1
        assert bound == pytest.approx(leaf.energy, abs=1e-9)
        priced = max(priced, leaf.features["prior"])
    assert placed > 10
    assert (priced > 1.0) == with_priors  # the priors' costs are in it
    assert np.isfinite(bounds).sum() >= placed


def test_a_loops_bound_is_below_its_energy(l_room):
    # With the hull, free space and priors, which the bound leaves out (each adds nothing
    # or more), over every loop one move away from the best.
    pieces, hints = _cut_with_priors(l_room, 5, 7, noise=(0.5, 0.1))
    params = UNTUNED.model_copy(update={"use_structure": False, "use_boundary": False})
    placement = place_pieces(pieces, params, hints)
    assert placement is not None and placement.closed
    search = search_module._Search(pieces, params, hints, True)
    best = placement.best
    orders, rotations = search_module._moves(
        np.array([search.index[fid] for fid in best.order]), np.array(best.rotations)
    )
    bounds = search_module._loop_bounds(search, orders, rotations)
    checked = 0
    for order, turns, bound in zip(orders, rotations, bounds.tolist(), strict=True):
        leaf = _placed_leaf(search, order, turns)
        if leaf is not None:
            assert bound <= leaf.energy + 1e-9
            checked += leaf.energy > bound + 1e-6
    assert checked > 0  # the terms left out count somewhere


def test_moves_are_every_loop_one_move_away():
    order, rotations = np.array([0, 3, 1, 4, 2]), np.array([0, 2, 1, 0, 3])
    orders, turned = search_module._moves(order, rotations)
    loops = {(tuple(o), tuple(r)) for o, r in zip(orders.tolist(), turned.tolist(), strict=True)}
    assert len(loops) == len(orders)
    expected = set()
    for moved, place, turn, next_turn in itertools.product(
        range(1, 5), range(1, 5), range(4), range(4)
    ):
        pairs = zip(order.tolist(), rotations.tolist(), strict=True)
        rest = [pair for k, pair in enumerate(pairs) if k != moved]
        loop = [*rest[:place], (int(order[moved]), turn), *rest[place:]]
        if place + 1 < 5:
            loop[place + 1] = (loop[place + 1][0], next_turn)
        new = tuple(o for o, _ in loop), tuple(r for _, r in loop)
        if new != (tuple(order.tolist()), tuple(rotations.tolist())):
            expected.add(new)
    assert loops == expected
    assert ((0, 3, 4, 1, 2), (0, 2, 0, 1, 3)) in loops  # two neighbours swapped
    assert ((0, 3, 1, 4, 2), (0, 2, 1, 3, 3)) in loops  # one piece turned


def test_polish_reaches_the_best_loop_from_one_move_away():
    # The exhaustive search's best, moved away from by one move to a worse loop: polishing
    # that loop finds the best again.
    pieces = _comb_pieces(6)
    best = place_pieces(pieces, GEOMETRY)
    assert best is not None and best.exhaustive
    search = search_module._Search(list(pieces), GEOMETRY, SiteHints(), True)
    index = search.index
    order = np.array([index[fid] for fid in best.best.order])
    rotations = np.array(best.best.rotations)
    orders, turned = search_module._moves(order, rotations)
    worse = []
    for o, r in zip(orders, turned, strict=True):
        leaf = _placed_leaf(search, o, r)
        if leaf is not None:
            worse.append(search_module._with_outside(search, leaf))
    assert worse
    start = max(worse, key=lambda c: c.energy)  # the worst loop one move away
    found = search_module._polish(search, start)
    assert found and _key(found[-1]) == _key(best.best)
    assert found[-1].energy == pytest.approx(best.best.energy, abs=1e-9)
    assert all(a.energy > b.energy for a, b in itertools.pairwise([start, *found]))
    assert 0 < search.nodes <= GEOMETRY.polish_nodes


def test_polish_keeps_to_its_budget():
    pieces = _comb_pieces(8)
    for budget in (0, 30):
        params = GEOMETRY.model_copy(
            update={"max_search_nodes": 200, "polish_nodes": budget, "restart_roots": 0}
        )
        placement = place_pieces(pieces, params)
        assert placement is not None and placement.closed and not placement.exhaustive
        # The closed search stops at its budget (one node over at most), the polish at its.
        assert placement.nodes_searched <= 200 + 1 + budget + len(pieces)


def _truth_priors(polygon, cuts, turns, rng=None, noise=(0.0, 0.0), frame=(0.5, (3.0, -1.0))):
    """Prior per piece from the truth: the piece made with ``turns[k]`` quarter turns sits
    turned back by them; the hints frame is the polygon's turned by frame[0], shifted."""
    yaw0, shift = frame
    c, s = math.cos(yaw0), math.sin(yaw0)
    turn = np.array([[c, -s], [s, c]])
    sources = _cut_points(polygon, cuts)
    priors = {}
    for k, quarter in enumerate(turns):
        dxy = np.zeros(2) if rng is None else rng.normal(0.0, noise[0], 2)
        dyaw = 0.0 if rng is None else rng.normal(0.0, noise[1])
        priors[f"p{k}"] = PiecePrior(
            yaw=yaw0 - quarter * math.pi / 2 + dyaw,
            source=turn @ sources[k] + np.array(shift) + dxy,
            sigma_xy=1.0,
            sigma_yaw=0.35,
        )
    return SiteHints(priors=priors)


# ---------------------------------------------------------------------------------------------
# What the search returns
# ---------------------------------------------------------------------------------------------


def test_recovers_order_rotations_and_translations_of_a_cut_room(l_room):
    pieces = chains_from_polygon(l_room, DISTINCT_CUTS, [0, 1, 2, 3])
    shuffled = [pieces[0], pieces[3], pieces[1], pieces[2]]
    placement = place_pieces(shuffled, GEOMETRY)
    assert placement is not None and placement.closed and placement.exhaustive
    best = placement.best
    assert best.order == ("p0", "p1", "p2", "p3")
    assert list(best.rotations) == [0, 3, 2, 1]  # each piece's turn undone
    assert best.missing == 0 and best.violated_pairs == ()
    assert best.features["turns"] == 0  # every cut is in the middle of a wall
    assert best.features["hull"] == 5
    points = _cut_points(l_room, DISTINCT_CUTS)
    assert placement.translations == pytest.approx(points - points[0])
    assert translations_of(shuffled, best) == pytest.approx(placement.translations)


def test_candidates_are_distinct_and_sorted(l_room):
    pieces = chains_from_polygon(l_room, [1.0, 9.5, 14.0, 20.0, 25.5], [0, 1, 2, 3, 1])
    placement = place_pieces(pieces, GEOMETRY.model_copy(update={"top_k": 5}))
    assert placement is not None
    candidates = placement.candidates
    assert len(candidates) == 5
    assert len({_key(c) for c in candidates}) == 5
    energies = [c.energy for c in candidates]
    assert energies == sorted(energies)
    assert candidates[0] is placement.best


def test_top_k_keeps_the_lowest(l_room):
    pieces = chains_from_polygon(l_room, _random_cuts(np.random.default_rng(1), 4), [0, 2, 1, 3])
    every = sorted(_all_closed(pieces, GEOMETRY), key=lambda c: c.energy)
    placement = place_pieces(pieces, GEOMETRY.model_copy(update={"top_k": 2}))
    assert placement is not None
    assert len(every) > 2 and len(placement.candidates) == 2
    assert [c.energy for c in placement.candidates] == pytest.approx([c.energy for c in every[:2]])


@pytest.mark.parametrize("window", [0.5, 2.0, 4.0])
def test_energy_window_drops_unlikely_candidates(l_room, window):
    pieces = chains_from_polygon(l_room, _random_cuts(np.random.default_rng(1), 4), [0, 2, 1, 3])
    every = _all_closed(pieces, GEOMETRY)
    lowest = min(c.energy for c in every)
    params = GEOMETRY.model_copy(update={"top_k": 100, "energy_window": window})
    placement = place_pieces(pieces, params)
    assert placement is not None
    got = {_key(c) for c in placement.candidates}
    assert got == {_key(c) for c in every if c.energy <= lowest + window}
    assert all(c.energy <= placement.best.energy + window for c in placement.candidates)


def test_a_narrow_window_prunes_the_search():
    # The window is a bound, not only a filter: assemblies that much less likely are not
    # even looked for.
    pieces = _comb_pieces(6)
    nodes = []
    for window in (0.5, 6.0, 50.0):
        params = GEOMETRY.model_copy(update={"top_k": 100, "energy_window": window})
        placement = place_pieces(pieces, params)
        assert placement is not None and placement.exhaustive
        nodes.append(placement.nodes_searched)
    assert nodes[0] < nodes[1] < nodes[2]


def _comb_pieces(n: int) -> list[Piece]:
    rng = np.random.default_rng(3)
    perimeter = 44.0
    cuts = sorted((np.arange(n) * perimeter / n + rng.uniform(0.0, 1.0, n)).tolist())
    return chains_from_polygon(COMB, cuts, rng.integers(0, 4, n).tolist())


@pytest.mark.parametrize("with_priors", [False, True])
def test_placing_siblings_together_changes_no_step_of_the_search(monkeypatch, l_room, with_priors):
    # The depth-first search places a few siblings at once to bound their children in one
    # batch; it still expands the same nodes in the same order as one sibling at a time.
    pieces, hints = _cut_with_priors(l_room, 5, 7, noise=(0.5, 0.1))
    hints = hints if with_priors else None
    runs = {}
    for group in (1, 3, 8):
        monkeypatch.setattr(search_module, "_DFS_GROUP", group)
        runs[group] = place_pieces(pieces, GEOMETRY, hints)
    first = runs[1]
    assert first is not None
    for placement in runs.values():
        assert placement is not None
        assert placement.nodes_searched == first.nodes_searched
        assert placement.candidates == first.candidates


def test_the_beams_wall_test_is_each_childs_own():
    # The beam tests its children's walls many at once: each child's walls and verdict
    # must be those of shift_walls and _crosses alone, to the last bit, crossing or not.
    pieces = _comb_pieces(9)
    search = search_module._Search(pieces, GEOMETRY, SiteHints(), True)
    states = [search_module._root(search)]
    for _ in range(3):  # a few layers of states of different lengths
        children = search_module._children(search, states[-4:])
        for c in range(0, len(children.piece), 5):
            parent = states[-4:][int(children.parent[c])]
            child = search_module._extend(
                search, parent, int(children.piece[c]), int(children.turn[c])
            )
            if child is not None:
                states.append(child)
    children = search_module._children(search, states)
    placed = search_module._Placed.of(states)
    walls, crosses = search_module._children_walls(search, placed, children, slice(None))
    for c in range(len(children.piece)):
        state, j = states[int(children.parent[c])], int(children.piece[c])
        own = shift_walls(pieces[j].rotated[int(children.rotation[c])][1], state.end)
        assert np.array_equal(walls[c, : search.wall_count[j]], own)
        assert np.isnan(walls[c, search.wall_count[j] :]).all()
        assert crosses[c] == search_module._crosses(own, state.walls)
    assert 0 < crosses.sum() < len(crosses)


@pytest.mark.parametrize("spare", [0, 1, 500])
def test_the_beams_chunks_change_no_step_of_the_search(monkeypatch, spare):
    # However many children the beam tests at once, it lays the same layers.
    pieces = _comb_pieces(10)
    params = GEOMETRY.model_copy(update={"beam_width": 40, "max_search_nodes": 3000})
    first = place_pieces(pieces, params)
    monkeypatch.setattr(search_module, "_BEAM_SPARE", spare)
    again = place_pieces(pieces, params)
    assert first is not None and again is not None
    assert again.nodes_searched == first.nodes_searched
    assert again.candidates == first.candidates


@pytest.mark.parametrize("with_priors", [False, True])
def test_a_batchs_children_split_by_state(l_room, with_priors):
    # With priors on some pieces only, the states of a batch hold different numbers of
    # anchors; each child's costs are still those of its own state.
    pieces, hints = _cut_with_priors(l_room, 5, 6, noise=(0.5, 0.1))
    some = {k: v for k, v in hints.priors.items() if k not in ("p1", "p3")}
    search = search_module._Search(
        pieces, GEOMETRY, SiteHints(priors=some if with_priors else {}), True
    )
    root = search_module._root(search)
    states = [
        child
        for child in (search_module._extend(search, root, j, t) for j in (1, 2, 3) for t in (0, 1))
        if child is not None
    ]
    if with_priors:
        assert len({len(state.anchors) for state in states}) > 1
    batch = search_module._children(search, states)
    for k, state in enumerate(states):
        alone, part = search_module._children(search, [state]), batch.of(k)
        assert np.array_equal(part.piece, alone.piece) and np.array_equal(part.turn, alone.turn)
        assert np.all(part.parent == 0)
        assert part.bound == pytest.approx(alone.bound, abs=1e-9)
        assert part.end == pytest.approx(alone.end, abs=1e-12)
        if with_priors:
            assert part.position is not None and alone.position is not None
            assert part.position == pytest.approx(alone.position, abs=1e-9)


@pytest.mark.parametrize("budget", [1, 7, 50])
def test_node_budget_is_respected(budget):
    pieces = _comb_pieces(6)
    full = place_pieces(pieces, GEOMETRY)
    assert full is not None and full.exhaustive and full.nodes_searched > 200
    limited = place_pieces(pieces, GEOMETRY.model_copy(update={"max_search_nodes": budget}))
    assert limited is not None
    # The closed search keeps to its budget; the open fallback, the restarts and the polish
    # have budgets of their own.
    most = budget + 1 + GEOMETRY.max_open_nodes + 1 + GEOMETRY.polish_nodes + _restarts_nodes(6)
    assert limited.nodes_searched <= most
    assert not limited.exhaustive


def test_a_wide_beam_leaves_the_budget_room_to_close_the_loop():
    # 12 pieces and a beam of 1000 per loop position would spend 11 000 nodes, more than
    # the budget: the beam keeps to half of it and the search still returns closed loops.
    pieces = _comb_pieces(12)
    params = GEOMETRY.model_copy(update={"beam_width": 1000, "max_search_nodes": 4000})
    placement = place_pieces(pieces, params)
    assert placement is not None and placement.closed
    assert placement.nodes_searched <= 4000 + 1 + params.polish_nodes + _restarts_nodes(12)


def _restarts_nodes(n, params=GEOMETRY):
    """The most nodes the restarts of a site of n pieces spend: their budgets, one node over
    each, and placing each loop they keep again."""
    return params.restart_roots * (params.restart_nodes + 1 + params.top_k * (n - 1))


@pytest.mark.parametrize(("n", "count", "roots"), [(12, 2, [4, 8]), (9, 3, [2, 4, 7]), (2, 2, [1])])
def test_restarts_enter_the_loop_at_pieces_spread_evenly(n, count, roots):
    assert search_module._restart_roots(n, count) == roots


def test_a_restart_records_its_loops_led_by_the_first_piece():
    # The search from piece 0 has no node to spend; the restart from piece 3 searches the
    # whole tree: its best, shifted to start at piece 0, is the exhaustive search's best,
    # scored alike.
    pieces = _comb_pieces(6)
    best = place_pieces(pieces, GEOMETRY)
    assert best is not None and best.exhaustive
    params = GEOMETRY.model_copy(update={"max_search_nodes": 1, "restart_nodes": 10**6})
    search = search_module._Search(list(pieces), params, SiteHints(), True)
    assert not search.top
    spent = search_module._restart(search, 3)
    assert spent > best.nodes_searched / 2
    found = min(
        (search_module._with_outside(search, c) for _, _, c in search.top), key=lambda c: c.energy
    )
    assert _key(found) == _key(best.best)
    assert found.energy == pytest.approx(best.best.energy, abs=1e-9)


def test_a_restart_keeps_to_the_pair_hints():
    # Pair hints name pieces, not places in the loop: a restart's loops, placed again from
    # the first piece, are scored with the hints as the first search scores its own.
    pieces = _comb_pieces(6)
    free = place_pieces(pieces, GEOMETRY)
    assert free is not None
    wanted = free.best.order
    hints = SiteHints(pairs=tuple(HintPair(a, b, True) for a, b in itertools.pairwise(wanted)))
    wide = GEOMETRY.model_copy(update={"energy_window": 20.0})  # keep hint breakers too
    full = place_pieces(pieces, wide, hints)
    assert full is not None and full.exhaustive
    params = wide.model_copy(update={"max_search_nodes": 1, "restart_nodes": 10**6})
    search = search_module._Search(list(pieces), params, hints, True)
    search_module._restart(search, 2)
    found = [search_module._with_outside(search, c) for _, _, c in search.top]
    best = min(found, key=lambda c: c.energy)
    assert _key(best) == _key(full.best)
    assert best.violated_pairs == full.best.violated_pairs
    assert best.energy == pytest.approx(full.best.energy, abs=1e-9)
    assert len(found) > 1
    for cand in found:  # every loop scored as evaluate_placement scores it, hints and all
        alone = evaluate_placement(pieces, cand.order, cand.rotations, wide, hints)
        assert alone is not None
        assert cand.violated_pairs == alone.violated_pairs
        assert cand.energy == pytest.approx(alone.energy, abs=1e-9)


def test_restarts_keep_to_their_budget():
    pieces = _comb_pieces(10)
    params = GEOMETRY.model_copy(update={"max_search_nodes": 300, "restart_nodes": 200})
    placement = place_pieces(pieces, params)
    assert placement is not None and placement.closed and not placement.exhaustive
    alone = place_pieces(pieces, params.model_copy(update={"restart_roots": 0}))
    assert alone is not None
    assert placement.nodes_searched > alone.nodes_searched
    limit = 300 + 1 + params.polish_nodes + _restarts_nodes(10, params)
    assert placement.nodes_searched <= limit
    assert placement.best.energy <= alone.best.energy + 1e-9


def test_a_small_site_is_searched_in_fewer_nodes():
    # Below large_site_pieces each piece fewer divides the beam by 3 (and children's bounds
    # finish the loop exactly): a 6-piece site's depth-first search finishes anyway, and
    # finds the same placements in fewer nodes.
    pieces = _comb_pieces(6)
    whole = place_pieces(pieces, GEOMETRY.model_copy(update={"large_site_pieces": 1}))
    scaled = place_pieces(pieces, GEOMETRY)
    assert whole is not None and scaled is not None
    assert whole.exhaustive and scaled.exhaustive
    assert scaled.candidates == whole.candidates
    assert scaled.nodes_searched < whole.nodes_searched


def test_same_input_same_result():
    pieces = _comb_pieces(6)
    for params in (GEOMETRY, GEOMETRY.model_copy(update={"max_search_nodes": 40})):
        first, second = place_pieces(pieces, params), place_pieces(list(pieces), params)
        assert first is not None and second is not None
        assert first.nodes_searched == second.nodes_searched
        assert first.exhaustive == second.exhaustive
        assert [(_key(c), c.energy) for c in first.candidates] == [
            (_key(c), c.energy) for c in second.candidates
        ]
        assert np.array_equal(first.translations, second.translations)


# ---------------------------------------------------------------------------------------------
# Hints
# ---------------------------------------------------------------------------------------------


def _square_quarters() -> list[Piece]:
    """A 4 m square cut in the middle of each wall: four identical L pieces (every order of
    them closes the same square)."""
    square = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], dtype=np.float64)
    return chains_from_polygon(square, [2.0, 6.0, 10.0, 14.0], [0, 3, 2, 1])


def test_pieces_of_equal_shape_tie():
    pieces = _square_quarters()
    assert all(np.allclose(p.keypoints, pieces[0].keypoints) for p in pieces)
    placement = place_pieces(pieces, GEOMETRY)
    assert placement is not None
    energies = [c.energy for c in placement.candidates]
    assert len(energies) == 6  # 3! orders of the other pieces
    assert max(energies) == pytest.approx(min(energies))


def test_an_order_hint_steers_a_tie():
    pieces = _square_quarters()
    free = place_pieces(pieces, GEOMETRY)
    assert free is not None
    # Ask for the other pieces in the reverse of the order the unhinted search picked.
    wanted = ("p0", *reversed(free.best.order[1:]))
    assert wanted != free.best.order
    hints = SiteHints(pairs=tuple(HintPair(a, b, True) for a, b in itertools.pairwise(wanted)))
    wide = GEOMETRY.model_copy(update={"energy_window": 20.0})  # keep hint breakers too
    steered = place_pieces(pieces, wide, hints)
    assert steered is not None
    assert steered.best.order == wanted
    assert steered.best.violated_pairs == ()
    assert steered.best.energy == pytest.approx(free.best.energy)
    # Assemblies that break the hint are still there, each broken pair costing its price.
    broken = [c for c in steered.alternatives if c.violated_pairs]
    assert {len(c.violated_pairs) for c in broken} >= {2, 3}
    for cand in broken:
        plain = evaluate_placement(pieces, cand.order, cand.rotations, wide)
        assert plain is not None
        price = wide.hint_pair_cost * len(cand.violated_pairs)
        assert cand.energy == pytest.approx(plain.energy + price)


def test_a_neighbour_hint_steers_a_tie_either_way_round():
    pieces = _square_quarters()
    free = place_pieces(pieces, GEOMETRY)
    assert free is not None
    # The piece opposite p0 in the unhinted best is to become p0's neighbour.
    opposite = free.best.order[2]
    for pair in (HintPair("p0", opposite, False), HintPair(opposite, "p0", False)):
        steered = place_pieces(pieces, GEOMETRY, SiteHints(pairs=(pair,)))
        assert steered is not None
        assert steered.best.order.index(opposite) in (1, 3)  # p0 is first: next to 1 and 3
        assert steered.best.violated_pairs == ()
        assert steered.best.energy == pytest.approx(free.best.energy)


def test_a_hint_the_scans_contradict_is_reported_not_obeyed(l_room):
    # Three pieces of the L room: p2 directly after p0 closes the loop only at a high cost
    # (turns, hull, a gap), far more than breaking the hint costs.
    pieces = chains_from_polygon(l_room, [1.0, 9.5, 20.0], [0, 1, 2])
    bad = HintPair("p0", "p2", True)
    obeying = [c for c in _all_closed(pieces, GEOMETRY) if c.order[1] == "p2"]
    truth = evaluate_placement(pieces, ["p0", "p1", "p2"], [0, 3, 2], GEOMETRY)
    assert truth is not None and obeying
    assert min(c.energy for c in obeying) > truth.energy + 2 * GEOMETRY.hint_pair_cost
    placement = place_pieces(pieces, GEOMETRY, SiteHints(pairs=(bad,)))
    assert placement is not None
    assert placement.best.order == ("p0", "p1", "p2")
    assert placement.best.violated_pairs == (bad,)
    assert placement.best.energy == pytest.approx(truth.energy + GEOMETRY.hint_pair_cost)


def test_hints_naming_absent_pieces_are_ignored(l_room):
    pieces = chains_from_polygon(l_room, DISTINCT_CUTS, [0, 1, 2, 3])
    hints = SiteHints(pairs=(HintPair("p0", "ghost", True), HintPair("ghost", "p1", False)))
    plain, hinted = place_pieces(pieces, GEOMETRY), place_pieces(pieces, GEOMETRY, hints)
    assert plain is not None and hinted is not None
    assert _key(hinted.best) == _key(plain.best)
    assert hinted.best.energy == pytest.approx(plain.best.energy)
    assert hinted.best.violated_pairs == ()


def test_two_tied_rooms(l_room):
    pieces = chains_from_polygon(l_room, TIED_CUTS, [0, 1, 2, 3])
    placement = place_pieces(pieces, GEOMETRY)
    assert placement is not None
    orders = [c.order for c in placement.candidates[:2]]
    assert set(orders) == {("p0", "p1", "p2", "p3"), ("p0", "p2", "p1", "p3")}
    assert placement.candidates[1].energy == pytest.approx(placement.candidates[0].energy)


def _seeing_floor(piece: Piece, room: np.ndarray, source: np.ndarray, reach: float) -> Piece:
    """The piece (rotation 0, source at ``source`` in the room) with the room's floor within
    ``reach`` of its walls as its seen free space."""
    cell = 0.25
    lo, hi = room.min(axis=0), room.max(axis=0)
    xs, ys = np.meshgrid(np.arange(lo[0], hi[0], cell), np.arange(lo[1], hi[1], cell))
    centres = np.column_stack([xs.ravel(), ys.ravel()]) + cell / 2
    walls = piece.keypoints + source
    near = distance_to_chain(centres, walls) <= reach
    seen = centres[points_in_polygon(centres, room) & near] - source
    origin = seen.min(axis=0) - cell / 2
    ij = np.round((seen - origin) / cell - 0.5).astype(int)
    grid = np.zeros(tuple(ij.max(axis=0) + 1), dtype=bool)
    grid[ij[:, 0], ij[:, 1]] = True
    free = FreeSpace(grid, origin, cell, seen.min(axis=0) - cell, seen.max(axis=0) + cell)
    return dataclasses.replace(piece, free=free)


HALL = np.array([[0, 0], [12, 0], [12, 6], [0, 6]], dtype=np.float64)


def _hall_piece(piece: Piece, source: np.ndarray, gap: float) -> Piece:
    """A piece of the 12 x 6 m hall that saw the whole floor (0.4 m clear of the walls),
    its chain ``gap`` short at its end: the next scan starts that far on."""
    cell = 0.25
    xs, ys = np.meshgrid(np.arange(0.5, 11.5, cell), np.arange(0.5, 5.5, cell))
    seen = np.column_stack([xs.ravel(), ys.ravel()]) + cell / 2 - source
    origin = seen.min(axis=0) - 1.5 * cell
    ij = np.floor((seen - origin) / cell).astype(int)
    grid = np.zeros(tuple(ij.max(axis=0) + 2), dtype=bool)
    grid[ij[:, 0], ij[:, 1]] = True
    free = FreeSpace(grid, origin, cell, seen.min(axis=0) - cell, seen.max(axis=0) + cell)
    keypoints = piece.keypoints.copy()
    last = keypoints[-1] - keypoints[-2]
    keypoints[-1] -= gap * last / np.linalg.norm(last)
    return dataclasses.replace(piece, keypoints=keypoints, free=free)


@pytest.mark.parametrize("gap", [0.0, 0.2, 1.0])
def test_with_priors_free_space_forgives_the_drift_the_junctions_explain(gap):
    # Twelve scans of a hall, each junction hiding a gap. Placed end to end, the far
    # pieces drift into the space the first ones saw empty: by less than the junctions'
    # spread (0.3 m each) at 0.2 m, which is not a contradiction; far more at 1 m.
    cuts = [1.5 + 3.0 * k for k in range(12)]
    pieces = chains_from_polygon(HALL, cuts, [0] * 12)
    pieces = [_hall_piece(p, point_at_arc(HALL, c), gap) for p, c in zip(pieces, cuts, strict=True)]
    params = UNTUNED.model_copy(update={"use_boundary": False, "use_structure": False})
    exact = params.model_copy(update={"conflict_drift_sigmas": 0.0})
    priors = _truth_priors(HALL, cuts, [0] * 12)
    order, rotations = [p.id for p in pieces], [0] * 12
    forgiving = evaluate_placement(pieces, order, rotations, params, priors)
    strict = evaluate_placement(pieces, order, rotations, exact, priors)
    # Without priors every wall counts where the end-to-end loop puts it (see the param).
    unhinted = evaluate_placement(pieces, order, rotations, params)
    assert forgiving is not None and strict is not None and unhinted is not None
    assert unhinted.features["conflict"] == strict.features["conflict"]
    if gap == 0.0:
        assert strict.features["conflict"] == forgiving.features["conflict"] == 0.0
    elif gap < 0.3:
        assert strict.features["conflict"] > 10.0
        assert forgiving.features["conflict"] == 0.0
    else:
        assert forgiving.features["conflict"] > 10.0


def test_the_state_keeps_each_placed_free_space_box_at_its_source():
    # The conflict test reads the placed pieces' free-space boxes from the state, kept as
    # the loop grows: each must be its piece's box at that turn, moved to its source.
    cuts = [1.5 + 3.0 * k for k in range(12)]
    pieces = chains_from_polygon(HALL, cuts, [0, 1, 2, 3] * 3)
    pieces = [_hall_piece(p, point_at_arc(HALL, c), 0.2) for p, c in zip(pieces, cuts, strict=True)]
    search = search_module._Search(pieces, UNTUNED, SiteHints(), True)
    turns = [(-k) % 4 for k in (0, 1, 2, 3) * 3]  # undo each chain's quarter turns
    state = search_module._placed_loop(search, list(range(12)), turns)
    assert state is not None and len(state.order) == 12
    placed = zip(state.order, state.rotations, strict=True)
    boxes = [pieces[j].rotated_free[r].box for j, r in placed]
    moved = np.array(boxes) + np.tile(state.sources, 2)
    assert np.array_equal(state.free_at, moved)
    assert np.isfinite(state.free_at).all()


@pytest.mark.parametrize("use_outside", [True, False])
def test_floor_seen_outside_breaks_the_tie_of_two_rooms(l_room, use_outside):
    # The tied L room's swapped assembly leaves floor a scan saw outside its walls.
    pieces = chains_from_polygon(l_room, TIED_CUTS, [0, 0, 0, 0])
    sources = [point_at_arc(l_room, cut) for cut in TIED_CUTS]
    seeing = [_seeing_floor(p, l_room, s, 2.0) for p, s in zip(pieces, sources, strict=True)]
    params = GEOMETRY.model_copy(update={"use_outside": use_outside})
    placement = place_pieces(seeing, params)
    assert placement is not None
    best, runner_up = placement.candidates[:2]
    if not use_outside:
        assert runner_up.energy == pytest.approx(best.energy)
        return
    assert best.order == ("p0", "p1", "p2", "p3")
    assert best.features["outside"] == 0.0
    assert runner_up.order == ("p0", "p2", "p1", "p3")
    assert runner_up.features["outside"] > 1.0
    assert runner_up.energy == pytest.approx(best.energy + runner_up.features["outside"])


@pytest.mark.parametrize("frame", [(0.0, (0.0, 0.0)), (0.5, (3.0, -1.0)), (-2.0, (-7.0, 4.0))])
def test_priors_pick_the_right_one_of_two_tied_rooms(l_room, frame):
    turns = [0, 1, 2, 3]
    pieces = chains_from_polygon(l_room, TIED_CUTS, turns)
    hints = _truth_priors(l_room, TIED_CUTS, turns, frame=frame)
    placement = place_pieces(pieces, GEOMETRY, hints)
    assert placement is not None
    assert placement.best.order == ("p0", "p1", "p2", "p3")
    assert list(placement.best.rotations) == [0, 3, 2, 1]
    assert placement.best.features["prior"] == pytest.approx(0.0, abs=1e-9)
    runner_up = placement.alternatives[0]
    assert runner_up.energy > placement.best.energy + 1.0


def test_priors_pick_the_right_room_when_the_first_pieces_yaw_is_far_off(l_room):
    # The first piece's prior is turned by 60 degrees: its quarter turn points the wrong
    # way. The other three priors, and the assembly they agree with, still decide.
    turns = [0, 1, 2, 3]
    pieces = chains_from_polygon(l_room, TIED_CUTS, turns)
    hints = _truth_priors(l_room, TIED_CUTS, turns)
    first = hints.priors["p0"]
    off = dataclasses.replace(first, yaw=first.yaw + math.radians(60.0))
    placement = place_pieces(pieces, GEOMETRY, SiteHints(priors={**hints.priors, "p0": off}))
    assert placement is not None
    assert placement.best.order == ("p0", "p1", "p2", "p3")
    assert list(placement.best.rotations) == [0, 3, 2, 1]
    # The far-off prior costs about what a Cauchy loss gives one outlier, no more.
    assert placement.best.features["prior"] < 4.0


def test_priors_whose_yaws_blur_the_frame_are_read_in_the_frame_the_loop_tells(l_room):
    # Twelve priors of 20 degrees whose yaw errors, taken modulo a quarter turn (all the
    # priors alone can tell), put the hints frame's yaw 33 degrees off its true 28.6: read
    # in that frame every prior misleads. The best loop knows each piece's quarter turn,
    # so the frame refitted from it is right, and the search run again there finds the room.
    errors = np.radians([-48, 7, -28, -30, 14, -24, 0, 22, 16, 31, 18, -36])
    cuts = [0.5 + 28.0 / 12 * k for k in range(12)]
    turns = [k % 4 for k in range(12)]
    pieces = chains_from_polygon(l_room, cuts, turns)
    exact = _truth_priors(l_room, cuts, turns).priors
    blurred_yaws = zip(exact.items(), errors, strict=True)
    priors = {k: dataclasses.replace(p, yaw=p.yaw + e) for (k, p), e in blurred_yaws}
    hints = SiteHints(priors=priors)
    truth = (tuple(f"p{k}" for k in range(12)), (0, 3, 2, 1) * 3)

    def off(yaw: float) -> float:  # degrees from the true frame, modulo a quarter turn
        return abs(math.degrees(wrap_angle(4.0 * (yaw - 0.5)) / 4.0))

    estimate = frame_estimate("p0", priors)
    assert estimate is not None and off(estimate.yaw) > 30.0
    once = GEOMETRY.model_copy(update={"frame_refit_deg": 360.0})  # the estimate only
    blurred = place_pieces(pieces, once, hints)
    assert blurred is not None and (blurred.best.order, blurred.best.rotations) != truth
    # The wrong loop found first agrees with the wrong frame within 5 degrees (the default
    # threshold does not search again); at 2 the refits lead to the room.
    assert off(loop_frame_yaw(pieces, blurred.best, hints)) > 25.0
    refit = GEOMETRY.model_copy(update={"frame_refit_deg": 2.0})
    placement = place_pieces(pieces, refit, hints)
    assert placement is not None and placement.frame_yaw is not None
    assert (placement.best.order, placement.best.rotations) == truth
    assert off(placement.frame_yaw) < 1.0
    assert placement.best.energy < blurred.best.energy
    # Scored in the frame the search settled on, the loop has the energy it was given.
    again = evaluate_placement(pieces, *truth, refit, hints, placement.frame_yaw)
    assert again is not None and again.energy == pytest.approx(placement.best.energy)


def test_a_loop_is_valid_whichever_piece_is_fixed_first():
    # Laid end to end from the first piece, a loop carries its junctions' overlaps and gaps
    # (here 0.3 m up the right wall, 0.5 m short along the top) to its last junction, where
    # the last piece then runs over the first's corner. Fixed first, any piece must give
    # the same valid loop: which is first depends only on names or priors.
    rect = np.array([[0, 0], [6, 0], [6, 4], [0, 4]], dtype=np.float64)
    pieces = chains_from_polygon(rect, [5.7, 8.0, 13.0, 18.0], [0, 0, 0, 0])

    def lengthened(piece: Piece, by: float) -> Piece:
        keypoints = piece.keypoints.copy()
        last = keypoints[-1] - keypoints[-2]
        keypoints[-1] += by * last / np.linalg.norm(last)
        return dataclasses.replace(piece, keypoints=keypoints)

    pieces = [lengthened(p, by) for p, by in zip(pieces, [0.3, -0.5, 0.0, 0.0], strict=True)]
    search = search_module._Search(pieces, GEOMETRY, SiteHints(), True)
    laid = search_module._placed_loop(search, [0, 1, 2, 3], [0, 0, 0, 0])
    assert laid is not None
    # Where it lies, the last piece's bottom wall runs across the first's right wall.
    assert search_module._crosses(laid.walls[-1:], laid.walls[:2])
    for k in range(4):
        led = pieces[k:] + pieces[:k]
        assert evaluate_placement(led, [p.id for p in led], [0, 0, 0, 0], GEOMETRY) is not None


def test_priors_pick_the_assignment_of_identical_pieces():
    # Which of four identical pieces goes where is only known from the priors.
    square = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], dtype=np.float64)
    cuts, turns = [2.0, 6.0, 10.0, 14.0], [0, 3, 2, 1]
    pieces = chains_from_polygon(square, cuts, turns)
    # Rename so the loop order is p0 p3 p1 p2.
    names = {"p0": "p0", "p1": "p3", "p2": "p1", "p3": "p2"}
    renamed = [dataclasses.replace(p, id=names[p.id]) for p in pieces]
    truth = _truth_priors(square, cuts, turns, frame=(1.0, (2.0, 2.0)))
    hints = SiteHints(priors={names[k]: v for k, v in truth.priors.items()})
    ordered = sorted(renamed, key=lambda p: p.id)
    free = place_pieces(ordered, GEOMETRY)
    assert free is not None and free.best.order != ("p0", "p3", "p1", "p2")
    placement = place_pieces(ordered, GEOMETRY, hints)
    assert placement is not None
    assert placement.best.order == ("p0", "p3", "p1", "p2")


# ---------------------------------------------------------------------------------------------
# Junction evidence in the search
# ---------------------------------------------------------------------------------------------


def test_structure_across_the_true_cuts_breaks_a_tie(l_room):
    # Each true junction has its own object crossing the cut, seen by both scans.
    rng = np.random.default_rng(0)
    pieces = chains_from_polygon(l_room, TIED_CUTS, [0, 0, 0, 0])

    def crossing(k: int) -> np.ndarray:
        lo = np.array([-0.6, 0.3 + 0.5 * k, 0.2 + 0.5 * k])
        legs = rng.uniform(lo, lo + np.array([0.1, 0.3, 0.3]), size=(1500, 3))
        body = rng.uniform(
            lo + np.array([0.3, 0.0, 0.0]), lo + np.array([1.1, 0.3, 0.3]), (3000, 3)
        )
        return np.vstack([legs, body])

    objects = [crossing(k) for k in range(4)]
    seen = [
        dataclasses.replace(p, target_region=objects[k], source_region=objects[k - 1], ceiling=2.5)
        for k, p in enumerate(pieces)
    ]
    params = PlacementParams(use_boundary=False, use_free_space=False)
    placement = place_pieces(seen, params)
    assert placement is not None
    assert placement.best.order == ("p0", "p1", "p2", "p3")
    assert placement.best.features["structure"] < -3.5
    swapped = evaluate_placement(seen, ["p0", "p2", "p1", "p3"], [0, 0, 0, 0], params)
    assert swapped is not None
    assert swapped.energy > placement.best.energy + 2.0


# ---------------------------------------------------------------------------------------------
# Open chains and invalid placements
# ---------------------------------------------------------------------------------------------


def test_a_single_partial_piece_gives_an_open_placement():
    square = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], dtype=np.float64)
    piece = chains_from_polygon(square, [1.0, 9.0], [0, 0])[0]
    placement = place_pieces([piece], GEOMETRY)
    assert placement is not None
    assert not placement.closed
    assert placement.best.order == (piece.id,)
    assert placement.best.missing == 0
    assert placement.translations == pytest.approx(np.zeros((1, 2)))


def test_a_single_closed_piece_closes():
    square = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], dtype=np.float64)
    whole = bare_piece("w", np.vstack([[2.0, 0.0], square[1:], square[:1], [[1.9, 0.0]]]))
    placement = place_pieces([whole], GEOMETRY)
    assert placement is not None and placement.closed


def test_no_pieces_no_placement():
    assert place_pieces([], GEOMETRY) is None


def test_invalid_placements_are_rejected(l_room):
    pieces = chains_from_polygon(l_room, DISTINCT_CUTS, [0, 0, 0, 0])
    assert evaluate_placement(pieces, ["p0", "p1", "p2", "p3"], [0, 0, 0, 0], GEOMETRY)
    # Folding a piece back onto the previous wall (a 180 degree junction) is not a loop.
    assert evaluate_placement(pieces, ["p0", "p1", "p2", "p3"], [0, 2, 0, 0], GEOMETRY) is None
    # The fixed piece must come first, unturned; every piece exactly once.
    assert evaluate_placement(pieces, ["p1", "p0", "p2", "p3"], [0, 0, 0, 0], GEOMETRY) is None
    assert evaluate_placement(pieces, ["p0", "p1", "p2", "p3"], [1, 1, 1, 1], GEOMETRY) is None
    assert evaluate_placement(pieces, ["p0", "p1", "p2", "p2"], [0, 0, 0, 0], GEOMETRY) is None
    assert evaluate_placement(pieces, ["p0", "p1", "p2"], [0, 0, 0], GEOMETRY) is None


def test_crossing_walls_are_rejected(l_room):
    # p3 right after p0 (a left turn at the junction) runs its long wall back through p0's.
    pieces = chains_from_polygon(l_room, DISTINCT_CUTS, [0, 0, 0, 0])
    assert evaluate_placement(pieces, ["p0", "p3", "p2", "p1"], [0, 0, 0, 0], GEOMETRY) is None


# Walls as (axis, offset, lo, hi): axis 0 runs along x at y = offset, axis 1 along y.
HORIZONTAL = np.array([[0.0, 0.0, 0.0, 4.0]])


@pytest.mark.parametrize(
    ("wall", "crosses"),
    [
        ([1.0, 2.0, -1.0, 1.0], True),  # through the middle
        ([1.0, 4.0, 0.0, 3.0], False),  # a corner: touching at the end
        ([1.0, 2.0, 0.0, 3.0], False),  # a T: touching at its own end
        ([1.0, 2.0, 0.03, 3.0], False),  # within the 5 cm a touch may miss by
        ([1.0, 2.0, -0.2, 3.0], True),  # past it
        ([0.0, 0.02, 3.0, 6.0], True),  # on the same line, overlapping by 1 m
        ([0.0, 0.0, 3.97, 6.0], False),  # on the same line, touching end to end
        ([0.0, 0.2, 1.0, 3.0], False),  # parallel, 20 cm apart
    ],
)
def test_walls_cross_only_where_they_pass_through_each_other(wall, crosses):
    new = np.array([wall])
    assert search_module._crosses(new, HORIZONTAL) is crosses
    assert search_module._crosses(HORIZONTAL, new) is crosses
    far = new + np.array([0.0, 50.0, 0.0, 0.0])  # another wall, far away, changes nothing
    assert search_module._crosses(np.vstack([new, far]), HORIZONTAL) is crosses


def test_evaluate_placement_agrees_with_the_search(l_room):
    pieces = chains_from_polygon(l_room, TIED_CUTS, [0, 1, 2, 3])
    placement = place_pieces(pieces, GEOMETRY)
    assert placement is not None
    for cand in placement.candidates:
        again = evaluate_placement(pieces, cand.order, cand.rotations, GEOMETRY)
        assert again is not None
        assert again.energy == pytest.approx(cand.energy)
        assert again.features == pytest.approx(dict(cand.features))


def test_a_piece_with_a_very_short_wall_does_not_crash(l_room):
    # Cuts 5 cm apart leave a piece of a single 5 cm wall.
    pieces = chains_from_polygon(l_room, [4.0, 14.3, 26.56, 26.61], [0, 1, 2, 3])
    assert len(pieces[2].keypoints) == 2 and pieces[2].length < 0.1
    placement = place_pieces(pieces, GEOMETRY)
    assert placement is not None
