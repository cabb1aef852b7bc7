"""RGB-D frame rooms: one Manhattan room rendered from 1-3 camera stations.

A room (synthetic rect, L, U or T, or a real MatterportLayout outline snapped to Manhattan)
is built as triangles: walls with door openings (a small outside space behind each) and
windows (seen through, no return), reveals, floor, ceiling and furniture boxes. One to three
stations at least 1.2 m apart are placed, and 2-8 frames chosen whose horizontal fields of
view together cover the wall loop with little overlap. Each frame is rendered by
``open3d.t.geometry.RaycastingScene``: depth (z along the optical axis, 16-bit millimeters,
noise growing with z^2, dropouts at grazing angles, edges and blobs) and a flat-shaded colour
image. The truth (``truth.json``) holds the poses (optical to world 4x4, z up, floor at
z = 0) and the counter-clockwise outline.

    .venv/bin/python -m bench.outside.frames /tmp/scene --seed 3 --camera wide --kind L
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import open3d as o3d
from PIL import Image

from bench.outside.clouds import BoolArray, FloatArray, Rng, make_ccw, points_in_poly, signed_area
from bench.room_shapes import DEFAULT_PATH, raw_outlines

__all__ = ["CAMERAS", "KINDS", "make_scene", "real_shapes"]

CAMERAS = {
    "kinect": dict(width=640, height=480, fx=525.0, fy=525.0, cx=319.5, cy=239.5),
    "realsense": dict(width=640, height=480, fx=385.0, fy=385.0, cx=321.2, cy=238.6),
    "wide": dict(width=640, height=480, fx=300.0, fy=300.0, cx=320.0, cy=240.0),
}
KINDS = ("rect", "L", "U", "T", "real")
# name: width, depth, height ranges (meters), colour
FURN_TYPES = {
    "cabinet": ((0.6, 1.6), (0.35, 0.6), (0.7, 1.2), [120, 80, 50]),
    "wardrobe": ((0.9, 2.0), (0.55, 0.65), (1.9, 2.3), [200, 190, 170]),
    "bookshelf": ((0.6, 1.2), (0.3, 0.4), (1.5, 2.1), [90, 60, 40]),
    "bed": ((1.4, 1.8), (1.9, 2.1), (0.45, 0.6), [180, 60, 60]),
    "sofa": ((1.6, 2.4), (0.8, 1.0), (0.7, 0.9), [60, 80, 140]),
    "desk": ((1.0, 1.6), (0.6, 0.8), (0.72, 0.78), [160, 130, 90]),
}
# A real outline: (index in the file, house, snapped polygon or None)
RealShape = tuple[int, str, FloatArray | None]


# ----------------------------------------------------------------------------- polygons
def _crosses(a: FloatArray, b: FloatArray, c: FloatArray, d: FloatArray, eps: float = 1e-9) -> bool:
    """Whether segments ab and cd cross properly."""

    def orient(p: FloatArray, q: FloatArray, r: FloatArray) -> float:
        return float((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]))

    o1, o2, o3, o4 = orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b)
    return (o1 * o2 < -eps) and (o3 * o4 < -eps)


def is_simple(p: FloatArray) -> bool:
    """Whether no two non-adjacent edges cross."""
    n = len(p)
    for i in range(n):
        for j in range(i + 2, n):
            if not (i == 0 and j == n - 1) and _crosses(p[i], p[(i + 1) % n], p[j], p[(j + 1) % n]):
                return False
    return True


def dist_to_boundary(pts: FloatArray, poly: FloatArray) -> FloatArray:
    """Distance of each (M, 2) point to the polygon's boundary."""
    best = np.full(len(pts), np.inf)
    for i in range(len(poly)):
        a, b = np.asarray(poly[i]), np.asarray(poly[(i + 1) % len(poly)])
        ab = b - a
        t = np.clip(((pts - a) @ ab) / (ab @ ab), 0, 1)
        best = np.minimum(best, np.linalg.norm(pts - (a + t[:, None] * ab), axis=1))
    return best


def _quarter_turns(p: FloatArray, rng: Rng) -> FloatArray:
    """The polygon turned by a random multiple of 90 degrees, mirrored half the time, CCW."""
    R = np.array([[0, -1], [1, 0]], float)
    for _ in range(rng.integers(4)):
        p = p @ R.T
    if rng.random() < 0.5:
        p[:, 0] = -p[:, 0]
    return make_ccw(p)


def synth_polygon(kind: str, rng: Rng) -> FloatArray:
    """A synthetic outline of ``kind`` (rect, L, U, T), (K, 2) CCW meters."""
    if kind == "rect":
        w, h = rng.uniform(3, 8), rng.uniform(3, 8)
        p = np.array([[0, 0], [w, 0], [w, h], [0, h]], float)
    elif kind == "L":
        W, H = rng.uniform(4, 8), rng.uniform(4, 8)
        a, b = rng.uniform(0.3, 0.6) * W, rng.uniform(0.3, 0.6) * H
        p = np.array([[0, 0], [W, 0], [W, H - b], [W - a, H - b], [W - a, H], [0, H]], float)
    elif kind == "U":
        W, H = rng.uniform(5, 8), rng.uniform(4, 8)
        nw = rng.uniform(0.25, 0.45) * W
        x0 = rng.uniform(1.3, W - nw - 1.3)
        d = rng.uniform(0.3, 0.55) * H
        p = np.array(
            [[0, 0], [W, 0], [W, H], [x0 + nw, H], [x0 + nw, H - d], [x0, H - d], [x0, H], [0, H]],
            float,
        )
    elif kind == "T":
        W, H = rng.uniform(5, 8), rng.uniform(4, 8)
        d = rng.uniform(0.35, 0.55) * H  # the bar's depth (top)
        s = rng.uniform(0.35, 0.6) * W  # the stem's width
        x0 = rng.uniform(0.8, W - s - 0.8)
        p = np.array(
            [[x0, 0], [x0 + s, 0], [x0 + s, H - d], [W, H - d], [W, H], [0, H], [0, H - d],
             [x0, H - d]],
            float,
        )  # fmt: skip
    else:
        raise ValueError(kind)
    return _quarter_turns(p, rng)


