"""Synthetic scenes with ground truth: one rectilinear room scanned in partial fragments.

World frame: right-handed, z up, floor at z = 0, meters; the room polygon is counter-clockwise
seen from above. The room (random, of a shape family, or a given outline) loop is
cut into contiguous stretches (neighbours overlap or leave a gap of a few decimeters; see
:mod:`services.synthetic.cuts`); each fragment sees its stretch of wall plus the floor,
ceiling and furniture in front of it (see :mod:`services.synthetic.scan`), with noise,
outliers and uneven density, in its own tilted, rotated and shifted local frame.

Pure: returns arrays, writes no files (the CLI writes PLYs).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass, field
from typing import Any, Literal, Protocol

import numpy as np

from services.geometry import signed_area
from services.synthetic.cuts import (
    Cut,
    arc_cuts,
    cut_turns,
    edge_cuts,
    furniture_clearance,
    stretches,
)
from services.synthetic.families import pick_family, random_room
from services.synthetic.furniture import Furnishing, furnish_room, transient_boxes
from services.synthetic.room import Room
from services.synthetic.scan import ScanStyle, Stretch, sample_scan, stretch_keypoints
from services.synthetic.shapes import is_simple_rectilinear
from services.types import FloatArray

__all__ = [
    "Junction",
    "SceneSpec",
    "SyntheticFragment",
    "SyntheticScene",
    "fragment_truth",
    "generate_scene",
    "ground_truth_json",
]

_Range = tuple[float, float]


@dataclass(frozen=True)
class SceneSpec:
    """Parameters of the scene generator; ranges are (low, high), sampled uniformly.

    size_range: ((min_x, min_y), (max_x, max_y)) of the room bounding box (axes then swapped
    at random). ceiling_fraction: ceiling reach as a fraction of the fragment's floor reach.
    end_margin: plain wall (no opening, no furniture) at both ends of every stretch.
    straight_fragments: allow fragments that see one straight wall only (else every stretch
    spans at least one corner). corner_cut_share: share of cuts moved onto a room corner,
    which then lies in the unseen gap between the two neighbours (their junction turns).
    density_falloff, scanner_spacing, patch_gain_range, oversample: see
    :class:`services.synthetic.scan.ScanStyle`.

    cut_model: "edges" (at most one cut per edge, two on a long edge) or "arc" (cuts anywhere
    on the loop, several per edge, single-wall fragments whatever ``straight_fragments``; see
    :mod:`services.synthetic.cuts`). min_stretch: "arc" only, least visible wall per
    fragment, m. With "arc" and ``end_margin == 0`` doors, windows and furniture may cross
    cuts. shape_family: "carved" (random grid carving) or "mixed" (one family per scene among
    carved, long thin, L, T, U, comb and notched; :mod:`services.synthetic.families`).
    reach_beyond: per-fragment extra floor, ceiling and furniture seen past both ends of
    the stretch along the loop, m (neighbours then share floor and furniture even across a
    gap). far_walls: with ``see_through``, the share of doors through which a scan also
    sees the next room's wall facing the door (1-3 m behind it, wider than the door).
    transient_clutter: per-fragment objects seen by that scan only (people, carts,
    boxes), per 4 m of stretch. max_scene_points: when > 0, point counts are scaled down so
    that n fragments times the largest count stays within it.
    """

    n_corners_range: tuple[int, int] = (4, 16)
    size_range: tuple[_Range, _Range] = ((2.0, 6.0), (18.0, 20.0))
    height_range: _Range = (2.4, 3.2)
    n_fragments_range: tuple[int, int] = (2, 8)
    noise_range: _Range = (0.01, 0.02)
    outlier_fraction: float = 0.01
    max_tilt_deg: float = 3.0
    max_translation: float = 10.0
    points_per_fragment: tuple[int, int] = (40_000, 120_000)
    furniture: bool = True
    clutter: float = 1.0
    openings: bool = True
    see_through: bool = False
    far_walls: float = 0.0
    ceiling_fraction: _Range = (0.0, 0.6)
    no_ceiling_share: float = 0.0
    floor_reach_range: _Range = (2.0, 4.0)
    gap_range: _Range = (-0.3, 0.3)
    min_edge: float = 0.8
    end_margin: float = 0.5
    straight_fragments: bool = False
    corner_cut_share: float = 0.0
    density_falloff: float = 1.0
    scanner_spacing: float = 6.0
    patch_gain_range: _Range = (1.0, 3.0)
    oversample: float = 2.5
    cut_model: Literal["edges", "arc"] = "edges"
    min_stretch: float = 1.0
    shape_family: Literal["carved", "mixed"] = "carved"
    reach_beyond: _Range = (0.0, 0.0)
    transient_clutter: _Range = (0.0, 0.0)
    max_scene_points: int = 0

    def __post_init__(self) -> None:
        ranges: tuple[tuple[float, float], ...] = (
            self.n_corners_range,
            self.height_range,
            self.n_fragments_range,
        )
        ranges += (self.noise_range, self.points_per_fragment, self.ceiling_fraction)
        ranges += (self.floor_reach_range, self.gap_range, self.patch_gain_range)
        ranges += tuple(zip(*self.size_range, strict=True))
        if any(lo > hi for lo, hi in ranges):
            raise ValueError("every range must be (low, high) with low <= high")
        if self.n_corners_range[1] < 4 or self.n_fragments_range[0] < 1:
            raise ValueError("rooms need >= 4 corners and scenes >= 1 fragment")
        self._check_options()

    def _check_options(self) -> None:
        """Checks of the cut, shape and scanner options."""
        if self.cut_model not in ("edges", "arc") or self.shape_family not in ("carved", "mixed"):
            raise ValueError("cut_model is 'edges' or 'arc'; shape_family 'carved' or 'mixed'")
        ranges = (self.reach_beyond, self.transient_clutter)
        if any(lo > hi or lo < 0.0 for lo, hi in ranges) or self.max_scene_points < 0:
            raise ValueError("reach_beyond and transient_clutter are (low, high) >= 0")
        if not 0.0 <= self.far_walls <= 1.0:
            raise ValueError("far_walls is a share of the doors, in [0, 1]")
        if not 0.0 <= self.no_ceiling_share <= 1.0:
            raise ValueError("no_ceiling_share is a share of the scans, in [0, 1]")
        if self.min_stretch <= 0.0 or -self.gap_range[0] >= self.min_stretch:
            raise ValueError("min_stretch must be > 0 and longer than the largest overlap")

    @classmethod
    def easy(cls) -> SceneSpec:
        """Small rooms, few fragments, little noise and clutter."""
        return cls(
            n_corners_range=(4, 8),
            size_range=((3.0, 4.0), (10.0, 12.0)),
            n_fragments_range=(2, 4),
            noise_range=(0.005, 0.01),
            outlier_fraction=0.002,
            max_tilt_deg=1.0,
            points_per_fragment=(30_000, 60_000),
            clutter=0.5,
            density_falloff=0.5,
            patch_gain_range=(1.0, 1.5),
        )

    @classmethod
    def paper(cls) -> SceneSpec:
        """The paper's dataset range: 2 x 6 m to 18 x 20 m, 4 to 16 corners."""
        return cls()

    @classmethod
    def hard(cls) -> SceneSpec:
        """More clutter, noise, outliers, tilt and fragments; strongly uneven density."""
        return cls(
            n_corners_range=(6, 16),
            n_fragments_range=(4, 10),
            noise_range=(0.02, 0.025),
            outlier_fraction=0.05,
            max_tilt_deg=5.0,
            clutter=2.0,
            see_through=True,
            ceiling_fraction=(0.3, 1.0),
            straight_fragments=True,
            density_falloff=2.0,
            scanner_spacing=15.0,
            patch_gain_range=(3.0, 8.0),
            oversample=4.0,
        )

    @classmethod
    def stress(cls) -> SceneSpec:
        """Large rooms (up to 30 x 40 m) and over a million points per fragment."""
        return cls(
            n_corners_range=(8, 16),
            size_range=((18.0, 20.0), (30.0, 40.0)),
            n_fragments_range=(6, 8),
            points_per_fragment=(1_000_000, 1_200_000),
            oversample=2.0,
        )

    @classmethod
    def world(cls) -> SceneSpec:
        """As hard as scenes made outside the project: cuts anywhere (straight junctions,
        single-wall fragments, a few on corners), overlaps up to 0.5 m and gaps up to 0.3 m,
        openings and furniture across cuts, real-looking room shapes of real rooms' sizes
        (3 to 10 by 3 to 13 m; the MatterportLayout outlines' median perimeter is 21 m, so
        many fragments see a single wall), 2 to 16 fragments (benchmarks set
        ``n_fragments_range`` per bucket) from scanners that differ in noise, density,
        reach and clutter. A scan sees from nothing to 1 m of floor and furniture past its
        stretch's ends, so neighbours may share no more than the wall they overlap on
        (scenes made elsewhere share 0.2 m, median), and its floor 1 to 4 m deep; 30 % of
        the scans see no ceiling; through half the doors a scan sees the next room's far
        wall. Point counts shrink for many fragments (at most 1.2 M points per scene)."""
        return cls(
            size_range=((3.0, 3.0), (10.0, 13.0)),
            n_fragments_range=(2, 16),
            noise_range=(0.005, 0.03),
            outlier_fraction=0.02,
            max_tilt_deg=4.0,
            points_per_fragment=(30_000, 120_000),
            clutter=1.5,
            see_through=True,
            ceiling_fraction=(0.0, 1.0),
            no_ceiling_share=0.3,
            floor_reach_range=(1.0, 4.0),
            gap_range=(-0.5, 0.3),
            min_edge=0.5,
            end_margin=0.0,
            straight_fragments=True,
            corner_cut_share=0.15,
            density_falloff=1.5,
            scanner_spacing=8.0,
            patch_gain_range=(1.0, 5.0),
            cut_model="arc",
            min_stretch=1.0,
            shape_family="mixed",
            reach_beyond=(0.0, 1.0),
            far_walls=0.5,
            transient_clutter=(0.0, 1.0),
            max_scene_points=1_200_000,
        )


