"""Where the room loop is cut into the fragments' stretches, and what each junction is.

Arc positions run along the counter-clockwise room loop from polygon vertex 0, in
[0, perimeter), meters. A cut is where two neighbouring stretches meet: (edge, t along the
edge, gap); gap > 0 leaves that much wall unseen between them, gap < 0 makes them overlap by
that much. Two cut models:

- "edges" (:func:`edge_cuts`): at most one cut per edge (two on a long edge for a straight
  stretch), every cut ``end_margin`` plus half the largest gap from corners.
- "arc" (:func:`arc_cuts`): n cuts anywhere on the loop, several on one long edge, at least
  ``min_stretch`` of visible wall per stretch, ``end_margin`` from corners unless moved onto a
  corner.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import NDArray

from services.geometry import cross
from services.synthetic.room import Room
from services.synthetic.scan import Stretch
from services.types import FloatArray

if TYPE_CHECKING:
    from services.synthetic.scene import SceneSpec

__all__ = ["Cut", "arc_cuts", "cut_turns", "edge_cuts", "furniture_clearance", "stretches"]

_MIN_STRAIGHT = 2.5  # shortest stretch that sees a single straight wall ("edges" model)
_CORNER_GAP = (0.1, 0.4)  # m, unseen wall around a corner where a cut falls on it ("edges")


class Cut(NamedTuple):
    """Where stretch k - 1 ends and stretch k starts: arc ``room.arcs[edge] + t``, ``gap``."""

    edge: int
    t: float
    gap: float


def edge_cuts(rng: np.random.Generator, spec: SceneSpec, room: Room) -> list[Cut] | None:
    """The "edges" model: cuts sorted along the loop, or None when the room has too few edges.

    Cuts stay ``end_margin`` (plus half the largest gap) from corners; distinct edges between
    cuts give every stretch at least one corner; two cuts on one long edge give a straight
    stretch (``straight_fragments``). A share ``corner_cut_share`` of the cuts then moves
    onto a corner (:func:`_cuts_at_corners`).
    """
    margin = spec.end_margin + 0.5 * max(abs(g) for g in spec.gap_range)
    slots = [e for e in range(room.n_edges) if room.lengths[e] >= 2 * margin + 0.1]
    if spec.straight_fragments:
        slots += [e for e in slots if room.lengths[e] >= 2 * margin + _MIN_STRAIGHT + 0.01]
    n = min(int(rng.integers(spec.n_fragments_range[0], spec.n_fragments_range[1] + 1)), len(slots))
    if n < 2:
        return None
    edges = np.array(slots)[rng.choice(len(slots), n, replace=False)]
    cuts: list[Cut] = []
    for e in np.unique(edges):
        length = room.lengths[e]
        if np.count_nonzero(edges == e) == 1:
            ts = [rng.uniform(margin, length - margin)]
        else:
            first = rng.uniform(margin, length - margin - _MIN_STRAIGHT)
            ts = [first, rng.uniform(first + _MIN_STRAIGHT, length - margin)]
        cuts += [Cut(int(e), float(t), float(rng.uniform(*spec.gap_range))) for t in ts]
    cuts = sorted(cuts, key=lambda c: room.arcs[c[0]] + c[1])
    if spec.corner_cut_share > 0.0:
        cuts = _cuts_at_corners(rng, spec, room, cuts)
    return cuts


def _cuts_at_corners(
    rng: np.random.Generator, spec: SceneSpec, room: Room, cuts: list[Cut]
) -> list[Cut]:
    """Move a share of the cuts onto the corner that starts their edge, with a gap that
    hides the corner. Only cuts alone on their edge whose previous cut is two or more edges
    back move, so both neighbouring stretches keep a corner of their own."""
    edges = [e for e, _, _ in cuts]
    out = []
    for k, (e, t, gap) in enumerate(cuts):
        previous = edges[k - 1]
        alone = edges.count(e) == 1
        far = (e - previous) % room.n_edges >= 2 or len(cuts) == 1
        if rng.random() < spec.corner_cut_share and alone and far:
            out.append(Cut(e, 0.0, float(rng.uniform(_CORNER_GAP[0], _CORNER_GAP[1]))))
        else:
            out.append(Cut(e, t, gap))
    return out


def arc_cuts(
    rng: np.random.Generator, spec: SceneSpec, room: Room, *, fit: bool = False
) -> list[Cut] | None:
    """The "arc" model: n cuts anywhere on the loop, sorted along it.

    n is drawn from ``n_fragments_range``. Consecutive cuts are at least ``min_stretch`` plus
    the largest positive gap apart, so every stretch shows at least ``min_stretch`` of wall
    whatever the gaps; cuts keep ``end_margin`` from corners (positions are drawn uniformly on
    the loop with those stretches taken out). A share ``corner_cut_share`` then moves onto
    the nearest corner when that keeps the spacing. Gaps are drawn from ``gap_range``.

    Returns None when the room cannot hold n cuts (or fewer than 2), unless ``fit``: then as
    many as fit (a given room shape cannot be redrawn).
    """
    n = int(rng.integers(spec.n_fragments_range[0], spec.n_fragments_range[1] + 1))
    spacing = spec.min_stretch + max(spec.gap_range[1], 0.0)
    allowed = np.maximum(room.lengths - 2.0 * spec.end_margin, 0.0)
    capacity = math.floor(float(allowed.sum()) / spacing)
    if n > capacity and fit:
        n = capacity
    if n < 2 or n > capacity:
        return None
    arcs = _spread(rng, room, allowed, n, spacing, spec.end_margin)
    if spec.corner_cut_share > 0.0:
        arcs = _onto_corners(arcs, rng.random(n) < spec.corner_cut_share, room, spacing)
    gaps = rng.uniform(spec.gap_range[0], spec.gap_range[1], n)
    order = np.argsort(arcs)
    edges = np.clip(np.searchsorted(room.arcs, arcs, side="right") - 1, 0, room.n_edges - 1)
    return [Cut(int(edges[k]), float(arcs[k] - room.arcs[edges[k]]), float(gaps[k])) for k in order]


def _spread(
    rng: np.random.Generator,
    room: Room,
    allowed: FloatArray,
    n: int,
    spacing: float,
    margin: float,
) -> FloatArray:
    """(n,) arc positions, uniformly random, ``spacing`` apart at least, in the allowed
    stretches ([margin, length - margin] of every edge; ``allowed`` (V,) their lengths).

    Drawn on the loop with the forbidden stretches taken out (length ``allowed.sum()``),
    where spacing is kept; putting them back only moves cuts further apart.
    """
    total = float(allowed.sum())
    steps = spacing + (total - n * spacing) * rng.dirichlet(np.ones(n))
    packed = np.mod(rng.uniform(0.0, total) + np.concatenate([[0.0], np.cumsum(steps[:-1])]), total)
    starts = np.concatenate([[0.0], np.cumsum(allowed)])
    edge = np.clip(np.searchsorted(starts, packed, side="right") - 1, 0, room.n_edges - 1)
    arcs: FloatArray = np.mod(room.arcs[edge] + margin + (packed - starts[edge]), room.perimeter)
    return arcs


def _onto_corners(
    arcs: FloatArray, move: NDArray[np.bool_], room: Room, spacing: float
) -> FloatArray:
    """Move the flagged cuts onto their nearest corner when every other cut stays
    ``spacing`` away from it along the loop."""
    out = arcs.copy()
    for k in np.flatnonzero(move):
        corner = float(room.arcs[np.argmin(np.abs(room.arcs - out[k]))] % room.perimeter)
        distance = np.abs(
            np.mod(out - corner + 0.5 * room.perimeter, room.perimeter) - 0.5 * room.perimeter
        )
        distance[k] = np.inf
        if distance.min() >= spacing:
            out[k] = corner
    return out


def stretches(room: Room, cuts: list[Cut]) -> list[Stretch]:
    """Stretch k runs from cut k to cut k + 1 (cyclic), shrunk or grown by half of each gap."""
    arcs = [room.arcs[e] + t for e, t, _ in cuts]
    out = []
    for k, (start, gap) in enumerate(zip(arcs, (g for _, _, g in cuts), strict=True)):
        nxt = (k + 1) % len(cuts)
        end = arcs[nxt] + (room.perimeter if nxt == 0 else 0.0) - 0.5 * cuts[nxt][2]
        begin = start + 0.5 * gap
        out.append(Stretch(float(np.mod(begin, room.perimeter)), float(end - begin)))
    return out


def cut_turns(room: Room, cuts: list[Cut]) -> list[int]:
    """Per cut, the signed quarter turns of the room corners inside its junction.

    The junction is the loop between the two stretch ends, ``|gap|`` long and centred on the
    cut: unseen wall for a gap, wall both see for an overlap. A convex (left) corner counts
    +1, a reflex one -1; 0 for a straight junction.
    """
    before = np.roll(room.dirs, 1, axis=0)  # the edge arriving at vertex v, (V, 2)
    signs = np.where(cross(before, room.dirs) > 0.0, 1, -1)
    turns = []
    for e, t, gap in cuts:
        low = room.arcs[e] + t - 0.5 * abs(gap)
        inside = np.mod(room.arcs[:-1] - low, room.perimeter) <= abs(gap) + 1e-9
        turns.append(int(signs[inside].sum()))
    return turns


def furniture_clearance(spec: SceneSpec, cuts: list[Cut]) -> tuple[list[tuple[int, float]], float]:
    """Cut positions (edge, t) that openings and wall furniture keep clear of, and by how much.

    ``end_margin`` of plain wall beyond each stretch end (so half the largest gap more). With
    the "arc" model and ``end_margin == 0`` nothing is kept clear: doors, windows and furniture
    may then cross cuts and be seen in part by both neighbours.
    """
    if spec.cut_model == "arc" and spec.end_margin <= 0.0:
        return [], 0.0
    clearance = spec.end_margin + 0.5 * max(abs(g) for g in spec.gap_range)
    return [(e, t) for e, t, _ in cuts], clearance