# ----------------------------------------------------------------------------- real outlines
def _dedupe(poly: Any) -> FloatArray:
    p = np.asarray(poly, float)
    keep = [0]
    for i in range(1, len(p)):
        if np.linalg.norm(p[i] - p[keep[-1]]) > 1e-3:
            keep.append(i)
    p = p[keep]
    return p[:-1] if np.linalg.norm(p[0] - p[-1]) < 1e-3 else p


def _axis_edges(p: FloatArray, ang_tol_deg: float) -> list[list[Any]] | None:
    """Edges over 8 cm as [orientation "H" or "V", coordinate, length]; None if one is oblique."""
    edges = []
    for i in range(len(p)):
        a, b = p[i], p[(i + 1) % len(p)]
        d = b - a
        L = np.linalg.norm(d)
        if L < 0.08:
            continue  # a tiny edge, merged away
        ang = math.degrees(math.atan2(abs(d[1]), abs(d[0])))
        if ang < ang_tol_deg:
            edges.append(["H", (a[1] + b[1]) / 2, L])
        elif ang > 90 - ang_tol_deg:
            edges.append(["V", (a[0] + b[0]) / 2, L])
        else:
            return None
    return edges


def _absorb(m: list[Any], e: list[Any]) -> bool:
    """Line ``e`` merged into ``m`` (same orientation); False when they are 15 cm apart."""
    if abs(m[1] - e[1]) > 0.15:
        return False
    m[1] = (m[1] * m[2] + e[1] * e[2]) / (m[2] + e[2])
    m[2] += e[2]
    return True


def _merged_lines(edges: list[list[Any]]) -> list[list[Any]] | None:
    """Consecutive lines of one orientation merged (cyclically); None if they disagree."""
    merged: list[list[Any]] = []
    for e in edges:
        if merged and merged[-1][0] == e[0]:
            if not _absorb(merged[-1], e):
                return None
        else:
            merged.append(list(e))
    if len(merged) > 1 and merged[0][0] == merged[-1][0] and not _absorb(merged[0], merged.pop()):
        return None
    return merged


def snap_real(poly: Any, ang_tol_deg: float = 6.0, min_edge: float = 0.4) -> FloatArray | None:
    """A real outline snapped to an exact axis-aligned CCW polygon, within 25 cm of it;
    None if unusable."""
    p = _dedupe(poly)
    if len(p) < 4:
        return None
    p = make_ccw(p)
    edges = _axis_edges(p, ang_tol_deg)
    merged = None if edges is None else _merged_lines(edges)
    if merged is None or len(merged) < 4 or len(merged) % 2:
        return None
    k = len(merged)
    verts = []
    for i in range(k):
        e0, e1 = merged[i], merged[(i + 1) % k]
        verts.append([e1[1], e0[1]] if e0[0] == "H" else [e0[1], e1[1]])
    v = np.array(verts)
    if signed_area(v) <= 0 or not is_simple(v):
        return None
    if np.linalg.norm(np.roll(v, -1, axis=0) - v, axis=1).min() < min_edge:
        return None
    return v if np.max(dist_to_boundary(v, p)) <= 0.25 else None


@lru_cache(maxsize=4)
def real_shapes(path: Path = DEFAULT_PATH) -> tuple[RealShape, ...]:
    """The outlines of the test split's houses (:func:`bench.room_shapes.house_split`), in
    file order, snapped (None when unusable).

    Raises
    ------
    FileNotFoundError
        When the shapes file is missing.
    """
    return tuple((i, house, snap_real(polygon)) for i, house, polygon in raw_outlines(path))


def real_polygon(rng: Rng, shapes: tuple[RealShape, ...]) -> tuple[FloatArray, str, int]:
    """A random usable outline (4-12 corners, 2.2-10 m across, 6 m^2 at least), its house
    and its index in the file."""
    for idx in rng.permutation(len(shapes)):
        index, house, v = shapes[idx]
        if v is None or not 4 <= len(v) <= 12:
            continue
        ext = v.max(0) - v.min(0)
        if ext.min() < 2.2 or ext.max() > 10.0 or signed_area(v) < 6.0:
            continue
        return v, house, index
    raise RuntimeError("no real shape")