@dataclass(frozen=True)
class SyntheticFragment:
    """One partial scan with its ground truth.

    points: (N, 3) float64, fragment-local frame, meters (noise and outliers included).
    pose: (4, 4) float64, local -> world: p_world = pose @ [p_local, 1].
    keypoints_world: (K, 2) float64 world: start of the visible wall stretch, the corners
    inside it, its end; counter-clockwise order (room interior on the left).
    keypoints_local: (K, 3) float64, the same points at floor height (z_world = 0), local frame.
    diagonal: XY bounding-box diagonal of the noise-free, outlier-free points, world, m.
    loop_start, loop_end: arc positions in [0, perimeter) along the CCW room loop (from
    polygon vertex 0) of the stretch's ends; the stretch wraps past 0 when end < start.
    loop_index: position in the loop (fragments sorted by loop_start).
    centroid_local: (3,) float64 centroid of the noise-free points, local frame.
    """

    id: str
    points: FloatArray
    pose: FloatArray
    keypoints_world: FloatArray
    keypoints_local: FloatArray
    diagonal: float
    loop_start: float
    loop_end: float
    loop_index: int
    centroid_local: FloatArray

    @property
    def single_wall(self) -> bool:
        """True when the stretch holds no room corner (the scan sees one straight wall)."""
        return len(self.keypoints_world) == 2


