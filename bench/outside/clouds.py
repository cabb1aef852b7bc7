"""Point-cloud rooms: one Manhattan room scanned region by region, cut into fragments.

A scene is a room outline (six synthetic kinds, or a real MatterportLayout outline snapped
to Manhattan), its surfaces sampled like a scanner (walls, floor, a partial ceiling, door and
window reveals, what is seen through doors of the next room, furniture), the wall loop cut
into N arcs (overlaps up to 0.5 m, gaps up to 0.3 m) whose floor, ceiling and furniture are
the Voronoi-like sectors nearest each arc, each fragment with its own density and noise,
moved by a random rigid motion (yaw, tilt up to 3 degrees, shift) and written as a binary
little-endian PLY. The truth (``truth.json``) holds the poses (fragment-local to world, z
up, floor at z = 0), the counter-clockwise outline and what the room holds.

    .venv/bin/python -m bench.outside.clouds --seed 7 --kind T --n 3 --out /tmp/scene
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from bench.room_shapes import DEFAULT_PATH, raw_outlines

__all__ = [
    "SYN_KINDS",
    "boundary_project",
    "generate",
    "make_ccw",
    "points_in_poly",
    "real_pool",
    "signed_area",
    "write_ply",
]

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
Rng = np.random.Generator

SYN_KINDS = ("rect", "L", "U", "T", "corridor", "comb")
# name: width, depth, height ranges (meters) of furniture against a wall ...
_WALL_BOXES = {
    "cabinet": ((0.6, 2.0), (0.35, 0.6), (0.7, 1.2)),
    "sofa": ((1.5, 2.4), (0.8, 1.0), (0.7, 0.9)),
    "wardrobe": ((0.8, 2.0), (0.55, 0.65), (1.8, 2.0)),
    "shelf": ((0.6, 1.2), (0.3, 0.4), (1.2, 2.0)),
    "desk": ((1.0, 1.6), (0.6, 0.8), (0.72, 0.78)),
}
# ... and free-standing
_FREE_BOXES = {
    "table": ((0.8, 1.8), (0.6, 1.0), (0.7, 0.78)),
    "bed": ((1.9, 2.1), (0.9, 1.8), (0.45, 0.6)),
    "chair": ((0.4, 0.55), (0.4, 0.55), (0.8, 1.0)),
    "island": ((1.0, 2.0), (0.6, 1.0), (0.85, 0.95)),
}


# --------------------------------------------------------------------------- polygons
def signed_area(P: Any) -> float:
    """Signed area of a polygon, (K, 2) meters; positive when counter-clockwise."""
    P = np.asarray(P, float)
    x, y = P[:, 0], P[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def make_ccw(P: Any) -> FloatArray:
    """The polygon, (K, 2), reversed when clockwise."""
    P = np.asarray(P, float)
    return P if signed_area(P) > 0 else P[::-1].copy()


def remove_collinear(P: Any, tol: float = 1e-6) -> FloatArray:
    """The polygon without duplicate vertices and vertices between collinear edges."""
    P = np.asarray(P, float)
    changed = True
    while changed and len(P) > 3:
        changed = False
        for i in range(len(P)):
            a, b, c = P[i - 1], P[i], P[(i + 1) % len(P)]
            ab, bc = float(np.linalg.norm(b - a)), float(np.linalg.norm(c - b))
            cross = (b - a)[0] * (c - b)[1] - (b - a)[1] * (c - b)[0]
            if ab < tol or bc < tol or abs(cross) < tol * max(1.0, ab * bc):
                P = np.delete(P, i, axis=0)
                changed = True
                break
    return P


def is_manhattan(P: FloatArray, tol: float = 1e-6) -> bool:
    """Whether every edge is parallel to the x or the y axis."""
    d = np.roll(P, -1, axis=0) - P
    return bool(np.all((np.abs(d[:, 0]) <= tol) | (np.abs(d[:, 1]) <= tol)))


def _orient(a: FloatArray, b: FloatArray, c: FloatArray) -> float:
    return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


def _on_segment(a: FloatArray, b: FloatArray, c: FloatArray) -> bool:
    return bool(
        min(a[0], b[0]) - 1e-9 <= c[0] <= max(a[0], b[0]) + 1e-9
        and min(a[1], b[1]) - 1e-9 <= c[1] <= max(a[1], b[1]) + 1e-9
    )


def _segments_meet(p1: FloatArray, p2: FloatArray, q1: FloatArray, q2: FloatArray) -> bool:
    """Whether two segments cross or touch."""
    d1, d2 = _orient(q1, q2, p1), _orient(q1, q2, p2)
    d3, d4 = _orient(p1, p2, q1), _orient(p1, p2, q2)
    if d1 * d2 < 0 and d3 * d4 < 0 and min(abs(d1), abs(d2), abs(d3), abs(d4)) > 1e-9:
        return True
    touches = ((d1, q1, q2, p1), (d2, q1, q2, p2), (d3, p1, p2, q1), (d4, p1, p2, q2))
    return any(abs(d) <= 1e-9 and _on_segment(a, b, c) for d, a, b, c in touches)


def is_simple(P: FloatArray) -> bool:
    """Whether no two non-adjacent edges of the polygon meet."""
    n = len(P)
    for i in range(n):
        for j in range(i + 2, n):
            if (j + 1) % n == i:
                continue
            if _segments_meet(P[i], P[(i + 1) % n], P[j], P[(j + 1) % n]):
                return False
    return True


def min_edge(P: FloatArray) -> float:
    """Length of the polygon's shortest edge."""
    return float(np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1).min())