# ----------------------------------------------------------------------------- meshes
@dataclass
class MeshBuilder:
    """Triangle meshes, (V, 3) float32 vertices and (T, 3) uint32 triangles, with colours."""

    meshes: list[tuple[Any, Any, Any]] = field(default_factory=list)

    def quad(self, p0: Any, p1: Any, p2: Any, p3: Any, color: Any) -> None:
        """A quadrilateral of four corners in order."""
        v = np.array([p0, p1, p2, p3], np.float32)
        self.meshes.append((v, np.array([[0, 1, 2], [0, 2, 3]], np.uint32), color))

    def box(self, lo: Any, hi: Any, color: Any) -> None:
        """An axis-aligned box between corners ``lo`` and ``hi``."""
        m = o3d.geometry.TriangleMesh.create_box(*(np.asarray(hi) - np.asarray(lo)))
        m.translate(np.asarray(lo, float))
        self.meshes.append(
            (np.asarray(m.vertices, np.float32), np.asarray(m.triangles, np.uint32), color)
        )

    def wall_rect(self, a: Any, u: Any, n: Any, s: tuple[float, float], z: tuple[float, float],
                  color: Any, off: float = 0.0) -> None:  # fmt: skip
        """The rectangle of points a + s u (+ off n) for s in ``s``, height z in ``z``."""
        (s0, s1), (z0, z1) = s, z
        if s1 - s0 < 1e-6 or z1 - z0 < 1e-6:
            return
        base = np.array([a[0], a[1]]) + off * n
        q0, q1 = base + s0 * u, base + s1 * u
        self.quad([q0[0], q0[1], z0], [q1[0], q1[1], z0], [q1[0], q1[1], z1], [q0[0], q0[1], z1],
                  color)  # fmt: skip

    def horiz_rect(self, x0: float, y0: float, x1: float, y1: float, z: float, color: Any) -> None:
        """A horizontal rectangle at height z."""
        self.quad([x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z], color)


def grid_cells(poly: FloatArray) -> list[tuple[float, float, float, float]]:
    """The polygon as the cells (x0, y0, x1, y1) of the grid of its vertices' coordinates."""
    xs = np.unique(np.round(poly[:, 0], 6))
    ys = np.unique(np.round(poly[:, 1], 6))
    cells = []
    for i in range(len(xs) - 1):
        for j in range(len(ys) - 1):
            c = np.array([[(xs[i] + xs[i + 1]) / 2, (ys[j] + ys[j + 1]) / 2]])
            if points_in_poly(c, poly)[0]:
                cells.append((xs[i], ys[j], xs[i + 1], ys[j + 1]))
    return cells


def jitter_color(rng: Rng, base: Any, amt: float = 18) -> FloatArray:
    """An RGB colour (0-255) near ``base``."""
    return np.clip(np.asarray(base, float) + rng.normal(0, amt, 3), 0, 255)


@dataclass
class _Build:
    """A room being built: outline, height, wall thickness, colours, meshes and openings
    (per wall: (kind, s0, s1, z0, z1)), doors, windows and furniture as written to the truth."""

    poly: FloatArray
    H: float
    thick: float
    ceil_col: FloatArray
    mb: MeshBuilder = field(default_factory=MeshBuilder)
    openings: dict[int, list[tuple[Any, ...]]] = field(default_factory=dict)
    doors: list[dict[str, Any]] = field(default_factory=list)
    windows: list[dict[str, Any]] = field(default_factory=list)
    outside: list[tuple[float, float, float, float]] = field(default_factory=list)
    furniture: list[dict[str, Any]] = field(default_factory=list)

    def wall(self, i: int) -> tuple[FloatArray, float, FloatArray, FloatArray]:
        """Start, length, unit direction and inner normal of wall ``i``."""
        a, b = self.poly[i], self.poly[(i + 1) % len(self.poly)]
        L = float(np.linalg.norm(b - a))
        u = (b - a) / L
        return a, L, u, np.array([-u[1], u[0]])


def _outside_box(b: _Build, i: int, s0: float, w: float, depth: float, rng: Rng) -> Any:
    """Where the space behind a door on wall ``i`` would be: (along-wall extent, bounds), or
    None when it would overlap the room or another such space."""
    a, _, u, nin = b.wall(i)
    ext = (s0 - rng.uniform(0.3, 1.5), s0 + w + rng.uniform(0.3, 1.5))
    nout = -nin
    cs = np.array(
        [a + ext[0] * u + b.thick * nout, a + ext[1] * u + b.thick * nout,
         a + ext[1] * u + (b.thick + depth) * nout, a + ext[0] * u + (b.thick + depth) * nout]
    )  # fmt: skip
    lo, hi = cs.min(0), cs.max(0)
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 15), np.linspace(lo[1], hi[1], 15))
    g = np.c_[gx.ravel(), gy.ravel()]
    if points_in_poly(g, b.poly).any() or dist_to_boundary(g, b.poly).min() < b.thick * 0.9:
        return None
    if any(not (hi[0] < r[0] or lo[0] > r[2] or hi[1] < r[1] or lo[1] > r[3]) for r in b.outside):
        return None
    return ext, lo, hi


def _try_door(b: _Build, i: int, rng: Rng) -> None:
    """A door on wall ``i`` with a small outside space behind it (floor, ceiling, three walls
    and the back of the room's wall), if it fits."""
    a, length, u, nin = b.wall(i)
    w = rng.uniform(0.8, 1.0)
    if length < w + 0.7:
        return
    s0 = rng.uniform(0.3, length - w - 0.3)
    depth = rng.uniform(1.2, 3.0)
    space = _outside_box(b, i, s0, w, depth, rng)
    if space is None:
        return
    ext, lo, hi = space
    top = rng.uniform(2.0, min(2.15, b.H - 0.2))
    b.openings[i].append(("door", s0, s0 + w, 0.0, top))
    b.doors.append(dict(wall=int(i), s0=float(s0), s1=float(s0 + w), top=float(top)))
    b.outside.append((lo[0], lo[1], hi[0], hi[1]))
    oc = jitter_color(rng, [rng.uniform(150, 220)] * 3, 20)
    ofl = jitter_color(rng, [120, 120, 120], 30)
    Ho = b.H + rng.uniform(-0.2, 0.2)
    nout = -nin
    b.mb.horiz_rect(lo[0], lo[1], hi[0], hi[1], 0.0, ofl)
    b.mb.horiz_rect(lo[0], lo[1], hi[0], hi[1], Ho, b.ceil_col)
    b.mb.wall_rect(a + b.thick * nout + depth * nout, u, nout, ext, (0, Ho), oc)  # far wall
    for s in ext:  # the two side walls
        b.mb.wall_rect(a + s * u + b.thick * nout, nout, u, (0, depth), (0, Ho), oc)
    b.mb.wall_rect(a, u, nout, ext, (0, Ho), oc, off=b.thick)  # the back of our wall