@dataclass(frozen=True)
class Junction:
    """Where a fragment's stretch meets the next one along the CCW loop.

    gap: unseen wall between the two stretch ends along the loop, m; negative when they
    overlap (both see that much wall). turn: signed quarter turns of the room corners inside
    the junction (unseen, or seen by both): 0 for a straight junction, +1 for a convex
    corner, -1 for a reflex one.
    """

    from_id: str
    to_id: str
    gap: float
    turn: int


@dataclass(frozen=True)
class SyntheticScene:
    """A generated scene.

    polygon: (V, 2) float64 world, counter-clockwise, first vertex not repeated.
    fragments: sorted by id; ids do not follow the loop order.
    diagonal: room bounding-box diagonal, m.
    junctions: one per fragment in loop order (loop_index 0, 1, ...), to the next fragment.
    furnishing: the room's doors, windows and furniture, world frame (not the objects seen
    by one scan only).
    """

    seed: int
    polygon: FloatArray
    floor_z: float
    ceiling_z: float
    fragments: tuple[SyntheticFragment, ...]
    diagonal: float
    spec: SceneSpec
    junctions: tuple[Junction, ...] = ()
    furnishing: Furnishing = field(default_factory=Furnishing)

    @property
    def perimeter(self) -> float:
        """Length of the room loop, m."""
        return float(
            np.sum(np.linalg.norm(np.roll(self.polygon, -1, axis=0) - self.polygon, axis=1))
        )