def points_in_poly(xy: FloatArray, P: FloatArray) -> BoolArray:
    """Which of the (M, 2) points are inside the polygon (even-odd rule)."""
    x, y = xy[:, 0], xy[:, 1]
    inside = np.zeros(len(xy), bool)
    for i in range(len(P)):
        x1, y1 = P[i]
        x2, y2 = P[(i + 1) % len(P)]
        if y1 == y2:
            continue
        cond = (y1 > y) != (y2 > y)
        xint = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
        inside ^= cond & (x < xint)
    return inside


def boundary_project(
    xy: FloatArray, P: FloatArray, cum: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Distance of each (M, 2) point to the polygon's boundary, and the perimeter parameter
    (meters from vertex 0, ``cum`` from :func:`perimeter_cum`) of its nearest boundary point."""
    best_d = np.full(len(xy), np.inf)
    best_t = np.zeros(len(xy))
    for i in range(len(P)):
        a, b = P[i], P[(i + 1) % len(P)]
        ab = b - a
        L2 = float(ab @ ab)
        u = np.clip(((xy - a) @ ab) / L2, 0.0, 1.0)
        d = np.linalg.norm(xy - (a + u[:, None] * ab), axis=1)
        m = d < best_d
        best_d[m] = d[m]
        best_t[m] = cum[i] + u[m] * math.sqrt(L2)
    return best_d, best_t


def perimeter_cum(P: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(K + 1,) perimeter parameter of each vertex (then the perimeter), and (K,) edge lengths."""
    lengths = np.array([np.linalg.norm(P[(i + 1) % len(P)] - P[i]) for i in range(len(P))])
    return np.concatenate([[0.0], np.cumsum(lengths)]), lengths


# --------------------------------------------------------------------------- room kinds
def _room_rect(rng: Rng) -> list[tuple[float, float]]:
    W, H = rng.uniform(3, 9), rng.uniform(3, 9)
    return [(0, 0), (W, 0), (W, H), (0, H)]


def _room_l(rng: Rng) -> list[tuple[float, float]]:
    W, H = rng.uniform(4, 9), rng.uniform(4, 9)
    a = rng.uniform(1.2, W - 1.5)
    b = rng.uniform(1.2, H - 1.5)
    return [(0, 0), (W, 0), (W, H - b), (W - a, H - b), (W - a, H), (0, H)]


def _room_u(rng: Rng) -> list[tuple[float, float]]:
    W, H = rng.uniform(5, 9), rng.uniform(4, 9)
    a = rng.uniform(1.2, W - 2.6)
    b = rng.uniform(1.0, H - 1.5)
    x0 = rng.uniform(1.2, W - 1.2 - a)
    return [(0, 0), (W, 0), (W, H), (x0 + a, H), (x0 + a, H - b), (x0, H - b), (x0, H), (0, H)]


def _room_t(rng: Rng) -> list[tuple[float, float]]:
    W = rng.uniform(5, 9)
    h1 = rng.uniform(2.0, 4.0)
    a = rng.uniform(1.8, W - 2.0)
    h2 = rng.uniform(1.5, 4.5)
    x0 = rng.uniform(0.8, W - a - 0.8)
    return [
        (x0, 0), (x0 + a, 0), (x0 + a, h2), (W, h2), (W, h2 + h1), (0, h2 + h1), (0, h2), (x0, h2),
    ]  # fmt: skip


def _room_corridor(rng: Rng) -> list[tuple[float, float]]:
    w = rng.uniform(1.8, 2.5)
    L = rng.uniform(5.0, 14.0)
    if rng.random() < 0.6:
        return [(0, 0), (L, 0), (L, w), (0, w)]
    L2 = rng.uniform(3.0, 9.0)  # an L-shaped corridor
    return [(0, 0), (L, 0), (L, L2), (L - w, L2), (L - w, w), (0, w)]


def _room_comb(rng: Rng) -> list[tuple[float, float]]:
    """A rectangle whose top wall carries pilasters (inward notches) or alcoves (outward)."""
    W, H = rng.uniform(5, 9), rng.uniform(3.5, 8)
    k = int(rng.integers(1, 4))
    for _ in range(100):  # k disjoint intervals on (0.6, W - 0.6)
        xs = np.sort(rng.uniform(0.6, W - 0.6, 2 * k))
        widths = xs[1::2] - xs[0::2]
        gaps = xs[2::2] - xs[1:-1:2] if k > 1 else np.array([1.0])
        if widths.min() >= 0.4 and (k == 1 or gaps.min() >= 0.6):
            break
    else:
        return _room_rect(rng)
    outward = rng.random() < 0.5
    pts = [(0, 0), (W, 0), (W, H)]
    for j in reversed(range(k)):
        x1, x2 = xs[2 * j], xs[2 * j + 1]
        yy = H + rng.uniform(0.5, 2.0) if outward else H - rng.uniform(0.3, min(1.5, H - 2.0))
        pts += [(x2, H), (x2, yy), (x1, yy), (x1, H)]
    return [*pts, (0, H)]


_ROOMS = {
    "rect": _room_rect,
    "L": _room_l,
    "U": _room_u,
    "T": _room_t,
    "corridor": _room_corridor,
    "comb": _room_comb,
}


# --------------------------------------------------------------------------- real outlines
def _dominant_turn(P: FloatArray) -> FloatArray:
    """The outline turned so that its edges' dominant direction (mod 90 deg) is along x."""
    E = np.roll(P, -1, axis=0) - P
    L = np.linalg.norm(E, axis=1)
    if L.min() < 1e-6:
        P = P[L >= 1e-6]
        E = np.roll(P, -1, axis=0) - P
        L = np.linalg.norm(E, axis=1)
    ang = np.arctan2(E[:, 1], E[:, 0])
    theta = np.angle(np.sum(L * np.exp(4j * ang))) / 4.0
    c, s = math.cos(-theta), math.sin(-theta)
    return P @ np.array([[c, -s], [s, c]]).T


def _edge_lines(P: FloatArray, angle_tol_deg: float) -> list[list[Any]] | None:
    """Each edge as [orientation "H" or "V", coordinate, length]; None if one is oblique."""
    E = np.roll(P, -1, axis=0) - P
    edges = []
    for i, a in enumerate(np.degrees(np.arctan2(E[:, 1], E[:, 0]))):
        m = a % 90.0
        if min(m, 90.0 - m) > angle_tol_deg:
            return None
        horizontal = round(float(a) / 90.0) % 4 in (0, 2)
        p, q = P[i], P[(i + 1) % len(P)]
        coord = (p[1] + q[1]) / 2 if horizontal else (p[0] + q[0]) / 2
        edges.append(["H" if horizontal else "V", coord, float(np.linalg.norm(q - p))])
    return edges


def _merge_same(edges: list[list[Any]]) -> list[list[Any]]:
    """Consecutive lines of one orientation merged into one (length-weighted coordinate)."""
    changed = True
    while changed and len(edges) > 1:
        changed = False
        for i in range(len(edges)):
            j = (i + 1) % len(edges)
            if edges[i][0] == edges[j][0]:
                Lt = edges[i][2] + edges[j][2]
                co = (edges[i][1] * edges[i][2] + edges[j][1] * edges[j][2]) / max(Lt, 1e-9)
                edges[i] = [edges[i][0], co, Lt]
                del edges[j]
                changed = True
                break
    return edges


def _vertices(edges: list[list[Any]]) -> FloatArray:
    """Vertex k: where line k - 1 meets line k."""
    V = []
    for k in range(len(edges)):
        e0, e1 = edges[k - 1], edges[k]
        V.append((e1[1], e0[1]) if e0[0] == "H" else (e0[1], e1[1]))
    return np.array(V)


def _drop_short_edges(edges: list[list[Any]], shortest: float) -> FloatArray | None:
    """Vertices of the lines once every edge shorter than ``shortest`` is dropped (its two
    parallel neighbours merged); None when fewer than 4 lines are left."""
    for _ in range(100):
        if len(edges) < 4:
            return None
        V = _vertices(edges)
        Ls = np.array([np.linalg.norm(V[(k + 1) % len(V)] - V[k]) for k in range(len(V))])
        for k in range(len(V)):
            edges[k][2] = Ls[k]
        k = int(np.argmin(Ls))
        if Ls[k] >= shortest:
            return V
        del edges[k]
        edges = _merge_same(edges)
    return None


def snap_real(poly: Any, angle_tol_deg: float = 6.0, shortest: float = 0.25) -> FloatArray | None:
    """A real annotated outline snapped to an exact Manhattan polygon, counter-clockwise,
    centred at its vertices' mean; None if unusable."""
    P = np.asarray(poly, float)
    P = P - P.mean(axis=0)
    if len(P) < 4:
        return None
    edges = _edge_lines(_dominant_turn(P), angle_tol_deg)
    V = None if edges is None else _drop_short_edges(_merge_same(edges), shortest)
    if V is None:
        return None
    V = remove_collinear(V)
    if len(V) < 4 or not is_manhattan(V, 1e-6):
        return None
    V = make_ccw(V)
    return V if is_simple(V) else None


@lru_cache(maxsize=4)
def real_pool(path: Path = DEFAULT_PATH) -> tuple[tuple[int, str, FloatArray], ...]:
    """(index in the file, house, polygon) of the usable real outlines of the test split's
    houses (:func:`bench.room_shapes.house_split`): snapped, 4-16 corners, a sane size.

    Raises
    ------
    FileNotFoundError
        When the shapes file is missing.
    """
    pool = []
    for idx, house, polygon in raw_outlines(path):
        V = snap_real(polygon)
        if V is None or not 4 <= len(V) <= 16:
            continue
        ext = V.max(0) - V.min(0)
        if signed_area(V) < 6.0 or ext.min() < 1.8 or ext.max() > 16.0 or min_edge(V) < 0.3:
            continue
        pool.append((idx, house, V))
    return tuple(pool)


def make_room(kind: str, rng: Rng) -> tuple[FloatArray, dict[str, Any]]:
    """A room outline of one kind (or "real"), centred on its bounding box, and its origin."""
    for _ in range(200):
        meta: dict[str, Any] = {}
        if kind == "real":
            pool = real_pool()
            idx, house, V = pool[int(rng.integers(len(pool)))]
            meta = {"real_index": idx, "house": house}
        else:
            V = np.array(_ROOMS[kind](rng), float)
        V = remove_collinear(make_ccw(V))
        if is_manhattan(V) and is_simple(V) and min_edge(V) >= 0.3:
            return V - (V.min(0) + V.max(0)) / 2.0, meta
    raise RuntimeError("could not make room")


# --------------------------------------------------------------------------- the scene
@dataclass
class Room:
    """A room and its cut: outline (K, 2) CCW meters, perimeter parameters, ceiling height,
    openings, furniture boxes and the fragments' arcs (start, end) of the wall loop."""

    kind: str
    P: FloatArray
    cum: FloatArray
    Ledge: FloatArray
    meta: dict[str, Any]
    H: float = 0.0
    openings: list[dict[str, Any]] = field(default_factory=list)
    boxes: list[dict[str, Any]] = field(default_factory=list)
    arcs: list[tuple[float, float]] = field(default_factory=list)
    cuts: FloatArray = field(default_factory=lambda: np.zeros(0))
    overlaps: FloatArray = field(default_factory=lambda: np.zeros(0))

    @property
    def perim(self) -> float:
        """The wall loop's length, meters."""
        return float(self.cum[-1])

    def inner_normal(self, e: int) -> FloatArray:
        """Unit direction along edge ``e`` and its normal into the room (CCW: the left)."""
        d = (self.P[(e + 1) % len(self.P)] - self.P[e]) / self.Ledge[e]
        return np.array([-d[1], d[0]])


def _place_opening(
    room: Room, e: int, typ: str, occupied: list[tuple[float, float]], rng: Rng
) -> None:
    """One door or window on edge ``e``, clear of the ``occupied`` stretches, if it fits."""
    Le = room.Ledge[e]
    w = rng.uniform(0.8, 1.0) if typ == "door" else rng.uniform(0.7, min(2.0, Le - 0.6))
    for _try in range(20):
        u0 = rng.uniform(0.25, Le - 0.25 - w)
        if not all(u0 > b + 0.3 or u0 + w < a - 0.3 for a, b in occupied):
            continue
        occupied.append((u0, u0 + w))
        z0, z1 = 0.0, 2.0
        if typ == "window":
            z0 = rng.uniform(0.7, 1.0)
            z1 = min(room.H - 0.2, rng.uniform(1.9, 2.3))
        room.openings.append(
            dict(
                edge=e, u0=float(u0), u1=float(u0 + w), z0=z0, z1=z1, type=typ,
                thick=float(rng.uniform(0.1, 0.25)), view_far=float(rng.uniform(1.0, 3.0)),
                far_wall=bool(rng.random() < 0.5),
            )
        )  # fmt: skip
        return


def _add_openings(room: Room, rng: Rng) -> None:
    """Doors (to a next room) and windows on the walls."""
    for e in range(len(room.P)):
        Le = room.Ledge[e]
        occupied: list[tuple[float, float]] = []
        n_door = 1 if (Le > 1.6 and rng.random() < 0.35) else 0
        n_win = int(rng.integers(0, 3)) if (Le > 1.8 and rng.random() < 0.45) else 0
        for typ in ["door"] * n_door + ["window"] * n_win:
            _place_opening(room, e, typ, occupied, rng)


def _blocks_door(room: Room, e: int, u0: float, w: float) -> bool:
    return any(
        o["edge"] == e
        and o["type"] == "door"
        and not (u0 > o["u1"] + 0.1 or u0 + w < o["u0"] - 0.1)
        for o in room.openings
    )


def _add_wall_boxes(room: Room, rng: Rng) -> None:
    """Furniture against the walls, never in front of a door."""
    P, nE = room.P, len(room.P)
    for e in range(nE):
        Le = room.Ledge[e]
        if Le < 1.2:
            continue
        for _ in range(rng.poisson(Le / 3.5)):
            typ = str(rng.choice(list(_WALL_BOXES)))
            w, dp, h = (rng.uniform(*r) for r in _WALL_BOXES[typ])
            if w > Le - 0.2:
                continue
            u0 = rng.uniform(0.05, Le - w - 0.05)
            if _blocks_door(room, e, u0, w):
                continue
            gap = rng.uniform(0.0, 0.08)
            d = (P[(e + 1) % nE] - P[e]) / Le
            c = P[e] + d * (u0 + w / 2) + room.inner_normal(e) * (gap + dp / 2)
            room.boxes.append(
                dict(
                    c=c.tolist(), sx=float(w), sy=float(dp), yaw=float(math.atan2(d[1], d[0])),
                    h=float(h), edge=e, u0=float(u0), u1=float(u0 + w), gap=float(gap), type=typ,
                )
            )  # fmt: skip


def _box_corners(c: FloatArray, sx: float, sy: float, yaw: float) -> FloatArray:
    cs, sn = math.cos(yaw), math.sin(yaw)
    local = np.array([[sx / 2 * i, sy / 2 * j] for i in (-1, 1) for j in (-1, 1)])
    return local @ np.array([[cs, sn], [-sn, cs]]) + c


def _add_free_boxes(room: Room, rng: Rng) -> None:
    """Free-standing tables, beds, chairs and islands, 0.3 m from the walls at least."""
    P = room.P
    for _ in range(rng.poisson(signed_area(P) / 12.0)):
        typ = str(rng.choice(list(_FREE_BOXES)))
        sx, sy, h = (rng.uniform(*r) for r in _FREE_BOXES[typ])
        yaw = 0.0 if rng.random() < 0.6 else rng.uniform(0, math.pi)
        for _try in range(30):
            c = rng.uniform(P.min(0), P.max(0))
            corners = _box_corners(c, sx, sy, yaw)
            dd, _ = boundary_project(corners, P, room.cum)
            if points_in_poly(corners, P).all() and dd.min() > 0.3:
                room.boxes.append(
                    dict(c=c.tolist(), sx=float(sx), sy=float(sy), yaw=float(yaw), h=float(h),
                         edge=-1, type=typ)
                )  # fmt: skip
                break


def _cut_arcs(room: Room, n_frag: int, rng: Rng) -> None:
    """The wall loop cut into ``n_frag`` arcs of 1 m at least (less in small rooms), with
    overlaps (up to 0.5 m) or gaps (up to 0.3 m) at the cuts."""
    perim = room.perim
    t0 = rng.uniform(0, perim)
    w = rng.dirichlet(np.full(n_frag, 2.0))
    min_arc = min(1.0, 0.8 * perim / n_frag)
    w = min_arc / perim + w * (1 - n_frag * min_arc / perim)
    ucuts = t0 + perim * np.concatenate([[0.0], np.cumsum(w)])  # last = first + perimeter
    room.cuts = ucuts[:-1] % perim
    room.overlaps = rng.uniform(-0.3, 0.5, n_frag)  # at cut k (the start of fragment k)
    for k in range(n_frag):
        s = ucuts[k] - room.overlaps[k] / 2
        e = ucuts[k + 1] + room.overlaps[(k + 1) % n_frag] / 2
        room.arcs.append((float(s % perim), float(s % perim + (e - s))))


def build_room(kind: str, n_frag: int, rng: Rng) -> Room:
    """A room of ``kind`` ("any": a synthetic kind drawn) long enough for ``n_frag`` arcs,
    with its openings, furniture and cut."""
    if kind == "any":
        kind = SYN_KINDS[int(rng.integers(len(SYN_KINDS)))]
    for _ in range(200):
        P, meta = make_room(kind, rng)
        cum, Ledge = perimeter_cum(P)
        if cum[-1] >= 1.25 * n_frag:
            break
    else:
        raise RuntimeError("room too small for N fragments")
    room = Room(kind=kind, P=P, cum=cum, Ledge=Ledge, meta=meta)
    room.H = float(rng.uniform(2.4, 3.0))
    _add_openings(room, rng)
    _add_wall_boxes(room, rng)
    _add_free_boxes(room, rng)
    _cut_arcs(room, n_frag, rng)
    return room


def in_arc(t: Any, arc: tuple[float, float], perim: float) -> Any:
    """Whether perimeter parameters ``t`` lie on the arc (start, end)."""
    s, e = arc
    return ((t - s) % perim) <= (e - s)


def edges_of_arc(room: Room, arc: tuple[float, float]) -> list[int]:
    """The edges the arc covers over 5 cm at least."""
    out = []
    for ei in range(len(room.P)):
        a, b = room.cum[ei], room.cum[ei + 1]
        frac = np.mean(in_arc(np.linspace(a, b, 200), arc, room.perim))
        if frac * (b - a) >= 0.05:
            out.append(ei)
    return out


# --------------------------------------------------------------------------- sampling
def sample_rect_uv(rng: Rng, lu: float, lv: float, spacing: float) -> tuple[FloatArray, FloatArray]:
    """Uniform random samples on a lu x lv rectangle at a density of 1 / spacing^2."""
    n = rng.poisson(max(lu * lv, 0.0) / spacing**2)
    return rng.uniform(0, lu, n), rng.uniform(0, lv, n)


@dataclass
class _Scan:
    """One fragment's scan: its arc, point spacing and depth reach (meters), points so far."""

    room: Room
    arc: tuple[float, float]
    sp: float
    depth: float
    pts: list[FloatArray] = field(default_factory=list)

    def add(self, xyz: Any) -> None:
        if len(xyz):
            self.pts.append(np.asarray(xyz, float))

    def region(self, xy: FloatArray) -> tuple[BoolArray, FloatArray]:
        """Points nearest a wall of the arc within the reach, and their distance to the walls."""
        d, t = boundary_project(xy, self.room.P, self.room.cum)
        return in_arc(t, self.arc, self.room.perim) & (d <= self.depth), d


def _scan_wall(scan: _Scan, e: int, rng: Rng) -> None:
    """Edge ``e``'s wall, minus openings and furniture flush with it, then its openings."""
    room, sp = scan.room, scan.sp
    a, Le = room.P[e], room.Ledge[e]
    dvec = (room.P[(e + 1) % len(room.P)] - a) / Le
    u, z = sample_rect_uv(rng, Le, room.H, sp)
    m = in_arc(room.cum[e] + u, scan.arc, room.perim)
    u, z = u[m], z[m]
    keep = np.ones(len(u), bool)
    for o in room.openings:
        if o["edge"] == e:
            keep &= ~((u > o["u0"]) & (u < o["u1"]) & (z > o["z0"]) & (z < o["z1"]))
    for bx in room.boxes:
        if bx["edge"] == e and bx["gap"] < 0.05:
            keep &= ~((u > bx["u0"]) & (u < bx["u1"]) & (z < bx["h"]))
    scan.add(np.column_stack([a + u[keep, None] * dvec, z[keep]]))
    for o in room.openings:
        tc = room.cum[e] + (o["u0"] + o["u1"]) / 2
        if o["edge"] == e and in_arc(np.array([tc]), scan.arc, room.perim)[0]:
            _scan_opening(scan, e, o, rng)


def _scan_opening(scan: _Scan, e: int, o: dict[str, Any], rng: Rng) -> None:
    """An opening's reveals (jambs, lintel, a window's sill) and, for a door, the view."""
    room, sp, th = scan.room, scan.sp, o["thick"]
    a = room.P[e]
    dvec = (room.P[(e + 1) % len(room.P)] - a) / room.Ledge[e]
    nn = room.inner_normal(e)
    for uu in (o["u0"], o["u1"]):  # jambs: u fixed, depth into the wall
        dd, zz = sample_rect_uv(rng, th, o["z1"] - o["z0"], sp)
        scan.add(np.column_stack([a + uu * dvec - dd[:, None] * nn, o["z0"] + zz]))
    for zz0 in [o["z1"]] + ([o["z0"]] if o["type"] == "window" else []):
        uu, dd = sample_rect_uv(rng, o["u1"] - o["u0"], th, sp)
        xy = a + (o["u0"] + uu)[:, None] * dvec - dd[:, None] * nn
        scan.add(np.column_stack([xy, np.full(len(uu), zz0)]))
    if o["type"] == "door":
        _scan_door_view(scan, a, dvec, nn, o, rng)


def _scan_door_view(
    scan: _Scan, a: FloatArray, dvec: FloatArray, nn: FloatArray, o: dict[str, Any], rng: Rng
) -> None:
    """The next room's floor seen through a door (a fan widening away from it) and, for some
    doors, its far wall."""
    room, sp, th = scan.room, scan.sp, o["thick"]
    wdt, far = o["u1"] - o["u0"], o["view_far"]
    mid = (o["u0"] + o["u1"]) / 2
    uu, dd = sample_rect_uv(rng, wdt + 2 * far * 1.5, far, sp * 1.3)
    uu = uu - far * 1.5 + o["u0"]
    m = np.abs(uu - mid) <= (wdt / 2) * (1 + dd / 2.0)
    xy = a + uu[m, None] * dvec - (dd[m] + th)[:, None] * nn
    dB, _ = boundary_project(xy, room.P, room.cum)
    out = ~points_in_poly(xy, room.P) & (dB > th * 0.9)
    scan.add(np.column_stack([xy[out], np.zeros(out.sum())]))
    if o["far_wall"]:
        hwf = (wdt / 2) * (1 + far / 2.0)
        uu, zz = sample_rect_uv(rng, 2 * hwf, room.H, sp * 1.3)
        uu = uu - hwf + mid
        m = zz < 2.0 * (1 + far / 2.0)
        xy = a + uu[m, None] * dvec - (far + th) * nn
        out = ~points_in_poly(xy, room.P)
        scan.add(np.column_stack([xy[out], zz[m][out]]))


def _in_footprints(xy: FloatArray, boxes: list[dict[str, Any]]) -> BoolArray:
    foot = np.zeros(len(xy), bool)
    for bx in boxes:
        cs, sn = math.cos(bx["yaw"]), math.sin(bx["yaw"])
        loc = (xy - np.array(bx["c"])) @ np.array([[cs, -sn], [sn, cs]])
        foot |= (np.abs(loc[:, 0]) < bx["sx"] / 2) & (np.abs(loc[:, 1]) < bx["sy"] / 2)
    return foot


def _scan_floor_ceiling(scan: _Scan, ceil_mode: str, ceil_band: float, rng: Rng) -> None:
    """The floor of the arc's sector (minus furniture footprints) and its ceiling: none, a
    band along the walls, or all of it."""
    P, sp = scan.room.P, scan.sp
    lo, hi = P.min(0) - 0.05, P.max(0) + 0.05
    area_bb = float(np.prod(hi - lo))
    xy = rng.uniform(lo, hi, (rng.poisson(area_bb / sp**2), 2))
    xy = xy[points_in_poly(xy, P)]
    xy = xy[scan.region(xy)[0]]
    xy = xy[~_in_footprints(xy, scan.room.boxes)]
    scan.add(np.column_stack([xy, np.zeros(len(xy))]))
    if ceil_mode == "none":
        return
    xy = rng.uniform(lo, hi, (rng.poisson(area_bb / (sp * 1.4) ** 2), 2))
    xy = xy[points_in_poly(xy, P)]
    m, dB = scan.region(xy)
    if ceil_mode == "band":
        m &= dB <= ceil_band
    scan.add(np.column_stack([xy[m], np.full(m.sum(), scan.room.H)]))


def _scan_box(scan: _Scan, bx: dict[str, Any], rng: Rng) -> None:
    """A box's top and sides (not the side against a wall) within the arc's sector."""
    sx, sy, h, sp = bx["sx"], bx["sy"], bx["h"], scan.sp
    u, v = sample_rect_uv(rng, sx, sy, sp)
    faces = [np.column_stack([u - sx / 2, v - sy / 2, np.full(len(u), h)])]
    sides = [(sx, 1, -sy / 2), (sx, 1, sy / 2), (sy, 0, -sx / 2), (sy, 0, sx / 2)]
    for side, (L, fixed_axis, fixed_val) in enumerate(sides):
        if bx["edge"] >= 0 and side == 0 and bx["gap"] < 0.1:  # -y faces the wall
            continue
        u, z = sample_rect_uv(rng, L, h, sp)
        fixed = np.full(len(u), fixed_val)
        cols = [u - L / 2, fixed, z] if fixed_axis == 1 else [fixed, u - L / 2, z]
        faces.append(np.column_stack(cols))
    F = np.vstack(faces)
    cs, sn = math.cos(bx["yaw"]), math.sin(bx["yaw"])
    xy = F[:, :2] @ np.array([[cs, -sn], [sn, cs]]).T + np.array(bx["c"])
    m, _ = scan.region(xy)
    scan.add(np.column_stack([xy[m], F[m, 2]]))


def sample_fragment(room: Room, k: int, rng: Rng) -> tuple[FloatArray, dict[str, Any]]:
    """Points of fragment ``k`` ((M, 3) float64, world frame, floor z = 0, meters) and its
    scanner's parameters (spacing, noise sigma, reach, ceiling kind)."""
    sp = float(rng.uniform(0.01, 0.03))
    sigma = float(rng.uniform(0.005, 0.02))
    scan = _Scan(room, room.arcs[k], sp, float(rng.uniform(1.5, 2.5)))
    ceil_mode = str(rng.choice(["none", "band", "full"], p=[0.3, 0.5, 0.2]))
    ceil_band = float(rng.uniform(0.4, 1.5))
    for e in range(len(room.P)):
        _scan_wall(scan, e, rng)
    _scan_floor_ceiling(scan, ceil_mode, ceil_band, rng)
    for bx in room.boxes:
        _scan_box(scan, bx, rng)
    X = np.vstack(scan.pts)
    X = X + rng.normal(scale=sigma, size=X.shape)
    n_out = int(0.002 * len(X))  # a few outliers
    if n_out:
        idx = rng.integers(0, len(X), n_out)
        X = np.vstack([X, X[idx] + rng.normal(scale=0.3, size=(n_out, 3))])
    return X, dict(spacing=sp, sigma=sigma, depth=scan.depth, ceiling=ceil_mode)


def rand_rot_tilt(rng: Rng, yaw: float, tilt_deg: float) -> FloatArray:
    """A 3x3 rotation: ``yaw`` about z, then ``tilt_deg`` about a random horizontal axis."""
    ax = rng.normal(size=2)
    ax = np.array([ax[0], ax[1], 0.0]) / np.linalg.norm([ax[0], ax[1], 0.0])
    th = math.radians(tilt_deg)
    K = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
    Rt = np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K
    c, s = math.cos(yaw), math.sin(yaw)
    return Rt @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def write_ply(path: Path, X: FloatArray) -> None:
    """(M, 3) points as a binary little-endian float32 PLY."""
    X = np.ascontiguousarray(X, dtype="<f4")
    header = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {len(X)}\n"
        "property float x\nproperty float y\nproperty float z\nend_header\n"
    )
    Path(path).write_bytes(header.encode("ascii") + X.tobytes())