def _try_window(b: _Build, i: int, rng: Rng) -> None:
    """A window on wall ``i`` clear of its other openings, if it fits."""
    length = b.wall(i)[1]
    w = rng.uniform(0.8, 1.8)
    if length < w + 0.8:
        return
    for _ in range(10):
        s0 = rng.uniform(0.4, length - w - 0.4)
        if all(s0 + w + 0.2 < o[1] or s0 > o[2] + 0.2 for o in b.openings[i]):
            sill = rng.uniform(0.7, 1.0)
            top = min(rng.uniform(1.9, 2.3), b.H - 0.15)
            b.openings[i].append(("window", s0, s0 + w, sill, top))
            b.windows.append(
                dict(wall=int(i), s0=float(s0), s1=float(s0 + w), sill=float(sill), top=float(top))
            )
            return


def _build_wall(b: _Build, i: int, col: FloatArray) -> None:
    """Wall ``i`` around its openings, and the openings' reveals through the wall."""
    a, L, u, nin = b.wall(i)
    ops = sorted(b.openings[i], key=lambda o: o[1])
    cuts = sorted({0.0, L, *[o[1] for o in ops], *[o[2] for o in ops]})
    for s0, s1 in itertools.pairwise(cuts):
        mid = (s0 + s1) / 2
        o = next((o for o in ops if o[1] <= mid <= o[2]), None)
        if o is None:
            b.mb.wall_rect(a, u, nin, (s0, s1), (0, b.H), col)
        else:
            b.mb.wall_rect(a, u, nin, (s0, s1), (0, o[3]), col)
            b.mb.wall_rect(a, u, nin, (s0, s1), (o[4], b.H), col)
    nout = -nin
    for _, s0, s1, z0, z1 in ops:
        for s in (s0, s1):
            b.mb.wall_rect(a + s * u, nout, u, (0, b.thick), (z0, z1), col)
        q0, q1 = a + s0 * u, a + s1 * u
        q2, q3 = q1 + b.thick * nout, q0 + b.thick * nout
        for z in [z0, z1] if z0 > 0 else [z1]:
            b.mb.quad([*q0, z], [*q1, z], [*q2, z], [*q3, z], col)


def build_scene(poly: FloatArray, H: float, rng: Rng, stations_xy: FloatArray) -> _Build:
    """The room's meshes: doors, windows, walls, floor, ceiling, furniture."""
    n = len(poly)
    wall_col = jitter_color(rng, [rng.uniform(190, 235)] * 3, 12)
    floor_col = jitter_color(rng, [150, 110, 70], 25)
    ceil_col = jitter_color(rng, [240, 240, 236], 5)
    b = _Build(poly, H, rng.uniform(0.1, 0.2), ceil_col, openings={i: [] for i in range(n)})
    n_doors_target = rng.choice([1, 1, 2, 2, 3])
    for i in rng.permutation(n):
        if len(b.doors) >= n_doors_target:
            break
        _try_door(b, int(i), rng)
    n_win = rng.integers(0, 4)
    for i in rng.permutation(n)[:n_win]:
        _try_window(b, int(i), rng)
    for i in range(n):
        _build_wall(b, i, jitter_color(rng, wall_col, 6))
    for x0, y0, x1, y1 in grid_cells(poly):
        b.mb.horiz_rect(x0, y0, x1, y1, 0.0, floor_col)
        b.mb.horiz_rect(x0, y0, x1, y1, H, ceil_col)
    b.furniture = place_furniture(b, rng, stations_xy)
    return b


# ----------------------------------------------------------------------------- furniture
@dataclass
class _Furnish:
    """Furniture being placed: world boxes (x0, y0, x1, y1) so far and their descriptions."""

    b: _Build
    stations: FloatArray
    placed: list[tuple[float, float, float, float]] = field(default_factory=list)
    desc: list[dict[str, Any]] = field(default_factory=list)

    def ok(self, lo: FloatArray, hi: FloatArray, clear: float = 0.05) -> bool:
        """Whether a box fits: inside the room, clear of the others and of the stations."""
        gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 6), np.linspace(lo[1], hi[1], 6))
        g = np.c_[gx.ravel(), gy.ravel()]
        if (
            not points_in_poly(g, self.b.poly).all()
            or dist_to_boundary(g, self.b.poly).min() < 0.005
        ):
            return False
        for r in self.placed:
            if not (hi[0] + clear < r[0] or lo[0] - clear > r[2] or hi[1] + clear < r[1]
                    or lo[1] - clear > r[3]):  # fmt: skip
                return False
        if len(self.stations):  # the cameras need room
            d = np.maximum(0, np.maximum(lo - self.stations, self.stations - hi))
            if (np.linalg.norm(d, axis=1) < 0.5).any():
                return False
        return True


