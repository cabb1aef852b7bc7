"""Random rectilinear rooms and plane-polygon geometry for synthetic scenes.

Everything is in the world frame: right-handed, z up, floor at z = 0, meters. Room boundary
polygons are (V, 2) float64, counter-clockwise seen from above (interior on the left of
every edge), first vertex not repeated, only axis-aligned edges.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from services.geometry import points_in_polygon, signed_area
from services.types import FloatArray

__all__ = [
    "Room",
    "grid_lines",
    "grid_outline",
    "nearest_boundary",
    "point_at_arc",
    "points_in_polygon",
    "random_rectilinear_polygon",
    "signed_area",
]

BoolArray = NDArray[np.bool_]
_Vertex = tuple[int, int]


@dataclass(frozen=True)
class Room:
    """A room boundary with per-edge data precomputed.

    polygon: (V, 2) world, CCW. starts: (V, 2) edge start points; dirs: (V, 2) unit edge
    directions; normals: (V, 2) unit inward normals (left of dirs); lengths: (V,);
    arcs: (V + 1,) arc length along the loop at each vertex (arcs[0] = 0, arcs[V] =
    perimeter). height: ceiling height above the floor (z = 0).
    """

    polygon: FloatArray
    height: float
    dirs: FloatArray
    normals: FloatArray
    lengths: FloatArray
    arcs: FloatArray

    @classmethod
    def from_polygon(cls, polygon: FloatArray, height: float) -> Room:
        """Precompute the edge data of a CCW polygon."""
        delta = np.roll(polygon, -1, axis=0) - polygon
        lengths = np.linalg.norm(delta, axis=1)
        dirs = delta / lengths[:, None]
        normals = np.column_stack([-dirs[:, 1], dirs[:, 0]])
        arcs = np.concatenate([[0.0], np.cumsum(lengths)])
        return cls(polygon, float(height), dirs, normals, lengths, arcs)

    @property
    def starts(self) -> FloatArray:
        """(V, 2) edge start points (the polygon vertices)."""
        return self.polygon

    @property
    def perimeter(self) -> float:
        """Length of the boundary loop."""
        return float(self.arcs[-1])

    @property
    def n_edges(self) -> int:
        """Number of edges (equal to the number of corners)."""
        return len(self.polygon)


def nearest_boundary(xy: FloatArray, room: Room) -> tuple[FloatArray, FloatArray]:
    """Distance from (M, 2) points to the room boundary, and the arc position of the foot.

    Returns (distance (M,), arc (M,)); arc is in [0, perimeter).
    """
    x, y = xy[:, 0], xy[:, 1]
    best = np.full(len(xy), np.inf)
    arc = np.zeros(len(xy))
    for e in range(room.n_edges):
        (px, py), (dx, dy) = room.polygon[e], room.dirs[e]
        rx, ry = x - px, y - py
        t = np.clip(rx * dx + ry * dy, 0.0, room.lengths[e])
        ex, ey = rx - t * dx, ry - t * dy
        squared = ex * ex + ey * ey  # squared distances: no sqrt inside the edge loop
        closer = squared < best
        best = np.where(closer, squared, best)
        arc = np.where(closer, room.arcs[e] + t, arc)
    return np.sqrt(best), np.mod(arc, room.perimeter)


def point_at_arc(room: Room, arc: FloatArray) -> tuple[FloatArray, NDArray[np.intp]]:
    """Points at arc positions (any real values, taken modulo the perimeter) on the loop.

    Returns ((M, 2) world points, (M,) index of the edge each lies on).
    """
    s = np.mod(np.asarray(arc, dtype=np.float64), room.perimeter)
    edge = np.clip(np.searchsorted(room.arcs, s, side="right") - 1, 0, room.n_edges - 1)
    points = room.polygon[edge] + (s - room.arcs[edge])[:, None] * room.dirs[edge]
    return points, edge


def random_rectilinear_polygon(
    rng: np.random.Generator,
    size: tuple[float, float],
    n_corners: int,
    min_edge: float,
) -> FloatArray:
    """A random simple rectilinear CCW polygon whose bounding box is ``size`` (x, y).

    Carves cells out of a coarse grid whose cells are at least ``min_edge`` wide, so no edge
    (and no corridor) is shorter than that. Aims for ``n_corners`` (even) corners and returns
    the closest count reached (never more). Bounding box min corner at (0, 0); the first
    vertex is random.
    """
    best = np.array([[0.0, 0.0], [size[0], 0.0], [size[0], size[1]], [0.0, size[1]]])
    for _ in range(8):
        xs = _cuts(rng, size[0], min_edge)
        ys = _cuts(rng, size[1], min_edge)
        loop = _carve(rng, len(xs) - 1, len(ys) - 1, n_corners)
        polygon = np.array([[xs[i], ys[j]] for i, j in loop])
        if len(polygon) > len(best):
            best = polygon
        if len(best) == n_corners:
            break
    return np.roll(best, -int(rng.integers(len(best))), axis=0)


def grid_lines(rng: np.random.Generator, length: float, n: int, min_edge: float) -> FloatArray:
    """(n + 1,) grid line positions 0 = c_0 < ... < c_n = length, cm-rounded, cells at least
    ``min_edge`` wide (random widths; needs ``length >= n * (min_edge + 0.02)``)."""
    spare = length - n * (min_edge + 0.02)
    widths = (min_edge + 0.02) + spare * rng.dirichlet(np.full(n, 2.0))
    cuts = np.round(np.concatenate([[0.0], np.cumsum(widths)]), 2)
    cuts[-1] = length
    return cuts


def _cuts(rng: np.random.Generator, length: float, min_edge: float) -> FloatArray:
    """Grid lines of 1 to 6 random cells (at least 2 when they fit), see :func:`grid_lines`."""
    cap = int(np.clip(np.floor(length / (min_edge + 0.02)), 1, 6))
    return grid_lines(rng, length, int(rng.integers(min(2, cap), cap + 1)), min_edge)


def _carve(rng: np.random.Generator, nx: int, ny: int, target: int) -> list[_Vertex]:
    """Remove boundary cells from a full nx x ny grid until the outline has ``target`` corners.

    Every accepted state is one simple loop without holes or pinches whose bounding box is
    still the full grid. Returns the outline's corner vertices (grid indices), CCW.
    """
    occupied = np.ones((nx, ny), dtype=bool)
    loop = grid_outline(occupied)
    assert loop is not None
    while len(loop) < target:
        cells = [tuple(c) for c in np.argwhere(occupied)]
        order = rng.permutation(len(cells))
        accepted: list[_Vertex] | None = None
        for k in order:
            i, j = cells[k]
            occupied[i, j] = False
            candidate = grid_outline(occupied) if _keeps_bbox(occupied) else None
            if candidate is not None and len(candidate) <= target:
                accepted = candidate
                break
            occupied[i, j] = True
        if accepted is None or occupied.mean() < 0.4:
            break
        loop = accepted
    return loop


def _keeps_bbox(occupied: NDArray[np.bool_]) -> bool:
    """True when the first and last row and column still hold a cell (bbox unchanged)."""
    edges = (occupied[0], occupied[-1], occupied[:, 0], occupied[:, -1])
    return all(bool(edge.any()) for edge in edges)


def grid_outline(occupied: NDArray[np.bool_]) -> list[_Vertex] | None:
    """CCW corner vertices of the occupied cells, or None unless they form one simple loop.

    occupied: (nx, ny) bool, cell (i, j) spans grid lines i..i+1 along x and j..j+1 along y.
    Returns the loop's turning vertices as grid indices (i, j), counter-clockwise.
    """
    nx, ny = occupied.shape
    padded = np.pad(occupied, 1)
    following: dict[_Vertex, _Vertex] = {}
    for i, j in np.argwhere(occupied):
        pi, pj = i + 1, j + 1
        # Each exposed cell side, walked with the cell on its left (CCW).
        sides = (
            (not padded[pi, pj - 1], (i, j), (i + 1, j)),
            (not padded[pi + 1, pj], (i + 1, j), (i + 1, j + 1)),
            (not padded[pi, pj + 1], (i + 1, j + 1), (i, j + 1)),
            (not padded[pi - 1, pj], (i, j + 1), (i, j)),
        )
        for exposed, a, b in sides:
            if exposed:
                if a in following:
                    return None  # two cells touch only at a vertex
                following[(int(a[0]), int(a[1]))] = (int(b[0]), int(b[1]))
    start = next(iter(following))
    walk = [start]
    while (nxt := following[walk[-1]]) != start:
        walk.append(nxt)
    if len(walk) != len(following) or nx * ny == 0:
        return None  # holes or several pieces
    return [v for k, v in enumerate(walk) if _turns(walk[k - 1], v, walk[(k + 1) % len(walk)])]


def _turns(a: _Vertex, b: _Vertex, c: _Vertex) -> bool:
    """True when a -> b -> c changes direction at b."""
    return (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0]) != 0