def generate_scene(spec: SceneSpec, seed: int, outline: FloatArray | None = None) -> SyntheticScene:
    """Generate a scene; the same (spec, seed, outline) gives identical arrays.

    Parameters
    ----------
    spec : SceneSpec
        What to generate.
    seed : int
        Seed of the one random generator everything is drawn from.
    outline : (V, 2) float64, optional
        A room shape to use instead of a random one: simple, counter-clockwise, axis-aligned
        edges, meters (e.g. from :func:`services.synthetic.shapes.clean_outline`). It is
        shifted so its bounding-box minimum is at the origin and starts at a random vertex;
        ``n_corners_range``, ``size_range`` and ``shape_family`` are then unused, and with the
        "arc" cut model a room too short for the drawn fragment count gets as many as fit.

    Returns
    -------
    SyntheticScene
        World frame, z up, floor at z = 0, meters.

    >>> scene = generate_scene(SceneSpec(points_per_fragment=(500, 500), furniture=False), 1)
    >>> len(scene.fragments) >= 2 and all(len(f.points) == 500 for f in scene.fragments)
    True
    """
    if outline is not None and not _usable_outline(outline):
        raise ValueError("outline must be a simple CCW rectilinear (V, 2) polygon, V >= 4")
    rng = np.random.default_rng(seed)
    height = round(float(rng.uniform(*spec.height_range)), 2)
    room, cuts = _room_and_cuts(rng, spec, height, outline)
    keep_clear, clearance = furniture_clearance(spec, cuts)
    furnishing = furnish_room(
        rng,
        room,
        keep_clear,
        clutter=spec.clutter,
        furniture=spec.furniture,
        openings=spec.openings,
        clearance=clearance,
    )
    ids = rng.permutation(len(cuts))
    names = [f"frag_{ids[k]:02d}" for k in range(len(cuts))]
    points_range = _points_range(spec, len(cuts))
    fragments = [
        _fragment(rng, spec, room, furnishing, stretch, k, names[k], points_range)
        for k, stretch in enumerate(stretches(room, cuts))
    ]
    lo, hi = room.polygon.min(axis=0), room.polygon.max(axis=0)
    return SyntheticScene(
        seed=seed,
        polygon=room.polygon,
        floor_z=0.0,
        ceiling_z=height,
        fragments=tuple(sorted(fragments, key=lambda f: f.id)),
        diagonal=float(np.linalg.norm(hi - lo)),
        spec=spec,
        junctions=_junctions(room, cuts, names),
        furnishing=furnishing,
    )


class _PlacedScan(Protocol):
    """What the truth of one scan (cloud or RGB-D frame) is read from (frozen records)."""

    @property
    def id(self) -> str: ...
    @property
    def pose(self) -> FloatArray: ...
    @property
    def keypoints_local(self) -> FloatArray: ...
    @property
    def keypoints_world(self) -> FloatArray: ...
    @property
    def diagonal(self) -> float: ...
    @property
    def loop_start(self) -> float: ...
    @property
    def loop_end(self) -> float: ...
    @property
    def loop_index(self) -> int: ...
    @property
    def centroid_local(self) -> FloatArray: ...


def fragment_truth(fragment: _PlacedScan) -> dict[str, Any]:
    """One scan's truth record: pose, keypoints, diagonal, loop position, centroid."""
    return {
        "id": fragment.id,
        "pose": fragment.pose.tolist(),
        "keypoints_local": fragment.keypoints_local.tolist(),
        "keypoints_world": fragment.keypoints_world.tolist(),
        "diagonal": fragment.diagonal,
        "loop_start": fragment.loop_start,
        "loop_end": fragment.loop_end,
        "loop_index": fragment.loop_index,
        "centroid_local": fragment.centroid_local.tolist(),
    }