def _try_table(f: _Furnish, rng: Rng) -> None:
    """A free-standing table with legs, 1 m from the walls at least, if it fits."""
    poly = f.b.poly
    w, d = rng.uniform(0.8, 1.6), rng.uniform(0.6, 1.0)
    if rng.random() < 0.5:
        w, d = d, w
    c = poly.min(0) + rng.random(2) * (poly.max(0) - poly.min(0))
    half = np.array([w / 2, d / 2])
    lo, hi = c - half, c + half
    if not f.ok(lo, hi, 0.3) or dist_to_boundary(np.array([c]), poly)[0] < 1.0:
        return
    h = rng.uniform(0.7, 0.78)
    col = jitter_color(rng, [140, 100, 60], 30)
    f.b.mb.box([lo[0], lo[1], h - 0.04], [hi[0], hi[1], h], col)
    for lx in (lo[0] + 0.03, hi[0] - 0.08):
        for ly in (lo[1] + 0.03, hi[1] - 0.08):
            f.b.mb.box([lx, ly, 0], [lx + 0.05, ly + 0.05, h - 0.04], col)
    f.placed.append((lo[0], lo[1], hi[0], hi[1]))
    f.desc.append(dict(type="table", lo=lo.tolist(), hi=hi.tolist(), h=float(h)))


def _before_door(f: _Furnish, lo: FloatArray, hi: FloatArray) -> bool:
    """Whether a box overlaps the 1 m in front of a door."""
    for j, ops in f.b.openings.items():
        aj, _, uj, nj = f.b.wall(j)
        for o in ops:
            if o[0] != "door":
                continue
            q = np.array([aj + o[1] * uj, aj + o[2] * uj, aj + o[1] * uj + nj, aj + o[2] * uj + nj])
            qlo, qhi = q.min(0), q.max(0)
            if not (hi[0] < qlo[0] or lo[0] > qhi[0] or hi[1] < qlo[1] or lo[1] > qhi[1]):
                return True
    return False


def _try_wall_piece(f: _Furnish, rng: Rng) -> None:
    """A piece of furniture against a random wall, not before a door nor above a window's
    sill, if it fits."""
    name = str(rng.choice(list(FURN_TYPES)))
    (w0, w1), (d0, d1), (h0, h1), col = FURN_TYPES[name]
    w, d, h = rng.uniform(w0, w1), rng.uniform(d0, d1), rng.uniform(h0, h1)
    i = int(rng.integers(len(f.b.poly)))
    a, length, u, nin = f.b.wall(i)
    if length < w + 0.2:
        return
    s0 = rng.uniform(0.02, length - w - 0.02)
    for o in f.b.openings[i]:
        if (o[0] == "door" or h > o[3] - 0.05) and not (s0 + w < o[1] - 0.1 or s0 > o[2] + 0.1):
            return
    gap = rng.uniform(0.01, 0.05)
    c0, c1 = a + s0 * u + gap * nin, a + (s0 + w) * u + (gap + d) * nin
    lo, hi = np.minimum(c0, c1), np.maximum(c0, c1)
    if _before_door(f, lo, hi) or not f.ok(lo, hi):
        return
    f.b.mb.box([lo[0], lo[1], 0], [hi[0], hi[1], h], jitter_color(rng, col, 25))
    f.placed.append((lo[0], lo[1], hi[0], hi[1]))
    f.desc.append(dict(type=name, wall=i, lo=lo.tolist(), hi=hi.tolist(), h=float(h)))


def place_furniture(b: _Build, rng: Rng, stations_xy: FloatArray) -> list[dict[str, Any]]:
    """1-7 pieces of furniture (more in larger rooms), meshed into ``b``; their descriptions."""
    n_target = int(np.clip(rng.poisson(1.0 + signed_area(b.poly) / 10.0), 1, 7))
    f = _Furnish(b, np.asarray(stations_xy))
    tries = 0
    while len(f.placed) < n_target and tries < 200:
        tries += 1
        if rng.random() < 0.25:
            _try_table(f, rng)
        else:
            _try_wall_piece(f, rng)
    return f.desc


# ----------------------------------------------------------------------------- cameras
def boundary_samples(poly: FloatArray, step: float = 0.05) -> FloatArray:
    """Points along the walls, ``step`` apart or so."""
    pts = []
    for i in range(len(poly)):
        a, b = poly[i], poly[(i + 1) % len(poly)]
        k = max(2, int(np.linalg.norm(b - a) / step))
        pts.append(a + ((np.arange(k) + 0.5) / k)[:, None] * (b - a))
    return np.vstack(pts)


def visible_mask(
    st: FloatArray, samples: FloatArray, poly: FloatArray, max_range: float = 7.0
) -> BoolArray:
    """Which wall samples a station sees (2D line of sight, within ``max_range``)."""
    d = samples - st
    dist = np.linalg.norm(d, axis=1)
    vis = dist < max_range
    r = samples - 0.01 * d / dist[:, None] - st
    for i in range(len(poly)):
        a, b = poly[i], poly[(i + 1) % len(poly)]
        s = b - a
        denom = r[:, 0] * s[1] - r[:, 1] * s[0]
        qp = a - st
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (qp[0] * s[1] - qp[1] * s[0]) / denom
            uu = (qp[0] * r[:, 1] - qp[1] * r[:, 0]) / denom
        vis &= ~((np.abs(denom) > 1e-12) & (t > 0) & (t < 1) & (uu >= 0) & (uu <= 1))
    return vis