def _write_fragment(room: Room, k: int, out: Path, rng: Rng) -> dict[str, Any]:
    """Fragment ``k`` sampled, moved by a random motion and written; its truth entry."""
    Xw, params = sample_fragment(room, k, rng)
    yaw = rng.uniform(-math.pi, math.pi)
    tilt = rng.uniform(0, 3.0)
    R = rand_rot_tilt(rng, yaw, tilt)
    t = np.array([rng.uniform(-4, 4), rng.uniform(-4, 4), rng.uniform(-1.6, 1.0)])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    Xl = (Xw - t) @ R  # R^T (p - t)
    fid = f"frag_{k:02d}"
    write_ply(out / f"{fid}.ply", Xl)
    s, e = room.arcs[k]
    return dict(
        id=fid, pose=T.tolist(), arc=[s % room.perim, (e - s)], edges=edges_of_arc(room, (s, e)),
        n_points=len(Xl), centroid_local=Xl.mean(0).tolist(), tilt_deg=float(tilt), **params,
    )  # fmt: skip


def generate(seed: int, kind: str, n_frag: int, out_dir: Path) -> dict[str, Any]:
    """Write one scene (``frag_KK.ply`` and ``truth.json``) into ``out_dir``; its truth.

    Parameters
    ----------
    seed : int
        The scene's seed: the same seed gives the same scene.
    kind : str
        One of :data:`SYN_KINDS`, "real" (a test-split outline) or "any" (a synthetic kind).
    n_frag : int
        Number of fragments.
    out_dir : Path
        Created if missing; PLY files already there are removed.

    Returns
    -------
    dict
        The truth: ``polygon`` (K, 2) CCW world meters, ``diag`` (its bounding box's
        diagonal), ``fragments`` (``id``, ``pose`` fragment-local to world 4x4,
        ``centroid_local``, arc and scanner parameters), openings, boxes, cuts, overlaps.
    """
    rng = np.random.default_rng(seed)
    room = build_room(kind, n_frag, rng)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("*.ply"):
        old.unlink()
    frags = [_write_fragment(room, k, out, rng) for k in range(n_frag)]
    P = room.P
    truth = dict(
        seed=int(seed), kind=room.kind, n=int(n_frag), polygon=P.tolist(), ceiling=room.H,
        perimeter=room.perim, diag=float(np.linalg.norm(P.max(0) - P.min(0))),
        order_ccw=[f["id"] for f in frags], openings=room.openings, boxes=room.boxes,
        cuts=[float(c) for c in room.cuts], overlaps=[float(o) for o in room.overlaps],
        fragments=frags, meta=room.meta,
    )  # fmt: skip
    (out / "truth.json").write_text(json.dumps(truth, indent=1))
    return truth


def main(argv: list[str] | None = None) -> int:
    """Write one scene (options: see ``--help``) and print a summary line."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--kind", default="any", choices=[*SYN_KINDS, "real", "any"])
    parser.add_argument("--n", type=int, required=True, help="number of fragments")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    truth = generate(args.seed, args.kind, args.n, args.out)
    points = sum(f["n_points"] for f in truth["fragments"])
    print(f"{truth['kind']} n={truth['n']} corners {len(truth['polygon'])} points {points}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