def ground_truth_json(scene: SyntheticScene) -> dict[str, Any]:
    """The scene's ground truth as JSON-able data (schema_version 1).

    Besides the room, the diagonal, the perimeter and the per-fragment truth (pose,
    keypoints, loop positions, ``single_wall``), ``junctions`` lists for each fragment in loop
    order ``{"from": id, "to": next id along the CCW loop, "gap": m (negative: overlap),
    "turn": 0 straight, +1 / -1 when the junction holds a convex / reflex corner}``.
    """
    return {
        "schema_version": 1,
        "seed": scene.seed,
        "room": {
            "polygon": scene.polygon.tolist(),
            "floor_z": scene.floor_z,
            "ceiling_z": scene.ceiling_z,
        },
        "diagonal": scene.diagonal,
        "perimeter": scene.perimeter,
        "fragments": [
            {**fragment_truth(f), "n_points": len(f.points), "single_wall": f.single_wall}
            for f in scene.fragments
        ],
        "junctions": [
            {"from": j.from_id, "to": j.to_id, "gap": j.gap, "turn": j.turn}
            for j in scene.junctions
        ],
        "spec": asdict(scene.spec),
    }


def _usable_outline(outline: FloatArray) -> bool:
    polygon = np.asarray(outline, dtype=np.float64)
    if polygon.ndim != 2 or polygon.shape[1:] != (2,) or len(polygon) < 4:
        return False
    return is_simple_rectilinear(polygon) and signed_area(polygon) > 0.0


def _room_and_cuts(
    rng: np.random.Generator, spec: SceneSpec, height: float, outline: FloatArray | None
) -> tuple[Room, list[Cut]]:
    """A room (random, or the outline at a random start vertex) and its cuts; up to 50 tries."""
    for _ in range(50):
        if outline is None:
            polygon = _random_polygon(rng, spec)
        else:
            polygon = np.asarray(outline, dtype=np.float64)
            polygon = np.roll(polygon - polygon.min(axis=0), -int(rng.integers(len(polygon))), 0)
        room = Room.from_polygon(polygon, height)
        if spec.cut_model == "arc":
            cuts = arc_cuts(rng, spec, room, fit=outline is not None)
        else:
            cuts = edge_cuts(rng, spec, room)
        if cuts is not None:
            return room, cuts
    raise RuntimeError("no room with room for the requested fragments")


def _random_polygon(rng: np.random.Generator, spec: SceneSpec) -> FloatArray:
    (x_lo, y_lo), (x_hi, y_hi) = spec.size_range
    size = (round(float(rng.uniform(x_lo, x_hi)), 2), round(float(rng.uniform(y_lo, y_hi)), 2))
    if rng.random() < 0.5:
        size = size[::-1]
    if spec.shape_family == "mixed":
        family = pick_family(rng, spec.n_corners_range)
        return random_room(rng, family, size, spec.n_corners_range, spec.min_edge)
    return random_room(rng, "carved", size, spec.n_corners_range, spec.min_edge)


def _junctions(room: Room, cuts: list[Cut], names: list[str]) -> tuple[Junction, ...]:
    """Junction k: from fragment k (loop order) to k + 1, across cut k + 1."""
    turns = cut_turns(room, cuts)
    n = len(cuts)
    return tuple(
        Junction(names[k], names[(k + 1) % n], cuts[(k + 1) % n].gap, turns[(k + 1) % n])
        for k in range(n)
    )


def _points_range(spec: SceneSpec, n_fragments: int) -> tuple[int, int]:
    """``points_per_fragment``, scaled down so n fragments stay within ``max_scene_points``."""
    lo, hi = spec.points_per_fragment
    if spec.max_scene_points <= 0 or n_fragments * hi <= spec.max_scene_points:
        return lo, hi
    scale = spec.max_scene_points / (n_fragments * hi)
    return max(1, int(lo * scale)), max(1, int(hi * scale))