def _candidates(poly: FloatArray, stations: FloatArray, half: float) -> tuple[Any, BoolArray]:
    """Every (station, yaw) every 3 degrees, and the (C, N) wall samples each one sees."""
    samples = boundary_samples(poly)
    cand, masks = [], []
    for k, st in enumerate(stations):
        vis = visible_mask(st, samples, poly)
        ang = np.arctan2(samples[:, 1] - st[1], samples[:, 0] - st[0])
        for yaw in np.radians(np.arange(0, 360, 3)):
            masks.append(vis & (np.abs(np.angle(np.exp(1j * (ang - yaw)))) < half))
            cand.append((k, float(yaw)))
    return cand, np.array(masks)


def _greedy(M: BoolArray, rng: Rng, first: int | None, goal: float, max_frames: int) -> list[int]:
    """Views chosen one by one for the most new wall less 1.5 times the overlap, the first
    one given or chosen so, until ``goal`` of the wall is seen."""
    N = M.shape[1]
    covered = np.zeros(N, bool)
    chosen: list[int] = []
    while covered.mean() < goal and len(chosen) < max_frames:
        scores = (M & ~covered).sum(1) - 1.5 * (M & covered).sum(1)
        if not chosen and first is not None:
            ci = first
        else:
            ci = int(np.argmax(scores + rng.uniform(0, 1e-3, len(scores))))
        if (M[ci] & ~covered).sum() < 0.02 * N:
            break
        chosen.append(ci)
        covered |= M[ci]
    return chosen


def plan_frames(
    poly: FloatArray, stations: FloatArray, hfov_deg: float, rng: Rng, max_frames: int = 8,
    goal: float = 0.97,
) -> tuple[list[tuple[int, float]], float, float]:  # fmt: skip
    """Frames (station, yaw) covering the wall loop with little overlap (the best of 8
    greedy runs), the share of wall covered and the overlap."""
    cand, M = _candidates(poly, stations, math.radians(hfov_deg) / 2 * 0.96)
    best: Any = None
    for restart in range(8):
        first = int(rng.integers(len(cand)))
        chosen = _greedy(M, rng, first if restart > 0 else None, goal, max_frames)
        covered = M[chosen].any(0) if chosen else np.zeros(M.shape[1], bool)
        cov = covered.mean()
        overlap = M[chosen].sum() / max(1, covered.sum()) - 1
        key = (cov < goal, len(chosen), overlap)
        if best is None or key < best[0]:
            best = (key, chosen, cov, overlap)
    _, chosen, cov, overlap = best
    return [cand[c] for c in chosen], float(cov), float(overlap)


def cam_pose(pos: FloatArray, yaw: float, pitch: float, roll: float) -> FloatArray:
    """Optical (x right, y down, z forward) to world 4x4 of a camera at ``pos``."""
    f = np.array(
        [math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), -math.sin(pitch)]
    )
    r = np.cross(f, np.array([0, 0, 1.0]))
    r /= np.linalg.norm(r)
    c, s = math.cos(roll), math.sin(roll)
    T = np.eye(4)
    T[:3, :3] = np.c_[r, np.cross(f, r), f] @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    T[:3, 3] = pos
    return T


def sample_stations(
    poly: FloatArray, k: int, rng: Rng, clearance: float = 0.9, corner: bool = False
) -> FloatArray | None:
    """``k`` stations inside the room, ``clearance`` from the walls and 1.2 m apart at least
    (``corner``: 0.9-1.4 m in from a convex corner along both walls); None if none found."""
    lo, hi = poly.min(0), poly.max(0)
    st: list[FloatArray] = []
    n = len(poly)
    for _ in range(5000):
        if corner:
            i = rng.integers(n)
            a, b, c = poly[i - 1], poly[i], poly[(i + 1) % n]
            u1, u2 = b - a, c - b
            if u1[0] * u2[1] - u1[1] * u2[0] <= 0:  # a reflex corner
                continue
            e1, e2 = (a - b) / np.linalg.norm(a - b), (c - b) / np.linalg.norm(c - b)
            p = b + rng.uniform(0.9, 1.4) * e1 + rng.uniform(0.9, 1.4) * e2
        else:
            p = lo + rng.random(2) * (hi - lo)
        if not points_in_poly(p[None], poly)[0] or dist_to_boundary(p[None], poly)[0] < clearance:
            continue
        if any(np.linalg.norm(p - q) < 1.2 for q in st):
            continue
        st.append(p)
        if len(st) == k:
            return np.array(st)
    return None


# ----------------------------------------------------------------------------- rendering
def _tensor(array: Any) -> Any:
    return o3d.core.Tensor.from_numpy(np.ascontiguousarray(array))


def _cast(scene: Any, T: FloatArray, cam: dict[str, Any]) -> tuple[FloatArray, ...]:
    """Per pixel: depth along the optical axis (0: no hit), hit or not, the geometry hit,
    its normal, the ray's direction (world)."""
    W, Hh = cam["width"], cam["height"]
    u, v = np.meshgrid(np.arange(W) + 0.0, np.arange(Hh) + 0.0)
    dc = np.stack([(u - cam["cx"]) / cam["fx"], (v - cam["cy"]) / cam["fy"], np.ones_like(u)], -1)
    dw = dc.reshape(-1, 3) @ T[:3, :3].T
    rays = np.c_[np.repeat(T[None, :3, 3], len(dw), 0), dw].astype(np.float32)
    ans = scene.cast_rays(_tensor(rays))
    z = ans["t_hit"].numpy().astype(np.float64)  # the ray's z is 1: t is the depth
    gid = ans["geometry_ids"].numpy().astype(np.int64)
    nrm = ans["primitive_normals"].numpy().astype(np.float64)
    hit = np.isfinite(z)
    z[~hit] = 0
    return z, hit, gid, nrm, dw


