"""Sparse RGB-D frames of synthetic rooms, rendered by ray casting, with ground truth.

The room (a random one of a shape family, or a given outline), its doors, windows and
furniture (:mod:`services.synthetic.furniture`) become one triangle mesh: wall slabs with the
openings cut out, floor and ceiling reaching past the walls, an enclosure around it all (what
a door or window shows of the outside) and the furniture boxes. Open3D's RaycastingScene
renders depth (Kinect-like noise: sigma grows with depth squared; dropouts at grazing angles
and at random) and a procedural colour texture (for ORB matching) from a few stations, each
frame looking around. Frames are chosen so that, in loop order, each one's stretch of room
boundary starts where the previous one's ended, give or take a few decimeters: little or no
overlap, as in the paper's sparse frames.

A frame's stretch, its true wall chain, is what its camera can see of the loop, found by
casting floor-plan rays across its field of view: the wall parts its rays reach first (not
those behind a protruding corner), at 10 degrees or more from the wall's surface (a wall seen
edge-on gives too few points to be located), in runs of 0.3 m or more along one wall (not a
sliver past a corner), from the first such part to the last. Hidden parts between two seen
ones stay in the chain only when what is seen tells where they run (the same wall, the next
one, or one wall further when a seen part reaches its corner); a view whose seen walls make
two chains is not used.

World frame: z up, floor at z = 0, meters. A frame's local frame is its optical frame (x
right, y down, z forward). Pure: returns arrays, writes no file.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import open3d as o3d
from numpy.typing import NDArray

from schemas.frames import IntrinsicsModel
from services.geometry import cross, points_in_polygon
from services.rgbd import RgbdFrame
from services.synthetic.families import pick_family, random_room
from services.synthetic.furniture import Box, Furnishing, furnish_room
from services.synthetic.room import Room, nearest_boundary
from services.synthetic.scan import Stretch, stretch_keypoints
from services.synthetic.scene import fragment_truth
from services.types import FloatArray

__all__ = [
    "CAMERAS",
    "KINECT",
    "FrameScene",
    "FrameSpec",
    "SyntheticFrame",
    "camera_pose",
    "frame_ground_truth_json",
    "generate_frame_scene",
    "render_frame",
    "scene_mesh",
]

_MATERIALS = np.array(
    [
        [200, 190, 170],  # walls
        [150, 110, 80],  # floor
        [230, 230, 225],  # ceiling
        [120, 140, 160],  # outside
        [90, 120, 70],  # furniture
    ],
    dtype=np.float64,
)
KINECT = IntrinsicsModel(width=640, height=480, fx=525.0, fy=525.0, cx=319.5, cy=239.5)
"""A Kinect-like depth camera (TUM RGB-D's default intrinsics): 63 degrees across."""
CAMERAS = {
    "kinect": KINECT,
    # A RealSense D435-like depth stream at 640x480: 79 degrees across.
    "realsense": IntrinsicsModel(width=640, height=480, fx=385.0, fy=385.0, cx=319.5, cy=239.5),
    # A wide-angle depth camera (Azure Kinect's wide field of view): 119 degrees across.
    "wide": IntrinsicsModel(width=640, height=480, fx=190.0, fy=190.0, cx=319.5, cy=239.5),
}
"""Depth cameras the frame generator renders with, by name."""

_WALL, _FLOOR, _CEILING, _OUTSIDE, _FURNITURE = range(5)
_RAY_STEP = math.radians(0.25)  # floor-plan rays of a view: a few cm apart at 7 m
_BOX_FACES = np.array(
    [
        [0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
        [2, 3, 7], [2, 7, 6], [1, 2, 6], [1, 6, 5], [0, 4, 7], [0, 7, 3],
    ],
    dtype=np.uint32,
)  # fmt: skip


@dataclass(frozen=True)
class FrameSpec:
    """Parameters of the frame generator; ranges are (low, high), sampled uniformly.

    size_range: ((min_x, min_y), (max_x, max_y)) of the room's bounding box, m.
    intrinsics: the depth camera (Kinect-like by default: 640x480, f = 525 px).
    camera_height, pitch_deg (negative: looking down), roll_deg: the camera's stance.
    n_stations: stations the frames are taken from; gap_range: unseen wall between one
    frame's stretch and the next along the loop, m (negative: overlap).
    max_range: readings farther than this are lost, m (the stations keep every wall of a
    frame within it). min_distance: least distance from a station to any wall, and from the
    camera to the walls it views, m. noise: Kinect-like depth noise and dropouts.
    min_incidence_deg, min_visible: what a frame sees of a wall (its true chain): parts
    reached first by its rays, at this angle or more from the surface, in runs of at least
    this length, m (:func:`_visible_stretch`).
    """

    n_corners_range: tuple[int, int] = (4, 8)
    size_range: tuple[tuple[float, float], tuple[float, float]] = ((3.0, 3.5), (7.0, 8.0))
    shape_family: Literal["carved", "mixed"] = "mixed"
    height_range: tuple[float, float] = (2.4, 3.0)
    intrinsics: IntrinsicsModel = field(default_factory=lambda: KINECT)
    camera_height: tuple[float, float] = (1.1, 1.6)
    pitch_deg: tuple[float, float] = (-20.0, -5.0)
    roll_deg: float = 3.0
    n_stations: tuple[int, int] = (1, 3)
    gap_range: tuple[float, float] = (-0.3, 0.2)
    max_range: float = 7.0
    min_distance: float = 1.2
    noise: bool = True
    dropout: float = 0.01
    min_incidence_deg: float = 10.0
    min_visible: float = 0.3
    furniture: bool = True
    clutter: float = 1.0
    openings: bool = True
    min_edge: float = 0.8


@dataclass(frozen=True)
class SyntheticFrame:
    """One rendered frame with its ground truth.

    frame: depth (meters, 0 = no reading), intrinsics, colour.
    pose: (4, 4) optical frame -> world.
    keypoints_world: (K, 2) world, the stretch of room boundary the frame sees, CCW.
    keypoints_local: (K, 3) the same at floor height, optical frame.
    diagonal: XY bounding-box diagonal of the noise-free hits, world, m.
    centroid_local: (3,) centroid of the noise-free hits, optical frame.
    loop_start, loop_end: arc positions of the stretch's ends on the CCW loop.
    """

    id: str
    frame: RgbdFrame
    pose: FloatArray
    keypoints_world: FloatArray
    keypoints_local: FloatArray
    diagonal: float
    centroid_local: FloatArray
    loop_start: float
    loop_end: float
    loop_index: int
    station: int


@dataclass(frozen=True)
class FrameScene:
    """A room and its frames (sorted by id; ids do not follow the loop)."""

    seed: int
    polygon: FloatArray
    ceiling_z: float
    frames: tuple[SyntheticFrame, ...]
    stations: FloatArray
    furnishing: Furnishing
    diagonal: float

    @property
    def perimeter(self) -> float:
        """Length of the room loop, m."""
        return float(
            np.sum(np.linalg.norm(np.roll(self.polygon, -1, axis=0) - self.polygon, axis=1))
        )


# --------------------------------------------------------------------------------------------
# The mesh
# --------------------------------------------------------------------------------------------


def _box(lo: FloatArray, hi: FloatArray) -> FloatArray:
    """(8, 3) corners of an axis-aligned box (bottom face, then top face)."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    return np.array(
        [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
         [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]]
    )  # fmt: skip


def _wall_boxes(room: Room, furnishing: Furnishing) -> list[tuple[FloatArray, FloatArray]]:
    """Wall slabs (outside the room, ``wall_thickness`` thick) minus the openings."""
    thick = furnishing.wall_thickness
    out = []
    n = room.n_edges
    for e in range(n):
        d, normal, length = room.dirs[e], room.normals[e], float(room.lengths[e])
        before, after = room.dirs[e - 1], room.dirs[(e + 1) % n]
        convex_before = cross(before, d) > 0
        convex_after = cross(d, after) > 0
        t_lo = -thick if convex_before else 0.0
        t_hi = length + thick if convex_after else length
        holes = [o for o in furnishing.openings if o.edge == e]
        cuts = sorted({t_lo, t_hi, *(o.t0 for o in holes), *(o.t1 for o in holes)})
        for a, b in itertools.pairwise(cuts):
            middle = 0.5 * (a + b)
            spans = [(o.z0, o.z1) for o in holes if o.t0 <= middle <= o.t1]
            z_levels = [0.0]
            for z0, z1 in sorted(spans):
                z_levels += [z0, z1]
            z_levels.append(room.height + 0.05)
            for z_lo, z_hi in zip(z_levels[0::2], z_levels[1::2], strict=True):
                if z_hi - z_lo < 1e-3:
                    continue
                p = room.polygon[e] + np.outer([a, b], d)
                q = p - thick * normal
                xy = np.vstack([p, q])
                out.append((np.append(xy.min(axis=0), z_lo), np.append(xy.max(axis=0), z_hi)))
    return out


def scene_mesh(
    room: Room, furnishing: Furnishing, margin: float = 4.0
) -> tuple[NDArray[np.float32], NDArray[np.uint32], NDArray[np.int64]]:
    """The room as one triangle mesh.

    Returns
    -------
    vertices : (V, 3) float32, world.
    triangles : (T, 3) uint32.
    material : (T,) int64, 0 wall, 1 floor, 2 ceiling, 3 outside, 4 furniture.
    """
    lo, hi = room.polygon.min(axis=0) - margin, room.polygon.max(axis=0) + margin
    top = room.height
    boxes: list[tuple[FloatArray, FloatArray, int]] = [
        (a, b, _WALL) for a, b in _wall_boxes(room, furnishing)
    ]
    boxes.append((np.append(lo, -0.1), np.append(hi, 0.0), _FLOOR))
    boxes.append((np.append(lo, top), np.append(hi, top + 0.1), _CEILING))
    for axis in (0, 1):  # the enclosure: what is seen through doors and windows
        for side, value in ((0, lo[axis]), (1, hi[axis])):
            a, b = np.append(lo, 0.0), np.append(hi, top)
            if side == 0:
                b[axis] = value + 0.1
            else:
                a[axis] = value - 0.1
            boxes.append((a, b, _OUTSIDE))
    boxes += [(box.lo, box.hi, _FURNITURE) for box in furnishing.boxes]
    vertices = np.vstack([_box(a, b) for a, b, _ in boxes]).astype(np.float32)
    triangles = (_BOX_FACES[None] + 8 * np.arange(len(boxes))[:, None, None]).reshape(-1, 3)
    material = np.repeat([kind for _, _, kind in boxes], len(_BOX_FACES)).astype(np.int64)
    return vertices, triangles.astype(np.uint32), material


# --------------------------------------------------------------------------------------------
# Rendering
# --------------------------------------------------------------------------------------------


def _tensor(array: NDArray[Any]) -> o3d.core.Tensor:
    """An Open3D tensor sharing the array's data type."""
    return o3d.core.Tensor.from_numpy(np.ascontiguousarray(array))


def _texture(points: FloatArray) -> FloatArray:
    """Blocky value noise in [0, 1] at two scales: corners for ORB, the same from any view."""
    value = np.zeros(len(points))
    for scale, weight, salt in ((0.11, 0.6, 1), (0.37, 0.4, 7)):
        cell = np.floor((points + 0.0137 * salt) / scale).astype(np.int64)
        key = (cell[:, 0] * 73856093) ^ (cell[:, 1] * 19349663) ^ (cell[:, 2] * 83492791)
        key = (key ^ (key >> 13)) * 1274126177 + salt
        value += weight * ((key >> 7) & 1023) / 1023.0
    return value


@dataclass(frozen=True)
class _Render:
    depth: NDArray[np.float32]  # (H, W) noise-free, 0 = miss
    points: FloatArray  # (N, 3) world hits of the valid pixels
    color: NDArray[np.uint8]


def _rays(pose: FloatArray, k: IntrinsicsModel) -> NDArray[np.float32]:
    """(H, W, 6) ray origins and directions (z component 1 along the optical axis)."""
    u, v = np.meshgrid(np.arange(k.width), np.arange(k.height))
    optical = np.stack([(u - k.cx) / k.fx, (v - k.cy) / k.fy, np.ones_like(u, float)], axis=-1)
    direction = optical @ pose[:3, :3].T
    origin = np.broadcast_to(pose[:3, 3], direction.shape)
    return np.concatenate([origin, direction], axis=-1).astype(np.float32)


def render_frame(
    scene: o3d.t.geometry.RaycastingScene,
    material: NDArray[np.int64],
    pose: FloatArray,
    k: IntrinsicsModel,
    max_range: float,
) -> _Render:
    """Noise-free depth (along the optical axis), world hits and colour of one view."""
    rays = _rays(pose, k)
    cast = scene.cast_rays(_tensor(rays))
    depth = cast["t_hit"].numpy()  # directions have unit z: t is the depth
    ids = cast["primitive_ids"].numpy().astype(np.int64)
    normals = cast["primitive_normals"].numpy()
    hit = np.isfinite(depth) & (depth <= max_range) & (depth >= 0.4)
    direction = rays[..., 3:] / np.linalg.norm(rays[..., 3:], axis=-1, keepdims=True)
    grazing = np.abs(np.sum(direction * normals, axis=-1)) < math.cos(math.radians(82.0))
    hit &= ~grazing
    depth = np.where(hit, depth, 0.0).astype(np.float32)
    points = rays[..., :3][hit] + depth[hit][:, None] * rays[..., 3:][hit]
    shade = 0.35 + 0.65 * _texture(points.astype(np.float64))
    rgb = np.zeros((k.height, k.width, 3))
    rgb[hit] = _MATERIALS[material[ids[hit]]] * shade[:, None]
    return _Render(depth, points.astype(np.float64), np.clip(rgb, 0, 255).astype(np.uint8))


def _kinect_noise(
    rng: np.random.Generator, depth: NDArray[np.float32], dropout: float
) -> NDArray[np.float32]:
    """Depth with Kinect-like noise, sigma = 1.2 mm + 1.9 mm (z - 0.4 m)^2, mm-quantised,
    and random dropouts."""
    sigma = 0.0012 + 0.0019 * np.square(np.maximum(depth - 0.4, 0.0))
    noisy = depth + rng.normal(size=depth.shape) * sigma
    noisy = np.where((depth > 0) & (rng.random(depth.shape) >= dropout), noisy, 0.0)
    return (np.round(noisy * 1000.0) / 1000.0).astype(np.float32)


# --------------------------------------------------------------------------------------------
# Stations and views
# --------------------------------------------------------------------------------------------


def camera_pose(position: FloatArray, yaw: float, pitch: float, roll: float) -> FloatArray:
    """Optical -> world pose of a camera at ``position`` (3,), heading ``yaw`` (radians from
    +x), tilted by ``pitch`` (negative: down) and rolled by ``roll`` about its axis."""
    forward = np.array(
        [math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), math.sin(pitch)]
    )
    right0 = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    down0 = np.cross(forward, right0)
    c, s = math.cos(roll), math.sin(roll)
    right, down = c * right0 + s * down0, -s * right0 + c * down0
    pose = np.eye(4)
    pose[:3, :3] = np.column_stack([right, down, forward])
    pose[:3, 3] = position
    return pose


def _ray_hits(
    room: Room, origin: FloatArray, angles: FloatArray
) -> tuple[FloatArray, FloatArray, NDArray[np.intp]]:
    """First hit of 2D rays with the room boundary: distance (R,), arc position (R,) and the
    edge hit (R,)."""
    direction = np.column_stack([np.cos(angles), np.sin(angles)])
    a, d = room.polygon, room.dirs * room.lengths[:, None]  # edges a + s d, s in [0, 1]
    w = a - origin  # (E, 2)
    denom = direction[:, None, 0] * d[None, :, 1] - direction[:, None, 1] * d[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[None, :, 0] * d[None, :, 1] - w[None, :, 1] * d[None, :, 0]) / denom
        s = (w[None, :, 0] * direction[:, None, 1] - w[None, :, 1] * direction[:, None, 0]) / denom
    ok = (np.abs(denom) > 1e-12) & (t > 1e-9) & (s >= 0.0) & (s <= 1.0)
    t = np.where(ok, t, np.inf)
    edge = np.argmin(t, axis=1)
    rows = np.arange(len(angles))
    distance = t[rows, edge]
    arc = room.arcs[edge] + s[rows, edge] * room.lengths[edge]
    return distance, np.mod(arc, room.perimeter), edge


def _visible_stretch(
    room: Room, edge: NDArray[np.intp], arc: FloatArray, angles: FloatArray, spec: FrameSpec
) -> tuple[float, float] | None:
    """(start, length) of the loop a camera sees, from its rays' first hits (right to left
    across the field of view); None when it sees no wall well enough, or walls that do not
    make one chain.

    A wall part counts when a ray reaches it first (parts hidden behind a protruding corner
    do not) at ``min_incidence_deg`` or more from its surface, and the run of such rays on
    that wall spans ``min_visible`` or more: a wall seen edge-on, or a sliver of it, gives too
    few points to be located. The stretch runs from the first such part to the last. Hidden
    parts between two seen ones stay in it when the walls there follow from what is seen: the
    same wall, or the next one (the corner is where their lines meet), or one wall further
    on when a seen part reaches the hidden wall's corner (a protruding corner's far side). A
    view with a gap of any other kind sees two chains, not one (None).
    """
    across = np.abs(np.cos(angles) * room.normals[edge, 0] + np.sin(angles) * room.normals[edge, 1])
    key = np.where(across >= math.sin(math.radians(spec.min_incidence_deg)), edge, -1)
    cuts = np.flatnonzero(np.diff(key)) + 1
    first, last = np.append(0, cuts), np.append(cuts, len(key)) - 1  # runs of one key
    span = np.mod(arc[last] - arc[first], room.perimeter)
    kept = (key[first] >= 0) & (span >= spec.min_visible) & (span < 0.5 * room.perimeter)
    first, last = first[kept], last[kept]
    if not len(first):
        return None
    n = room.n_edges
    wall = edge[first]
    # A neighbouring ray on the adjacent wall: the run reaches the corner between them.
    before = np.append(-1, edge)[first] == (wall - 1) % n
    after = np.append(edge, -1)[last + 1] == (wall + 1) % n
    start = np.where(before, room.arcs[wall], arc[first])
    end = np.mod(np.where(after, room.arcs[wall + 1], arc[last]), room.perimeter)
    reaches_end = _on_vertex(room, end, wall + 1)[:-1] | _on_vertex(room, start, wall)[1:]
    step = np.mod(np.diff(wall), n)
    if np.any((step > 2) | ((step == 2) & ~reaches_end)):
        return None
    return float(start[0]), float(np.mod(end[-1] - start[0], room.perimeter))


def _on_vertex(room: Room, arc: FloatArray, vertex: NDArray[np.intp]) -> NDArray[np.bool_]:
    """(M,) whether loop positions lie within 0.1 m of the given vertices (a ray step)."""
    gap = np.mod(arc - room.arcs[vertex % room.n_edges] + 0.5 * room.perimeter, room.perimeter)
    return np.abs(gap - 0.5 * room.perimeter) < 0.1


@dataclass(frozen=True)
class _View:
    station: int
    yaw: float
    start: float  # arc of the right end of the stretch the camera sees
    length: float  # CCW arc to its left end


def _view_offsets(k: IntrinsicsModel) -> FloatArray:
    """Bearings (radians, right to left, from the heading) of a view's floor-plan rays: the
    image's side edges and every ``_RAY_STEP`` between."""
    half = math.atan2(max(k.cx, k.width - 1 - k.cx), k.fx)
    return np.linspace(-half, half, 1 + int(np.ceil(2.0 * half / _RAY_STEP)))


def _view_stretch(
    room: Room, station: FloatArray, yaw: float, spec: FrameSpec
) -> tuple[float, float] | None:
    """(start, length) of the loop a camera at ``station`` (2,) heading ``yaw`` sees, or None
    when a wall in view lies out of range or too close, or it sees no one chain
    (:func:`_visible_stretch`) of a usable length."""
    angles = yaw + _view_offsets(spec.intrinsics)
    distance, arc, edge = _ray_hits(room, station, angles)
    if np.max(distance) > spec.max_range - 0.5 or np.min(distance) < spec.min_distance:
        return None
    seen = _visible_stretch(room, edge, arc, angles, spec)
    if seen is None or not 0.8 <= seen[1] <= 0.5 * room.perimeter:
        return None
    return seen


def _views(room: Room, stations: FloatArray, spec: FrameSpec) -> list[_View]:
    """Headings every 3 degrees from every station that see a stretch (:func:`_view_stretch`)."""
    views = []
    for index, station in enumerate(stations):
        for yaw in np.radians(np.arange(0.0, 360.0, 3.0)):
            seen = _view_stretch(room, station, float(yaw), spec)
            if seen is not None:
                views.append(_View(index, float(yaw), *seen))
    return views


def _signed_gap(a: float, b: float, perimeter: float) -> float:
    """Arc from a to b, wrapped into [-perimeter / 2, perimeter / 2)."""
    return float(np.mod(b - a + 0.5 * perimeter, perimeter) - 0.5 * perimeter)


def _tile_loop(
    rng: np.random.Generator, room: Room, views: list[_View], spec: FrameSpec
) -> list[_View] | None:
    """Views whose stretches follow each other round the loop, each starting within
    ``gap_range`` of the previous one's end, the last ending within it of the first's start."""
    if not views:
        return None
    lo, hi = spec.gap_range
    first = views[int(rng.integers(len(views)))]
    chosen, covered = [first], first.length
    while covered < room.perimeter + hi:
        end = chosen[-1].start + chosen[-1].length
        gaps = np.array([_signed_gap(end, v.start, room.perimeter) for v in views])
        fits = (gaps >= lo) & (gaps <= hi)
        remaining = room.perimeter - covered
        closing = [
            v for v, g, ok in zip(views, gaps, fits, strict=True)
            if ok and lo <= remaining - g - v.length <= hi
        ]  # fmt: skip
        if closing:
            chosen.append(closing[int(rng.integers(len(closing)))])
            return chosen
        advance = [
            (g + v.length, v) for v, g, ok in zip(views, gaps, fits, strict=True)
            if ok and covered + g + v.length < room.perimeter - (hi + 0.3)
        ]  # fmt: skip
        if not advance or len(chosen) > 24:
            return None
        advance.sort(key=lambda pair: -pair[0])
        _, pick = advance[int(rng.integers(min(3, len(advance))))]
        covered += _signed_gap(end, pick.start, room.perimeter) + pick.length
        chosen.append(pick)
    return None


def _stations(
    rng: np.random.Generator, room: Room, boxes: tuple[Box, ...], count: int, clearance: float
) -> FloatArray:
    """Station positions (x, y) at least ``clearance`` from walls, 0.4 m from furniture."""
    lo, hi = room.polygon.min(axis=0), room.polygon.max(axis=0)
    found: list[FloatArray] = []
    for _ in range(400):
        p = rng.uniform(lo, hi)
        inside = points_in_polygon(p[None], room.polygon)[0]
        if not inside or nearest_boundary(p[None], room)[0][0] < clearance:
            continue
        if any(np.all(p > b.lo[:2] - 0.4) and np.all(p < b.hi[:2] + 0.4) for b in boxes):
            continue
        found.append(p)
        if len(found) == count:
            break
    return np.array(found).reshape(-1, 2)


# --------------------------------------------------------------------------------------------
# The scene
# --------------------------------------------------------------------------------------------


def _room(rng: np.random.Generator, spec: FrameSpec, outline: FloatArray | None) -> Room:
    height = round(float(rng.uniform(*spec.height_range)), 2)
    if outline is not None:
        polygon = np.asarray(outline, dtype=np.float64)
        polygon = np.roll(polygon - polygon.min(axis=0), -int(rng.integers(len(polygon))), 0)
        return Room.from_polygon(polygon, height)
    (x_lo, y_lo), (x_hi, y_hi) = spec.size_range
    size = (float(rng.uniform(x_lo, x_hi)), float(rng.uniform(y_lo, y_hi)))
    size = size[::-1] if rng.random() < 0.5 else size
    family = pick_family(rng, spec.n_corners_range) if spec.shape_family == "mixed" else "carved"
    polygon = random_room(rng, family, size, spec.n_corners_range, spec.min_edge)
    return Room.from_polygon(polygon, height)


def generate_frame_scene(
    spec: FrameSpec, seed: int, outline: FloatArray | None = None
) -> FrameScene:
    """Render a scene's frames; the same (spec, seed, outline) gives identical arrays.

    Parameters
    ----------
    spec : what to generate.
    seed : seed of the one random generator everything is drawn from.
    outline : (V, 2) a room shape (simple, CCW, rectilinear) instead of a random one.

    Raises
    ------
    RuntimeError
        No stations and headings tile the room's loop within 40 tries (a room too large for
        ``max_range``, or too cluttered).
    """
    rng = np.random.default_rng(seed)
    for _ in range(40):
        room = _room(rng, spec, outline)
        furnishing = furnish_room(
            rng,
            room,
            [],
            clutter=spec.clutter,
            furniture=spec.furniture,
            openings=spec.openings,
            clearance=0.0,
        )
        count = int(rng.integers(spec.n_stations[0], spec.n_stations[1] + 1))
        stations = _stations(rng, room, furnishing.boxes, count, spec.min_distance)
        tiling = _tile_loop(rng, room, _views(room, stations, spec), spec)
        if tiling is not None:
            return _render_scene(rng, spec, seed, room, furnishing, stations, tiling)
    raise RuntimeError("no stations whose frames tile the room's loop")


def _render_scene(
    rng: np.random.Generator,
    spec: FrameSpec,
    seed: int,
    room: Room,
    furnishing: Furnishing,
    stations: FloatArray,
    tiling: list[_View],
) -> FrameScene:
    vertices, triangles, material = scene_mesh(room, furnishing)
    raycaster = o3d.t.geometry.RaycastingScene()
    raycaster.add_triangles(_tensor(vertices), _tensor(triangles))
    ids = rng.permutation(len(tiling))
    order = np.argsort([view.start for view in tiling])
    loop_index = np.empty(len(tiling), dtype=np.int64)
    loop_index[order] = np.arange(len(tiling))
    frames = []
    for k, view in enumerate(tiling):
        height = float(rng.uniform(*spec.camera_height))
        pitch = math.radians(float(rng.uniform(*spec.pitch_deg)))
        roll = math.radians(float(rng.uniform(-spec.roll_deg, spec.roll_deg)))
        position = np.append(stations[view.station], height)
        pose = camera_pose(position, view.yaw, pitch, roll)
        render = render_frame(raycaster, material, pose, spec.intrinsics, spec.max_range)
        depth = _kinect_noise(rng, render.depth, spec.dropout) if spec.noise else render.depth
        keypoints = stretch_keypoints(room, Stretch(view.start, view.length))
        on_floor = np.column_stack([keypoints, np.zeros(len(keypoints))])
        rotation, shift = pose[:3, :3], pose[:3, 3]
        lo, hi = render.points.min(axis=0), render.points.max(axis=0)
        frames.append(
            SyntheticFrame(
                id=f"frame_{ids[k]:02d}",
                frame=RgbdFrame(depth, spec.intrinsics, render.color),
                pose=pose,
                keypoints_world=keypoints,
                keypoints_local=(on_floor - shift) @ rotation,
                diagonal=float(np.linalg.norm(hi[:2] - lo[:2])),
                centroid_local=(render.points.mean(axis=0) - shift) @ rotation,
                loop_start=view.start,
                loop_end=float(np.mod(view.start + view.length, room.perimeter)),
                loop_index=int(loop_index[k]),
                station=view.station,
            )
        )
    lo, hi = room.polygon.min(axis=0), room.polygon.max(axis=0)
    return FrameScene(
        seed=seed,
        polygon=room.polygon,
        ceiling_z=room.height,
        frames=tuple(sorted(frames, key=lambda f: f.id)),
        stations=stations,
        furnishing=furnishing,
        diagonal=float(np.linalg.norm(hi - lo)),
    )


def frame_ground_truth_json(scene: FrameScene) -> dict[str, Any]:
    """The scene's ground truth in the shape :func:`services.evaluation.evaluate_result`
    reads (as :func:`services.synthetic.ground_truth_json` writes it for clouds)."""
    return {
        "schema_version": 1,
        "seed": scene.seed,
        "room": {"polygon": scene.polygon.tolist(), "floor_z": 0.0, "ceiling_z": scene.ceiling_z},
        "diagonal": scene.diagonal,
        "perimeter": scene.perimeter,
        "fragments": [
            {
                **fragment_truth(f),
                "station": f.station,
                "single_wall": len(f.keypoints_world) == 2,
            }
            for f in scene.frames
        ],
    }
