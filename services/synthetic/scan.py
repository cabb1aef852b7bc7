"""Surface sampling for one synthetic fragment: what a scan of one stretch of wall sees.

A fragment sees the walls of its stretch of the room loop (full height, minus openings and
the wall hidden behind furniture), the reveals of the parts of openings on it, the floor
beyond its doors, and the floor, ceiling and furniture in front of its walls: points whose
nearest wall point lies on the stretch (grown by ``ScanStyle.beyond``), within a reach. All
points are world frame, noise-free.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from services.synthetic.furniture import Box, Furnishing, Opening
from services.synthetic.room import Room, nearest_boundary, point_at_arc, points_in_polygon
from services.types import FloatArray

__all__ = ["ScanStyle", "Stretch", "sample_scan", "stretch_keypoints"]

BoolArray = NDArray[np.bool_]
_PILOT_DENSITY = 30.0  # points per m², to measure the visible area before the real pass
_SCANNER_HEIGHT = 1.5
_VIEW_DEPTH = 1.5  # m, a scanner's distance from a door: the view past it widens by far / this


@dataclass(frozen=True)
class Stretch:
    """A contiguous piece of the CCW loop: from arc ``start`` in [0, perimeter), ``length`` long."""

    start: float
    length: float


@dataclass(frozen=True)
class ScanStyle:
    """How one scan samples the surfaces it sees.

    reach: floor (and furniture) visible up to this distance from the stretch's walls, m.
    ceiling_reach: the same for the ceiling; 0 for none.
    falloff: density ~ (1 + d / 2 m) ** -falloff, d the distance to the nearest virtual
    scanner position; 0 for uniform density.
    scanner_spacing: one scanner position per this many meters of stretch.
    patch_gain: density factor inside one random sphere of 0.5-1.5 m radius (1 for none).
    see_through: also sample the floor beyond the doors.
    far_walls: with ``see_through``, the share of doors through which the scan also sees the
    next room's wall facing the door.
    oversample: candidates drawn per kept point before density thinning.
    beyond: floor, ceiling and furniture are seen in front of the stretch grown by this much
    along the loop at both ends, m (walls only on the stretch itself).
    """

    reach: float
    ceiling_reach: float
    falloff: float
    scanner_spacing: float
    patch_gain: float
    see_through: bool
    oversample: float
    beyond: float = 0.0
    far_walls: float = 0.0


def stretch_keypoints(room: Room, stretch: Stretch) -> FloatArray:
    """(K, 2) world keypoints of a stretch: its start, the corners inside it, its end."""
    inside = np.mod(room.arcs[:-1] - stretch.start, room.perimeter)
    order = np.argsort(inside)
    corners = order[(inside[order] > 0.0) & (inside[order] < stretch.length)]
    ends, _ = point_at_arc(room, np.array([stretch.start, stretch.start + stretch.length]))
    return np.vstack([ends[:1], room.polygon[corners], ends[1:]])


def sample_scan(
    rng: np.random.Generator,
    room: Room,
    furnishing: Furnishing,
    stretch: Stretch,
    style: ScanStyle,
    n_points: int,
) -> FloatArray:
    """(n, 3) noise-free world points of one scan, n <= n_points (n_points unless the scene is
    too small to hold that many distinct samples).

    Candidates are drawn uniformly per surface area, then thinned to ``n_points`` with
    weighted sampling without replacement so density falls with distance to the scanner.
    """
    pilot = _candidates(rng, room, furnishing, stretch, style, _PILOT_DENSITY)
    area = max(len(pilot) / _PILOT_DENSITY, 1.0)
    density = style.oversample * n_points / area
    points = _candidates(rng, room, furnishing, stretch, style, density)
    weights = _density_weights(rng, room, stretch, style, points)
    if len(points) <= n_points:
        return points
    # Weighted sampling without replacement (exponential keys, Efraimidis-Spirakis).
    keys = rng.standard_exponential(len(points)) / weights
    # In index order: argpartition's own order depends on numpy's SIMD level, and the noise
    # is drawn per point in this order.
    return points[np.sort(np.argpartition(keys, n_points - 1)[:n_points])]


def _candidates(
    rng: np.random.Generator,
    room: Room,
    furnishing: Furnishing,
    stretch: Stretch,
    style: ScanStyle,
    density: float,
) -> FloatArray:
    parts = _walls(rng, room, furnishing, stretch, density)
    parts += _reveals(rng, room, furnishing, stretch, style, density)
    region = _grown(room, stretch, style.beyond)
    keypoints = stretch_keypoints(room, region)
    for z, reach in ((0.0, style.reach), (room.height, style.ceiling_reach)):
        if reach <= 0.0:
            continue
        lo = np.maximum(keypoints.min(axis=0) - reach, room.polygon.min(axis=0))
        hi = np.minimum(keypoints.max(axis=0) + reach, room.polygon.max(axis=0))
        flat = _rect(rng, np.append(lo, z), [hi[0] - lo[0], 0, 0], [0, hi[1] - lo[1], 0], density)
        flat = flat[_in_front(flat[:, :2], room, region, keypoints, reach)]
        keep = points_in_polygon(flat[:, :2], room.polygon)
        if z == 0.0:
            keep &= ~_under_boxes(flat[:, :2], furnishing.boxes)
        parts.append(flat[keep])
    lo, hi = keypoints.min(axis=0) - style.reach, keypoints.max(axis=0) + style.reach
    for box in furnishing.boxes:
        if np.all(box.hi[:2] >= lo) and np.all(box.lo[:2] <= hi):
            faces = _box_faces(rng, box, density)
            parts.append(faces[_in_front(faces[:, :2], room, region, keypoints, style.reach)])
    return np.vstack(parts)


def _grown(room: Room, stretch: Stretch, beyond: float) -> Stretch:
    """The stretch grown by ``beyond`` at both ends (at most the whole loop)."""
    if beyond <= 0.0:
        return stretch
    length = min(stretch.length + 2.0 * beyond, room.perimeter)
    return Stretch(float(np.mod(stretch.start - beyond, room.perimeter)), length)


def _walls(
    rng: np.random.Generator,
    room: Room,
    furnishing: Furnishing,
    stretch: Stretch,
    density: float,
) -> list[FloatArray]:
    """Wall points of the stretch, minus openings and the wall hidden behind furniture."""
    parts = [np.zeros((0, 3))]
    for e in range(room.n_edges):
        d, start = room.dirs[e], room.polygon[e]
        for t_lo, t_hi in _visible_intervals(room, e, stretch):
            wall = _rect(
                rng, np.append(start + t_lo * d, 0.0), np.append((t_hi - t_lo) * d, 0.0),
                [0.0, 0.0, room.height], density,
            )  # fmt: skip
            t, z = (wall[:, :2] - start) @ d, wall[:, 2]
            hidden = np.zeros(len(wall), dtype=bool)
            for o in furnishing.openings:
                if o.edge == e:
                    hidden |= (t >= o.t0) & (t <= o.t1) & (z >= o.z0) & (z <= o.z1)
            for c in furnishing.covers:
                if c.edge == e:
                    hidden |= (t >= c.t0) & (t <= c.t1) & (z <= c.height)
            parts.append(wall[~hidden])
    return parts


def _reveals(
    rng: np.random.Generator,
    room: Room,
    furnishing: Furnishing,
    stretch: Stretch,
    style: ScanStyle,
    density: float,
) -> list[FloatArray]:
    """Jambs, lintels and sills of the parts of openings on the stretch, and the floor seen
    through doors. A jamb is seen when its side of the opening is on the stretch."""
    parts: list[FloatArray] = []
    depth = furnishing.wall_thickness
    for o in furnishing.openings:
        pieces = [
            (max(o.t0, lo), min(o.t1, hi))
            for lo, hi in _visible_intervals(room, o.edge, stretch)
            if min(o.t1, hi) > max(o.t0, lo)
        ]
        if not pieces:
            continue
        d, out = np.append(room.dirs[o.edge], 0.0), np.append(-room.normals[o.edge], 0.0)
        height = np.array([0.0, 0.0, o.z1 - o.z0])
        low = np.append(room.polygon[o.edge], 0.0) + o.t0 * d + np.array([0.0, 0.0, o.z0])
        if any(a == o.t0 for a, _ in pieces):
            parts.append(_rect(rng, low, depth * out, height, density))
        if any(b == o.t1 for _, b in pieces):
            parts.append(_rect(rng, low + (o.t1 - o.t0) * d, depth * out, height, density))
        for a, b in pieces:
            parts += _across(rng, room, o, (a, b), depth, style, density)
    return parts


def _across(
    rng: np.random.Generator,
    room: Room,
    o: Opening,
    piece: tuple[float, float],
    depth: float,
    style: ScanStyle,
    density: float,
) -> list[FloatArray]:
    """Lintel and sill (or the floor beyond a door) of one piece [a, b] of an opening."""
    d, out = np.append(room.dirs[o.edge], 0.0), np.append(-room.normals[o.edge], 0.0)
    corner = np.append(room.polygon[o.edge], 0.0) + piece[0] * d
    width, low = (piece[1] - piece[0]) * d, corner + np.array([0.0, 0.0, o.z0])
    parts = [_rect(rng, low + np.array([0.0, 0.0, o.z1 - o.z0]), width, depth * out, density)]
    if o.z0 > 0.0:
        parts.append(_rect(rng, low, width, depth * out, density))
    elif style.see_through:
        beyond = float(rng.uniform(0.5, 2.0))
        parts.append(_rect(rng, corner + depth * out, width, beyond * out, density))
        if style.far_walls > 0.0 and rng.random() < style.far_walls:
            parts.append(_far_wall(rng, room, corner + depth * out, width, out, density))
    return parts


def _far_wall(
    rng: np.random.Generator,
    room: Room,
    mouth: FloatArray,
    width: FloatArray,
    out: FloatArray,
    density: float,
) -> FloatArray:
    """The next room's wall facing a door, seen through it, and its floor up to that wall:
    the wall parallel to the door's wall, 1-3 m behind it, whole height, and wider than the
    door the farther it stands (the view widens past the jambs), the floor in that widening
    view. ``mouth``: the door's outer corner at the floor; ``width``: the door (its piece on
    the stretch) along its wall. Nothing inside the room itself."""
    far = float(rng.uniform(1.0, 3.0))
    spread = 0.5 * far / _VIEW_DEPTH * width  # past each jamb
    wall = _rect(
        rng, mouth + far * out - spread, width + 2 * spread, [0.0, 0.0, room.height], density
    )
    floor = _rect(rng, mouth - spread, width + 2 * spread, far * out, density)
    # Across the door from its middle, and out from its wall: the view widens with depth.
    door = float(np.linalg.norm(width))
    across = np.abs((floor - mouth - 0.5 * width) @ (width / door))
    depth = (floor - mouth) @ out
    floor = floor[across <= 0.5 * door * (1.0 + depth / _VIEW_DEPTH)]
    seen = np.vstack([wall, floor])
    return seen[~points_in_polygon(seen[:, :2], room.polygon)]


def _visible_intervals(room: Room, e: int, stretch: Stretch) -> list[tuple[float, float]]:
    """Pieces [t_lo, t_hi] of edge e (t along the edge) that lie on the stretch."""
    a, length = room.arcs[e], room.lengths[e]
    pieces = []
    for shift in (-room.perimeter, 0.0):  # the stretch may wrap past arc 0
        lo = max(a, stretch.start + shift)
        hi = min(a + length, stretch.start + stretch.length + shift)
        if hi > lo:
            pieces.append((float(lo - a), float(hi - a)))
    return pieces


def _on_stretch(arc: FloatArray, room: Room, stretch: Stretch) -> BoolArray:
    return np.mod(arc - stretch.start, room.perimeter) <= stretch.length


def _in_front(
    xy: FloatArray, room: Room, stretch: Stretch, keypoints: FloatArray, reach: float
) -> BoolArray:
    """Points within ``reach`` of the boundary whose nearest boundary point is on the stretch.

    Such points are within reach of the stretch's own polyline (keypoints), a cheap test on
    a few segments that spares the full nearest-boundary search for most candidates.
    """
    x, y = xy[:, 0], xy[:, 1]
    near = np.zeros(len(xy), dtype=bool)
    for (ax, ay), (bx, by) in itertools.pairwise(keypoints):
        dx, dy = bx - ax, by - ay
        rx, ry = x - ax, y - ay
        t = np.clip((rx * dx + ry * dy) / (dx * dx + dy * dy), 0.0, 1.0)
        ex, ey = rx - t * dx, ry - t * dy
        near |= ex * ex + ey * ey <= reach * reach
    idx = np.flatnonzero(near)
    distance, arc = nearest_boundary(xy[idx], room)
    near[idx] = (distance <= reach) & _on_stretch(arc, room, stretch)
    return near


def _under_boxes(xy: FloatArray, boxes: tuple[Box, ...]) -> BoolArray:
    """Points under the footprint of a solid box (whose floor the scanner cannot see)."""
    under = np.zeros(len(xy), dtype=bool)
    order = np.argsort(xy[:, 0])  # sorted x: each box only looks at its own x slab
    xs = xy[order, 0]
    for b in boxes:
        if b.solid:
            slab = order[np.searchsorted(xs, b.lo[0]) : np.searchsorted(xs, b.hi[0], "right")]
            y = xy[slab, 1]
            under[slab[(y >= b.lo[1]) & (y <= b.hi[1])]] = True
    return under


def _box_faces(rng: np.random.Generator, box: Box, density: float) -> FloatArray:
    """Points on the faces of a box that are not hidden."""
    size = box.hi - box.lo
    parts = [np.zeros((0, 3))]
    for axis in range(3):
        u_axis, v_axis = [k for k in range(3) if k != axis]
        u, v = np.zeros(3), np.zeros(3)
        u[u_axis], v[v_axis] = size[u_axis], size[v_axis]
        for side in (0, 1):
            if (axis, side) not in box.hidden:
                origin = box.lo.copy()
                origin[axis] = box.hi[axis] if side else box.lo[axis]
                parts.append(_rect(rng, origin, u, v, density))
    return np.vstack(parts)


def _rect(
    rng: np.random.Generator,
    origin: FloatArray,
    u: FloatArray | list[float],
    v: FloatArray | list[float],
    density: float,
) -> FloatArray:
    """Uniform points on the parallelogram origin + a u + b v, a, b in [0, 1]; Poisson count."""
    u_arr, v_arr = np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64)
    n = int(rng.poisson(density * float(np.linalg.norm(np.cross(u_arr, v_arr)))))
    ab = rng.random((n, 2))
    return origin + ab[:, :1] * u_arr + ab[:, 1:] * v_arr


def _density_weights(
    rng: np.random.Generator,
    room: Room,
    stretch: Stretch,
    style: ScanStyle,
    points: FloatArray,
) -> FloatArray:
    """Relative sampling density per point: distance falloff times one denser patch."""
    n_scanners = max(1, int(np.ceil(stretch.length / style.scanner_spacing)))
    arcs = stretch.start + (np.arange(n_scanners) + 0.5) * stretch.length / n_scanners
    feet, edges = point_at_arc(room, arcs)
    scanners = np.column_stack(
        [feet + 1.2 * room.normals[edges], np.full(n_scanners, _SCANNER_HEIGHT)]
    )
    squared = np.full(len(points), np.inf)
    for sx, sy, sz in scanners:
        dx, dy, dz = points[:, 0] - sx, points[:, 1] - sy, points[:, 2] - sz
        squared = np.minimum(squared, dx * dx + dy * dy + dz * dz)
    weights: FloatArray = (1.0 + np.sqrt(squared) / 2.0) ** -style.falloff
    if len(points) and style.patch_gain > 1.0:
        centre = points[rng.integers(len(points))]
        radius = rng.uniform(0.5, 1.5)
        weights[np.linalg.norm(points - centre, axis=1) < radius] *= style.patch_gain
    return weights