def _colour(z: Any, gid: Any, nrm: Any, hit: Any, colors: FloatArray, shape: Any, rng: Rng) -> Any:
    """Flat shading of each hit geometry's colour, sky where nothing is hit, a little noise."""
    col = np.zeros((len(z), 3))
    gidc = np.clip(gid, 0, len(colors) - 1)
    shade = 0.55 + 0.45 * np.abs(nrm @ np.array([0.3, 0.5, 0.81]))
    col[hit] = colors[gidc[hit]] * shade[hit, None]
    col[~hit] = [225, 235, 250]  # sky, or through windows
    col += rng.normal(0, 5, col.shape)
    return np.clip(col, 0, 255).astype(np.uint8).reshape(*shape, 3)


def _dropouts(z: Any, zn: Any, cosi: Any, hit: Any, shape: tuple[int, int], rng: Rng) -> Any:
    """Pixels without depth: no hit, out of range, grazing, random, at edges, blobs."""
    Hh, W = shape
    drop = ~hit
    drop |= (zn < 0.3) | (zn > 8.0)
    drop |= (cosi < 0.2) & (rng.random(z.shape) < (0.2 - cosi) / 0.2 + 0.3)
    drop |= rng.random(z.shape) < 0.005
    dimg = drop.reshape(Hh, W)
    zr = z.reshape(Hh, W)
    gx, gy = np.zeros_like(zr), np.zeros_like(zr)
    gx[:, 1:] = np.abs(np.diff(zr, axis=1))
    gy[1:, :] = np.abs(np.diff(zr, axis=0))
    edge = np.maximum(gx, gy) > 0.05 * np.maximum(zr, 0.3)
    dimg |= edge & (rng.random(zr.shape) < 0.6)
    for _ in range(rng.integers(0, 4)):
        cy_, cx_ = rng.integers(0, Hh), rng.integers(0, W)
        rr = rng.integers(3, 15)
        yy, xx = np.ogrid[:Hh, :W]
        dimg |= (yy - cy_) ** 2 + (xx - cx_) ** 2 < rr * rr
    return dimg


def render_frame(
    scene: Any, colors: FloatArray, T: FloatArray, cam: dict[str, Any], rng: Rng, noise_model: str
) -> tuple[Any, Any]:
    """(H, W) uint16 depth in millimeters (0: none) and (H, W, 3) uint8 colour of one frame."""
    shape = (cam["height"], cam["width"])
    z, hit, gid, nrm, dw = _cast(scene, T, cam)
    cosi = np.abs(np.sum(dw / np.linalg.norm(dw, axis=1, keepdims=True) * nrm, axis=1))
    col = _colour(z, gid, nrm, hit, colors, shape, rng)
    if noise_model == "kinect":
        sigma = 0.0012 + 0.0019 * (z - 0.4) ** 2
    else:  # stereo, RealSense-like: the error grows faster
        sigma = 0.0015 + 0.0030 * (z - 0.3) ** 2
    zn = z + rng.normal(0, 1, z.shape) * sigma
    dimg = _dropouts(z, zn, cosi, hit, shape, rng)
    depth_mm = np.round(zn.reshape(shape) * 1000.0)
    depth_mm[dimg] = 0
    return np.clip(depth_mm, 0, 65535).astype(np.uint16), col


# ----------------------------------------------------------------------------- scenes
@dataclass(frozen=True)
class Plan:
    """Where the cameras stand: (S, 2) stations, frames (station index, yaw in radians), the
    share of the wall loop they cover and their overlap, whether stations were put in
    corners."""

    stations: FloatArray
    frames: list[tuple[int, float]]
    coverage: float
    overlap: float
    corner: bool


def _plan_cameras(poly: FloatArray, camera: str, hfov: float, rng: Rng) -> Plan | None:
    """Stations (1-3, more only when fewer cannot do) and 2-8 frames covering 95 % of the
    wall loop; None when none is found."""
    k0 = 1 if (len(poly) == 4 and rng.random() < 0.6) else int(rng.choice([1, 2, 2, 3]))
    corner = bool(rng.random() < (0.5 if camera == "wide" else 0.25))
    for k in range(k0, 4):
        for _ in range(6):
            st = sample_stations(poly, k, rng, corner=corner)
            if st is None:
                st = sample_stations(poly, k, rng, clearance=0.7)
            if st is None:
                continue
            frames, cov, ov = plan_frames(poly, st, hfov, rng)
            if cov >= 0.95 and 2 <= len(frames) <= 8:
                return Plan(st, frames, cov, ov, corner)
    return None


def _room_and_plan(
    kind: str, camera: str, hfov: float, rng: Rng, shapes: tuple[RealShape, ...] | None
) -> tuple[FloatArray, str | None, int | None, Plan]:
    """A room (outline moved by up to 3 m, its house and file index if real) and a camera
    plan for it, 50 rooms tried at most."""
    for _attempt in range(50):
        house, shape_idx = None, None
        if kind == "real":
            poly, house, shape_idx = real_polygon(rng, real_shapes() if shapes is None else shapes)
        else:
            poly = synth_polygon(kind, rng)
        poly = make_ccw(poly - poly.mean(0) + rng.uniform(-3, 3, 2))
        plan = _plan_cameras(poly, camera, hfov, rng)
        if plan is not None:
            return poly, house, shape_idx, plan
    raise RuntimeError("could not plan cameras")


