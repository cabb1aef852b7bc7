"""Synthetic scenes with ground truth: one rectilinear room scanned in partial fragments.

World frame: right-handed, z up, floor at z = 0, meters; the room polygon is counter-clockwise
seen from above. The room loop is cut into contiguous stretches (neighbours overlap or leave
a gap of a few decimeters); each fragment sees only its stretch of wall plus the floor,
ceiling and furniture in front of it (see :mod:`services.synthetic.scan`), with noise,
outliers and uneven density, in its own tilted, rotated and shifted local frame.

Pure: returns arrays, writes no files (the CLI writes PLYs).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from services.geometry import signed_area
from services.synthetic.furniture import Furnishing, furnish_room
from services.synthetic.room import Room, random_rectilinear_polygon
from services.synthetic.scan import ScanStyle, Stretch, sample_scan, stretch_keypoints
from services.types import FloatArray

__all__ = [
    "SceneSpec",
    "SyntheticFragment",
    "SyntheticScene",
    "generate_scene",
    "ground_truth_json",
]

_Range = tuple[float, float]
_MIN_STRAIGHT = 2.5  # shortest stretch that sees a single straight wall
_CORNER_GAP = (0.1, 0.4)  # m, unseen wall around a corner where a cut falls on it


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
    ceiling_fraction: _Range = (0.0, 0.6)
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


@dataclass(frozen=True)
class SyntheticScene:
    """A generated scene.

    polygon: (V, 2) float64 world, counter-clockwise, first vertex not repeated.
    fragments: sorted by id; ids do not follow the loop order.
    diagonal: room bounding-box diagonal, m.
    """

    seed: int
    polygon: FloatArray
    floor_z: float
    ceiling_z: float
    fragments: tuple[SyntheticFragment, ...]
    diagonal: float
    spec: SceneSpec

    @property
    def perimeter(self) -> float:
        """Length of the room loop, m."""
        return float(
            np.sum(np.linalg.norm(np.roll(self.polygon, -1, axis=0) - self.polygon, axis=1))
        )


def generate_scene(spec: SceneSpec, seed: int) -> SyntheticScene:
    """Generate a scene; the same (spec, seed) gives identical arrays.

    >>> scene = generate_scene(SceneSpec(points_per_fragment=(500, 500), furniture=False), 1)
    >>> len(scene.fragments) >= 2 and all(len(f.points) == 500 for f in scene.fragments)
    True
    """
    rng = np.random.default_rng(seed)
    height = round(float(rng.uniform(*spec.height_range)), 2)
    for _ in range(50):
        room = Room.from_polygon(_random_polygon(rng, spec), height)
        cuts = _cut_positions(rng, spec, room)
        if cuts is not None:
            break
    else:
        raise RuntimeError("no room with room for the requested fragments")
    keep_clear = [(e, t) for e, t, _ in cuts]
    clear = spec.end_margin + 0.5 * max(abs(g) for g in spec.gap_range)
    furnishing = furnish_room(
        rng,
        room,
        keep_clear,
        clutter=spec.clutter,
        furniture=spec.furniture,
        openings=spec.openings,
        clearance=clear,
    )
    ids = rng.permutation(len(cuts))
    fragments = [
        _fragment(rng, spec, room, furnishing, stretch, k, f"frag_{ids[k]:02d}")
        for k, stretch in enumerate(_stretches(room, cuts))
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
    )


def ground_truth_json(scene: SyntheticScene) -> dict[str, Any]:
    """The scene's ground truth as JSON-able data (schema_version 1)."""
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
            {
                "id": f.id,
                "pose": f.pose.tolist(),
                "keypoints_local": f.keypoints_local.tolist(),
                "keypoints_world": f.keypoints_world.tolist(),
                "diagonal": f.diagonal,
                "loop_start": f.loop_start,
                "loop_end": f.loop_end,
                "loop_index": f.loop_index,
                "centroid_local": f.centroid_local.tolist(),
                "n_points": len(f.points),
            }
            for f in scene.fragments
        ],
        "spec": asdict(scene.spec),
    }


def _random_polygon(rng: np.random.Generator, spec: SceneSpec) -> FloatArray:
    (x_lo, y_lo), (x_hi, y_hi) = spec.size_range
    size = (round(float(rng.uniform(x_lo, x_hi)), 2), round(float(rng.uniform(y_lo, y_hi)), 2))
    if rng.random() < 0.5:
        size = size[::-1]
    lo, hi = spec.n_corners_range
    target = int(rng.choice(np.arange(max(4, lo + lo % 2), hi + 1, 2)))
    polygon = random_rectilinear_polygon(rng, size, target, spec.min_edge)
    assert signed_area(polygon) > 0.0
    return polygon


