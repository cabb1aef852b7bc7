"""Floorplan polygon and 3D layout model from placed wall chains."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from services.geometry import cross, signed_area
from services.placement import Piece, rot90
from services.placement.corners import corner_offsets, corner_view
from services.types import FloatArray

__all__ = ["LayoutMesh", "build_polygon", "layout_mesh"]


def _simplify(points: FloatArray, tolerance: float = 1e-3) -> FloatArray:
    """Drop repeated and collinear vertices of a closed polygon.

    Repeats go first: a corner followed by copies of itself has no outgoing direction, and
    judging it collinear then would drop the corner with its copies.

    >>> square = np.array([[0, 0], [1, 0], [1, 0], [1, 0], [1, 1], [0.5, 1], [0, 1]], float)
    >>> _simplify(square).tolist()
    [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
    """
    pts = points
    for _ in range(len(points)):
        if len(pts) < 3:
            return pts
        prev, nxt = np.roll(pts, 1, axis=0), np.roll(pts, -1, axis=0)
        a, b = pts - prev, nxt - pts
        short = np.linalg.norm(a, axis=1) < tolerance
        if short.any() and (~short).sum() >= 3:
            pts = pts[~short]
            continue
        drop = np.abs(cross(a, b)) < tolerance * np.maximum(np.linalg.norm(b, axis=1), 1e-9)
        if not drop.any():
            return pts
        pts = pts[~drop] if (~drop).sum() >= 3 else pts[:3]
    return pts


def _junction(
    q: FloatArray, d_in: FloatArray, p: FloatArray, d_out: FloatArray, step_late: bool = False
) -> FloatArray:
    """Vertices replacing a junction from a wall ending at q to one starting at p; a jog
    between parallel walls stands at q, or with ``step_late`` at p."""
    if abs(float(d_in @ d_out)) < 0.5:
        # Perpendicular: the corner where the two wall lines meet.
        corner = np.where(np.abs(d_in) > 0.5, p, q)
        return corner[None, :]
    # Parallel: continue along the wall; keep a jog if the offsets disagree.
    normal = np.array([-d_in[1], d_in[0]])
    if abs(float(normal @ (p - q))) < 1e-3:
        return np.zeros((0, 2))
    if step_late:
        return np.vstack([q + d_in * float(d_in @ (p - q)), p])
    return np.vstack([q, q + normal * float(normal @ (p - q))])


def build_polygon(
    pieces: Sequence[Piece],
    rotations: Sequence[int],
    translations: FloatArray,
    shared: Sequence[int] = (),
) -> FloatArray:
    """The room boundary from the placed chains: (V, 2) float64, site frame, CCW.

    Parameters
    ----------
    pieces : chains in loop order.
    rotations : quarter turns per piece.
    translations : (n, 2) site position of each piece's source.
    shared : per loop position, how many corners the piece shares with the one before
        (``PlacementCandidate.shared``): the loop goes on from the last of them along it.
    """
    if any(shared):
        translations = translations + corner_offsets(pieces, rotations, shared)
        pieces, _ = corner_view(pieces, shared, {})
    sites = [
        p.keypoints @ rot90(r).T + t
        for p, r, t in zip(pieces, rotations, translations, strict=True)
    ]
    n = len(sites)
    vertices: list[FloatArray] = []
    for i in range(n):
        chain, nxt = sites[i], sites[(i + 1) % n]
        vertices.append(chain[1:-1])
        d_in = _unit(chain[-1] - chain[-2])
        d_out = _unit(nxt[1] - nxt[0])
        # A step hides at the end whose view lost the wall (services.open_ends): the wall
        # of the other end goes on, out of its view, up to the step.
        step_late = pieces[(i + 1) % n].open_ends[0] and not pieces[i].open_ends[1]
        vertices.append(_junction(chain[-1], d_in, nxt[0], d_out, step_late))
    polygon = np.vstack(vertices) if vertices else np.zeros((0, 2))
    if len(polygon) >= 4:
        polygon = _simplify(_remove_jogs(_snap_to_axes(_simplify(polygon))))
    if len(polygon) >= 3 and signed_area(polygon) < 0:
        polygon = polygon[::-1]
    return polygon


def _snap_to_axes(polygon: FloatArray) -> FloatArray:
    """Make nearly axis-parallel edges exactly so, each at the mean of its two ends.

    Walls joined in parallel may keep a centimetre of offset mismatch after refinement; in
    a rectilinear polygon every vertex takes x from one edge and y from the other, so
    snapping each edge's constant coordinate keeps the polygon consistent.
    """
    out = polygon.copy()
    nxt = np.roll(np.arange(len(out)), -1)
    for i, j in zip(range(len(out)), nxt, strict=True):
        delta = np.abs(out[j] - out[i])
        axis = 1 if delta[0] >= delta[1] else 0  # the coordinate this edge keeps constant
        if delta[axis] < 0.25 * max(float(delta.max()), 1e-9):
            mean = 0.5 * (out[i, axis] + out[j, axis])
            out[i, axis] = out[j, axis] = mean
    return out


def _remove_jogs(polygon: FloatArray, tolerance: float = 0.21) -> FloatArray:
    """Join parallel walls separated by a jog shorter than ``tolerance`` into one wall at
    their length-weighted mean offset. The refinement leaves up to 10 cm between walls
    joined in parallel, and two such junctions along one wall add up (0.12 m left outside
    frame rooms with a corner too many: seeds 19-23, 6 of 300); a real step in a room is
    longer (about 1 MatterportLayout outline in 20 has an edge under 0.2 m)."""
    out = polygon.copy()
    n = len(out)
    for _ in range(n):
        changed = False
        for i in range(n):
            a, b, c, d = (out[(i + k) % n] for k in range(4))  # edges ab, bc (jog), cd
            jog = c - b
            axis = 0 if abs(jog[0]) >= abs(jog[1]) else 1  # the jog runs along this axis
            if not 0 < abs(jog[axis]) < tolerance:
                continue
            if abs(b[axis] - a[axis]) > 1e-9 or abs(d[axis] - c[axis]) > 1e-9:
                continue  # neighbours are not parallel to each other across the jog
            w1, w2 = np.abs(b - a).sum(), np.abs(d - c).sum()
            mean = (w1 * b[axis] + w2 * c[axis]) / max(w1 + w2, 1e-12)
            for k in range(4):
                out[(i + k) % n, axis] = mean
            changed = True
        if not changed:
            break
    return out


def _unit(v: FloatArray) -> FloatArray:
    norm = float(np.linalg.norm(v))
    return v / norm if norm > 0 else v


@dataclass(frozen=True)
class LayoutMesh:
    """Triangle mesh of the 3D layout: walls, floor and ceiling.

    vertices: (V, 3) float64, site frame; triangles: (T, 3) int64, outward-agnostic.
    """

    vertices: FloatArray
    triangles: NDArray[np.int64]


def _fan(polygon: FloatArray, z: float, offset: int) -> tuple[FloatArray, NDArray[np.int64]]:
    """Ear-clipping triangulation of a simple polygon at height z."""
    idx = list(range(len(polygon)))
    tris: list[tuple[int, int, int]] = []
    guard = 0
    while len(idx) > 3 and guard < 10 * len(polygon):
        guard += 1
        for k in range(len(idx)):
            a, b, c = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            pa, pb, pc = polygon[a], polygon[b], polygon[c]
            if (pb[0] - pa[0]) * (pc[1] - pa[1]) - (pb[1] - pa[1]) * (pc[0] - pa[0]) <= 0:
                continue
            others = [polygon[m] for m in idx if m not in (a, b, c)]
            if not any(_inside_triangle(o, pa, pb, pc) for o in others):
                tris.append((a, b, c))
                idx.pop(k)
                break
    if len(idx) == 3:
        tris.append((idx[0], idx[1], idx[2]))
    verts = np.column_stack([polygon, np.full(len(polygon), z)])
    return verts, np.asarray(tris, dtype=np.int64).reshape(-1, 3) + offset


def _inside_triangle(p: FloatArray, a: FloatArray, b: FloatArray, c: FloatArray) -> bool:
    def side(u: FloatArray, v: FloatArray) -> float:
        return float((v[0] - u[0]) * (p[1] - u[1]) - (v[1] - u[1]) * (p[0] - u[0]))

    return side(a, b) >= 0 and side(b, c) >= 0 and side(c, a) >= 0


def layout_mesh(polygon: FloatArray, floor_z: float, ceiling_z: float) -> LayoutMesh:
    """Walls between floor and ceiling heights, plus floor and ceiling polygons."""
    n = len(polygon)
    if n < 3:
        return LayoutMesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    bottom = np.column_stack([polygon, np.full(n, floor_z)])
    top = np.column_stack([polygon, np.full(n, ceiling_z)])
    k = np.arange(n)
    k1 = (k + 1) % n
    walls = np.vstack([np.column_stack([k, k1, n + k1]), np.column_stack([k, n + k1, n + k])])
    floor_v, floor_t = _fan(polygon, floor_z, 2 * n)
    ceil_v, ceil_t = _fan(polygon, ceiling_z, 3 * n)
    return LayoutMesh(
        vertices=np.vstack([bottom, top, floor_v, ceil_v]),
        triangles=np.vstack([walls, floor_t, ceil_t[:, ::-1]]),
    )
