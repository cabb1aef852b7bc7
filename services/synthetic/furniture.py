"""Doors, windows and furniture for synthetic rooms (world frame, z up, meters).

Furniture is axis-aligned boxes (rooms are rectilinear). Wall-side pieces stand against one
wall and hide the wall behind them up to their height; free-standing pieces keep half a meter
of floor to every wall. Openings cut the wall: doors from the floor up, windows in between.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.geometry import points_in_polygon, signed_area
from services.synthetic.room import Room, point_at_arc
from services.types import FloatArray

__all__ = ["Box", "Furnishing", "Opening", "WallCover", "furnish_room", "transient_boxes"]


@dataclass(frozen=True)
class Box:
    """An axis-aligned box, world frame. lo, hi: (3,) corners.

    hidden: faces never seen, as (axis, side) with side 0 at lo and 1 at hi.
    solid: hides the floor beneath it (false for tables on legs).
    """

    lo: FloatArray
    hi: FloatArray
    hidden: tuple[tuple[int, int], ...] = ((2, 0),)
    solid: bool = True


@dataclass(frozen=True)
class WallCover:
    """Wall of edge ``edge`` hidden behind furniture: t in [t0, t1] along it, z below height."""

    edge: int
    t0: float
    t1: float
    height: float


@dataclass(frozen=True)
class Opening:
    """A door (z0 = 0) or window: no wall for t in [t0, t1] along edge ``edge``, z in [z0, z1]."""

    edge: int
    t0: float
    t1: float
    z0: float
    z1: float


@dataclass(frozen=True)
class Furnishing:
    """What a room holds besides its bare walls, floor and ceiling."""

    boxes: tuple[Box, ...] = ()
    covers: tuple[WallCover, ...] = ()
    openings: tuple[Opening, ...] = ()
    wall_thickness: float = 0.15


# (width, depth, height) ranges in meters.
_WALL_KINDS = (
    ((0.8, 2.0), (0.55, 0.65), (1.9, 2.2)),  # wardrobe
    ((0.6, 1.6), (0.30, 0.40), (1.5, 2.1)),  # shelf
    ((1.6, 2.4), (0.80, 1.00), (0.75, 0.9)),  # sofa
    ((0.6, 1.5), (0.40, 0.50), (0.8, 1.0)),  # low cabinet
    ((1.0, 1.6), (0.60, 0.80), (0.72, 0.78)),  # desk
)
_FREE_KINDS = (
    ((0.8, 1.8), (0.6, 1.0), (0.72, 0.78)),  # table on legs
    ((0.8, 1.2), (0.4, 0.7), (0.35, 0.5)),  # coffee table
    ((0.7, 0.9), (0.7, 0.9), (0.75, 0.9)),  # armchair
)


def furnish_room(
    rng: np.random.Generator,
    room: Room,
    keep_clear: list[tuple[int, float]],
    *,
    clutter: float,
    furniture: bool,
    openings: bool,
    clearance: float,
) -> Furnishing:
    """Random doors, windows and furniture for a room.

    keep_clear: (edge, t) wall positions that no opening or wall-side furniture may come
    within ``clearance`` of (the ends of the fragments' visible stretches, so every stretch
    starts and ends on plain wall). Wall-side furniture is at most 2.2 m tall, so the top
    of every wall stays visible; covers list the wall hidden behind it.
    """
    taken: list[list[tuple[float, float]]] = [[] for _ in range(room.n_edges)]
    for e, t in keep_clear:
        taken[e].append((t - clearance, t + clearance))
    found = _openings(rng, room, taken) if openings else []
    boxes: list[Box] = []
    covers: list[WallCover] = []
    if furniture:
        _wall_furniture(rng, room, taken, clutter, boxes, covers)
        _free_furniture(rng, room, clutter, boxes)
    thickness = float(rng.uniform(0.1, 0.25))
    return Furnishing(tuple(boxes), tuple(covers), tuple(found), thickness)


def transient_boxes(
    rng: np.random.Generator,
    room: Room,
    boxes: tuple[Box, ...],
    start: float,
    length: float,
    level: float,
    reach: float,
) -> tuple[Box, ...]:
    """Objects present during one scan only (people, carts, boxes), in front of its stretch.

    About ``level`` per 4 m of the stretch (arc ``start``, ``length`` m along the loop): boxes
    0.3-0.8 m wide, 0.3-1.8 m tall, 0.3 m to min(reach, 3 m) from the wall, in the room and
    clear of ``boxes``. World frame.
    """
    found: list[Box] = []
    for _ in range(int(rng.poisson(level * length / 4.0))):
        foot, edge = point_at_arc(room, np.array([start + rng.uniform(0.0, length)]))
        centre = foot[0] + rng.uniform(0.3, max(0.3, min(reach, 3.0))) * room.normals[edge[0]]
        half = 0.5 * rng.uniform(0.3, 0.8, 2)
        lo, hi, height = centre - half, centre + half, float(rng.uniform(0.3, 1.8))
        if _footprint_free(room, lo, hi, [*boxes, *found], wall_clear=0.05, margin=0.05):
            found.append(Box(np.append(lo, 0.0), np.append(hi, height)))
    return tuple(found)


def _openings(
    rng: np.random.Generator, room: Room, taken: list[list[tuple[float, float]]]
) -> list[Opening]:
    n_doors = 1 + int(rng.poisson(room.perimeter / 30.0))
    n_windows = int(rng.poisson(room.perimeter / 8.0))
    found: list[Opening] = []
    for k in range(n_doors + n_windows):
        door = k < n_doors
        width = rng.uniform(0.8, 1.0) if door else rng.uniform(0.8, 2.2)
        z0 = 0.0 if door else rng.uniform(0.8, 1.0)
        z1 = min(rng.uniform(2.0, 2.1), room.height - 0.25)
        e = int(rng.choice(room.n_edges, p=room.lengths / room.perimeter))
        t0 = _edge_slot(rng, room.lengths[e], width, taken[e], end_margin=0.3)
        if t0 is not None:
            taken[e].append((t0 - 0.3, t0 + width + 0.3))
            found.append(Opening(e, t0, t0 + width, float(z0), float(z1)))
    return found


def _wall_furniture(
    rng: np.random.Generator,
    room: Room,
    taken: list[list[tuple[float, float]]],
    clutter: float,
    boxes: list[Box],
    covers: list[WallCover],
) -> None:
    for e in range(room.n_edges):
        for _ in range(int(rng.poisson(clutter * room.lengths[e] / 4.0))):
            widths, depths, heights = _WALL_KINDS[int(rng.integers(len(_WALL_KINDS)))]
            width = min(rng.uniform(*widths), 0.6 * room.lengths[e])
            depth, height = rng.uniform(*depths), rng.uniform(*heights)
            t0 = _edge_slot(rng, room.lengths[e], width, taken[e], end_margin=0.05)
            if t0 is None:
                continue
            gap = rng.uniform(0.01, 0.05)
            d, n = room.dirs[e], room.normals[e]
            a = room.polygon[e] + t0 * d + gap * n
            b = room.polygon[e] + (t0 + width) * d + (gap + depth) * n
            lo, hi = np.minimum(a, b), np.maximum(a, b)
            if not _footprint_free(room, lo, hi, boxes, wall_clear=0.0, margin=0.02):
                continue
            axis = int(np.argmax(np.abs(n)))
            back = (axis, 0 if n[axis] > 0 else 1)  # the face touching the wall
            boxes.append(Box(np.append(lo, 0.0), np.append(hi, height), ((2, 0), back)))
            covers.append(WallCover(e, t0, t0 + width, height))
            taken[e].append((t0 - 0.05, t0 + width + 0.05))


def _free_furniture(rng: np.random.Generator, room: Room, clutter: float, boxes: list[Box]) -> None:
    top = room.polygon.max(axis=0)
    for _ in range(int(rng.poisson(clutter * signed_area(room.polygon) / 12.0))):
        kind = int(rng.integers(len(_FREE_KINDS)))
        widths, depths, heights = _FREE_KINDS[kind]
        size = np.array([rng.uniform(*widths), rng.uniform(*depths)])
        size = size[::-1] if rng.random() < 0.5 else size
        lo = rng.uniform(0.0, 1.0, 2) * np.maximum(top - size, 0.0)
        hi, height = lo + size, float(rng.uniform(*heights))
        # Half a meter of floor around free furniture keeps it apart from the walls.
        if not _footprint_free(room, lo, hi, boxes, wall_clear=0.5, margin=0.3):
            continue
        if kind == 0:
            boxes.extend(_table(lo, hi, height))
        else:
            boxes.append(Box(np.append(lo, 0.0), np.append(hi, height)))


def _table(lo: FloatArray, hi: FloatArray, height: float) -> list[Box]:
    """A 4 cm top on four 5 cm legs; the floor below stays visible."""
    parts = [Box(np.append(lo, height - 0.04), np.append(hi, height), solid=False)]
    for x in (lo[0] + 0.03, hi[0] - 0.08):
        for y in (lo[1] + 0.03, hi[1] - 0.08):
            leg_lo = np.array([x, y, 0.0])
            leg_hi = np.array([x + 0.05, y + 0.05, height - 0.04])
            parts.append(Box(leg_lo, leg_hi, ((2, 0), (2, 1)), solid=False))
    return parts


def _edge_slot(
    rng: np.random.Generator,
    length: float,
    width: float,
    taken: list[tuple[float, float]],
    *,
    end_margin: float,
) -> float | None:
    """A start t0 for a width-long interval on an edge, clear of the taken intervals."""
    high = length - end_margin - width
    for _ in range(15):
        if high < end_margin:
            return None
        t0 = float(rng.uniform(end_margin, high))
        if all(t0 + width <= a or t0 >= b for a, b in taken):
            return t0
    return None


def _footprint_free(
    room: Room,
    lo: FloatArray,
    hi: FloatArray,
    boxes: list[Box] | tuple[Box, ...],
    *,
    wall_clear: float,
    margin: float,
) -> bool:
    """True when [lo, hi] grown by ``wall_clear`` lies in the room and keeps ``margin`` from boxes.

    A grid of probes every <= 0.4 m (finer than the narrowest corridor) and a no-vertex-inside
    test make the containment check exact enough for rectilinear rooms.
    """
    lo_in, hi_in = lo - wall_clear, hi + wall_clear
    steps = np.maximum(np.ceil((hi_in - lo_in) / 0.4).astype(int) + 1, 2)
    gx, gy = np.meshgrid(
        np.linspace(lo_in[0] + 1e-3, hi_in[0] - 1e-3, steps[0]),
        np.linspace(lo_in[1] + 1e-3, hi_in[1] - 1e-3, steps[1]),
    )
    if not points_in_polygon(np.column_stack([gx.ravel(), gy.ravel()]), room.polygon).all():
        return False
    v = room.polygon
    inner = (v > lo_in) & (v < hi_in)
    if np.any(inner[:, 0] & inner[:, 1]):
        return False
    return all(np.any(lo >= b.hi[:2] + margin) or np.any(hi <= b.lo[:2] - margin) for b in boxes)