def _cut_positions(
    rng: np.random.Generator, spec: SceneSpec, room: Room
) -> list[tuple[int, float, float]] | None:
    """Where neighbouring stretches meet: (edge, t along it, gap) sorted along the loop.

    gap > 0 leaves that much wall unseen between the two; gap < 0 makes them overlap. Cuts
    stay ``end_margin`` (plus half the gap) from corners; distinct edges between cuts give
    every stretch at least one corner; two cuts on one long edge give a straight stretch.
    """
    margin = spec.end_margin + 0.5 * max(abs(g) for g in spec.gap_range)
    slots = [e for e in range(room.n_edges) if room.lengths[e] >= 2 * margin + 0.1]
    if spec.straight_fragments:
        slots += [e for e in slots if room.lengths[e] >= 2 * margin + _MIN_STRAIGHT + 0.01]
    n = min(int(rng.integers(spec.n_fragments_range[0], spec.n_fragments_range[1] + 1)), len(slots))
    if n < 2:
        return None
    edges = np.array(slots)[rng.choice(len(slots), n, replace=False)]
    cuts: list[tuple[int, float, float]] = []
    for e in np.unique(edges):
        length = room.lengths[e]
        if np.count_nonzero(edges == e) == 1:
            ts = [rng.uniform(margin, length - margin)]
        else:
            first = rng.uniform(margin, length - margin - _MIN_STRAIGHT)
            ts = [first, rng.uniform(first + _MIN_STRAIGHT, length - margin)]
        cuts += [(int(e), float(t), float(rng.uniform(*spec.gap_range))) for t in ts]
    cuts = sorted(cuts, key=lambda c: room.arcs[c[0]] + c[1])
    if spec.corner_cut_share > 0.0:
        cuts = _cuts_at_corners(rng, spec, room, cuts)
    return cuts


def _cuts_at_corners(
    rng: np.random.Generator, spec: SceneSpec, room: Room, cuts: list[tuple[int, float, float]]
) -> list[tuple[int, float, float]]:
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
            out.append((e, 0.0, float(rng.uniform(_CORNER_GAP[0], _CORNER_GAP[1]))))
        else:
            out.append((e, t, gap))
    return out


def _stretches(room: Room, cuts: list[tuple[int, float, float]]) -> list[Stretch]:
    """Stretch k runs from cut k to cut k + 1 (cyclic), shrunk or grown by half of each gap."""
    arcs = [room.arcs[e] + t for e, t, _ in cuts]
    out = []
    for k, (start, gap) in enumerate(zip(arcs, (g for _, _, g in cuts), strict=True)):
        nxt = (k + 1) % len(cuts)
        end = arcs[nxt] + (room.perimeter if nxt == 0 else 0.0) - 0.5 * cuts[nxt][2]
        begin = start + 0.5 * gap
        out.append(Stretch(float(np.mod(begin, room.perimeter)), float(end - begin)))
    return out


def _fragment(
    rng: np.random.Generator,
    spec: SceneSpec,
    room: Room,
    furnishing: Furnishing,
    stretch: Stretch,
    loop_index: int,
    fragment_id: str,
) -> SyntheticFragment:
    reach = float(rng.uniform(*spec.floor_reach_range))
    style = ScanStyle(
        reach=reach,
        ceiling_reach=reach * float(rng.uniform(*spec.ceiling_fraction)),
        falloff=spec.density_falloff,
        scanner_spacing=spec.scanner_spacing,
        patch_gain=float(rng.uniform(*spec.patch_gain_range)),
        see_through=spec.see_through,
        oversample=spec.oversample,
    )
    n_total = int(rng.integers(spec.points_per_fragment[0], spec.points_per_fragment[1] + 1))
    n_outliers = round(n_total * spec.outlier_fraction)
    true = sample_scan(rng, room, furnishing, stretch, style, n_total - n_outliers)
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
        points=(world - shift) @ rotation,  # row-wise R^T (p - t): world -> local
        pose=pose,
        keypoints_world=keypoints,
        keypoints_local=(on_floor - shift) @ rotation,
        diagonal=float(np.linalg.norm(hi[:2] - lo[:2])),
        loop_start=stretch.start,
        loop_end=float(np.mod(stretch.start + stretch.length, room.perimeter)),
        loop_index=loop_index,
        centroid_local=(true.mean(axis=0) - shift) @ rotation,
    )


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