def _fragment(
    rng: np.random.Generator,
    spec: SceneSpec,
    room: Room,
    furnishing: Furnishing,
    stretch: Stretch,
    loop_index: int,
    fragment_id: str,
    points_range: tuple[int, int],
) -> SyntheticFragment:
    style = _scan_style(rng, spec)
    n_total = int(rng.integers(points_range[0], points_range[1] + 1))
    n_outliers = round(n_total * spec.outlier_fraction)
    seen = _with_transients(rng, spec, room, furnishing, stretch, style.reach)
    true = sample_scan(rng, room, seen, stretch, style, n_total - n_outliers)
    noisy = true + rng.normal(scale=rng.uniform(*spec.noise_range), size=true.shape)
    lo, hi = true.min(axis=0), true.max(axis=0)
    world = np.vstack([noisy, rng.uniform(lo, hi, (n_outliers, 3))])
    world = world[rng.permutation(len(world))]
    pose = _random_pose(rng, spec)
    rotation, shift = pose[:3, :3], pose[:3, 3]
    keypoints = stretch_keypoints(room, stretch)
    on_floor = np.column_stack([keypoints, np.zeros(len(keypoints))])
    return SyntheticFragment(
        id=fragment_id,
        # Row-wise R^T (p - t), world -> local, snapped to 1 um: BLAS computes the product
        # in other last bits on other machines, and the same seed must give the same scan.
        points=np.round((world - shift) @ rotation, 6),
        pose=pose,
        keypoints_world=keypoints,
        keypoints_local=(on_floor - shift) @ rotation,
        diagonal=float(np.linalg.norm(hi[:2] - lo[:2])),
        loop_start=stretch.start,
        loop_end=float(np.mod(stretch.start + stretch.length, room.perimeter)),
        loop_index=loop_index,
        centroid_local=(true.mean(axis=0) - shift) @ rotation,
    )


def _scan_style(rng: np.random.Generator, spec: SceneSpec) -> ScanStyle:
    """One scanner's reach, ceiling reach, patch gain and reach beyond its stretch."""
    reach = float(rng.uniform(*spec.floor_reach_range))
    style = ScanStyle(
        reach=reach,
        ceiling_reach=reach * float(rng.uniform(*spec.ceiling_fraction)),
        falloff=spec.density_falloff,
        scanner_spacing=spec.scanner_spacing,
        patch_gain=float(rng.uniform(*spec.patch_gain_range)),
        see_through=spec.see_through,
        far_walls=spec.far_walls,
        oversample=spec.oversample,
    )
    if spec.reach_beyond[1] > 0.0:
        style = dataclasses.replace(style, beyond=float(rng.uniform(*spec.reach_beyond)))
    if spec.no_ceiling_share > 0.0 and rng.random() < spec.no_ceiling_share:
        style = dataclasses.replace(style, ceiling_reach=0.0)
    return style


def _with_transients(
    rng: np.random.Generator,
    spec: SceneSpec,
    room: Room,
    furnishing: Furnishing,
    stretch: Stretch,
    reach: float,
) -> Furnishing:
    """The furnishing plus the objects only this scan sees (``transient_clutter``)."""
    if spec.transient_clutter[1] <= 0.0:
        return furnishing
    level = float(rng.uniform(*spec.transient_clutter))
    extra = transient_boxes(
        rng, room, furnishing.boxes, stretch.start, stretch.length, level, reach
    )
    return dataclasses.replace(furnishing, boxes=furnishing.boxes + extra)


def _random_pose(rng: np.random.Generator, spec: SceneSpec) -> FloatArray:
    """Local -> world: tilt about a random horizontal axis, then a yaw 2-88 degrees off any
    multiple of 90, then a shift up to max_translation horizontally and 1.5 m vertically."""
    yaw = int(rng.integers(4)) * math.pi / 2 + rng.uniform(math.radians(2), math.radians(88))
    tilt = math.radians(rng.uniform(0.0, spec.max_tilt_deg))
    azimuth = rng.uniform(0.0, 2 * math.pi)
    axis = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
    skew = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    tilt_rotation = np.eye(3) + math.sin(tilt) * skew + (1 - math.cos(tilt)) * skew @ skew
    c, s = math.cos(yaw), math.sin(yaw)
    yaw_rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    radius = spec.max_translation * math.sqrt(rng.random())
    heading = rng.uniform(0.0, 2 * math.pi)
    pose = np.eye(4)
    pose[:3, :3] = yaw_rotation @ tilt_rotation
    pose[:3, 3] = [radius * math.cos(heading), radius * math.sin(heading), rng.uniform(-1.5, 1.5)]
    return pose