def _raycasting(b: _Build) -> tuple[Any, FloatArray]:
    """The scene to cast rays on, and the colour of each of its geometries."""
    scene = o3d.t.geometry.RaycastingScene()
    for vtx, tri, _color in b.mb.meshes:
        scene.add_triangles(_tensor(vtx), _tensor(tri))
    return scene, np.array([np.asarray(c, float) for _, _, c in b.mb.meshes])


def _shoot(
    out: Path, scene: Any, colors: FloatArray, plan: Plan, camera: str, rng: Rng
) -> tuple[dict[str, dict[str, Any]], FloatArray]:
    """Each planned frame posed (a station's height 1-1.6 m, yaw +-2 degrees, pitch 0-25
    down, roll +-5, position +-3 cm), rendered and written to ``out/frames/<id>``; the
    frames' truth and the stations' heights."""
    st, frames = plan.stations, plan.frames
    cam = CAMERAS[camera]
    heights = rng.uniform(1.0, 1.6, len(st))
    perm = rng.permutation(len(frames))  # ids not in capture order
    truth = {}
    for j, (k, yaw0) in enumerate(frames):
        yaw = yaw0 + math.radians(rng.uniform(-2, 2))
        pitch = math.radians(rng.uniform(0, 25))
        roll = math.radians(rng.uniform(-5, 5))
        pos = np.array([st[k][0] + rng.normal(0, 0.03), st[k][1] + rng.normal(0, 0.03),
                        heights[k] + rng.normal(0, 0.02)])  # fmt: skip
        T = cam_pose(pos, yaw, pitch, roll)
        noise_model = "kinect" if camera == "kinect" else "realsense"
        depth, color = render_frame(scene, colors, T, cam, rng, noise_model)
        fid = f"frame_{perm[j]:02d}"
        fd = out / "frames" / fid
        fd.mkdir(parents=True, exist_ok=True)
        Image.fromarray(depth).save(fd / "depth.png")
        Image.fromarray(color).save(fd / "color.png")
        (fd / "intrinsics.json").write_text(json.dumps({**cam, "depth_scale": 1000.0}))
        truth[fid] = dict(
            pose=T.tolist(), station=int(k), capture_index=j, yaw_deg=math.degrees(yaw),
            pitch_deg=math.degrees(pitch), roll_deg=math.degrees(roll),
            valid_frac=float((depth > 0).mean()),
        )  # fmt: skip
    return truth, heights


def make_scene(
    outdir: Path, seed: int, camera: str, kind: str, shapes: tuple[RealShape, ...] | None = None
) -> dict[str, Any]:
    """Render one scene into ``outdir`` (``frames/<id>/{depth,color}.png, intrinsics.json``
    and ``truth.json``); its truth.

    Parameters
    ----------
    outdir : Path
        Created if missing.
    seed : int
        The scene's seed: the same seed gives the same scene.
    camera : str
        One of :data:`CAMERAS`.
    kind : str
        One of :data:`KINDS` ("real": a test-split outline).
    shapes : tuple, optional
        The real outlines to draw from (default :func:`real_shapes`).

    Returns
    -------
    dict
        The truth: ``polygon`` (K, 2) CCW world meters, ``frames`` (id to ``pose``, optical
        to world 4x4, and its station), stations, doors, windows, furniture.
    """
    rng = np.random.default_rng(seed)
    cam = dict(CAMERAS[camera])
    hfov = math.degrees(2 * math.atan(cam["width"] / 2 / cam["fx"]))
    poly, house, shape_idx, plan = _room_and_plan(kind, camera, hfov, rng, shapes)
    H = float(rng.uniform(2.5, 3.0))
    b = build_scene(poly, H, rng, plan.stations)
    scene, colors = _raycasting(b)
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    truth_frames, heights = _shoot(out, scene, colors, plan, camera, rng)
    truth = dict(
        seed=seed, camera=camera, intrinsics=cam, hfov_deg=hfov, kind=kind, house=house,
        shape_index=shape_idx, polygon=poly.tolist(), n_corners=len(poly), ceiling=H,
        wall_thickness=b.thick, stations=plan.stations.tolist(), station_heights=heights.tolist(),
        corner_stations=plan.corner, n_frames=len(plan.frames), coverage=plan.coverage,
        overlap=plan.overlap, doors=b.doors, windows=b.windows, furniture=b.furniture,
        frames=truth_frames,
    )  # fmt: skip
    (out / "truth.json").write_text(json.dumps(truth, indent=1))
    return truth


def main(argv: list[str] | None = None) -> int:
    """Render one scene (options: see ``--help``) and print a summary line."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("outdir", type=Path)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--camera", default="kinect", choices=list(CAMERAS))
    parser.add_argument("--kind", default="rect", choices=KINDS)
    args = parser.parse_args(argv)
    t = make_scene(args.outdir, args.seed, args.camera, args.kind)
    print(f"{t['kind']} {t['camera']}: {t['n_corners']} corners, {t['n_frames']} frames, "
          f"coverage {t['coverage']:.2f}, overlap {t['overlap']:.2f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
