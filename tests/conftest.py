"""Shared fixtures: synthetic scenes and their local layouts (built once per session), and
chain builders."""

from __future__ import annotations

import dataclasses
from functools import cache

import numpy as np
import pytest

from schemas.params import PlacementParams
from services.pipeline import estimate_layout
from services.placement import Piece, direction_index, rot90
from services.placement.pieces import FreeSpace
from services.synthetic import SceneSpec, SyntheticScene, generate_scene
from services.types import LocalLayout
from tests.service_fixtures import (  # noqa: F401  (real Redis 7 / 6.2, uvicorn, workers)
    any_redis,
    api,
    api_factory,
    redis7_url,
    redis62_url,
    redis_client,
    redis_process,
    redis_url,
    start_workers,
)

__all__ = [
    "CEILING",
    "FURNITURE",
    "UNTUNED",
    "bare_piece",
    "chains_from_polygon",
    "end_boxes",
    "end_shell",
    "overlapping_halves",
    "point_at_arc",
    "scene_layouts",
    "small_scene",
]

# The placement energy before fitting: unit weights, the plain Boltzmann share (with a
# fixed 'none of these' energy) as the confidence, and a refinement whose junctions hide
# no overlap on average. Tests that check energies, ties, shares and positions by hand use
# these, so that refitting the defaults does not move them.
UNTUNED = PlacementParams(
    refined_junction_mean=0.0,
    weight_turn=1.0,
    weight_hull=1.0,
    weight_closure=1.0,
    weight_structure=1.0,
    weight_boundary=1.0,
    weight_conflict=1.0,
    weight_outside=1.0,
    unexplored_energy=3.0,
    unexplored_per_piece=0.0,
    confidence_coefficients=(0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0),
)


@cache
def small_scene(preset: str = "easy", seed: int = 0, points: int = 30_000) -> SyntheticScene:
    """A generated scene with fewer points per fragment, cached across tests."""
    spec = getattr(SceneSpec, preset)()
    spec = dataclasses.replace(spec, points_per_fragment=(points, points + 10_000))
    return generate_scene(spec, seed)


@cache
def _small_scene_layouts(
    preset: str, seed: int, points: int
) -> tuple[tuple[str, LocalLayout], ...]:
    scene = small_scene(preset, seed, points)
    return tuple((f.id, estimate_layout(f.points)) for f in scene.fragments)


def scene_layouts(
    preset: str = "easy", seed: int = 0, points: int = 30_000
) -> dict[str, LocalLayout]:
    """Local layouts (default parameters) of :func:`small_scene`'s fragments, computed once per
    session; a new dict each call, so a test may add or drop fragments."""
    return dict(_small_scene_layouts(preset, seed, points))


def off_in_last_bits(layout: LocalLayout, seed: int) -> LocalLayout:
    """The layout as another machine's BLAS might give it: every float a few ulps away."""
    rng = np.random.default_rng(seed)

    def nudge(values: np.ndarray) -> np.ndarray:
        values = np.asarray(values, dtype=np.float64)
        steps = rng.integers(-3, 4, values.shape)
        toward = np.where(steps > 0, np.inf, -np.inf)
        out = values.copy()
        for step in range(3):  # up to three ulps either way
            out = np.where(np.abs(steps) > step, np.nextafter(out, toward), out)
        return out

    frame = dataclasses.replace(
        layout.frame,
        rotation=nudge(layout.frame.rotation),
        floor_z=float(nudge(np.array(layout.frame.floor_z))),
    )
    return dataclasses.replace(
        layout,
        keypoints=nudge(layout.keypoints),
        frame=frame,
        source_boundary=nudge(layout.source_boundary),
        target_boundary=nudge(layout.target_boundary),
    )


@pytest.fixture(scope="session")
def easy_scene() -> SyntheticScene:
    """The easy preset's scene of seed 0 at full density (what the service tests upload),
    built once per session."""
    return generate_scene(SceneSpec.easy(), 0)


def _perimeter(polygon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    closed = np.vstack([polygon, polygon[:1]])
    lengths = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    return closed, np.concatenate([[0.0], np.cumsum(lengths)])


def point_at_arc(polygon: np.ndarray, arc: float) -> np.ndarray:
    """The point at arc length ``arc`` along a closed polygon's boundary."""
    closed, cum = _perimeter(polygon)
    arc = arc % cum[-1]
    i = int(np.searchsorted(cum, arc, side="right") - 1)
    t = (arc - cum[i]) / (cum[i + 1] - cum[i])
    return closed[i] + t * (closed[i + 1] - closed[i])


def chains_from_polygon(
    polygon: np.ndarray,
    cuts: list[float],
    rotations: list[int],
    ends: list[float] | None = None,
) -> list[Piece]:
    """Cut a CCW polygon's boundary at arc positions into wall chains, each turned by a
    quarter-turn count and moved so its source is at the origin (as a fragment would be).
    ``ends``: where each chain ends (arc positions past its start, up to a loop further;
    default the next cut): past the next cut, neighbours overlap."""
    _, cum = _perimeter(polygon)
    total = cum[-1]
    pieces = []
    for k, start in enumerate(cuts):
        end = cuts[(k + 1) % len(cuts)] + (total if k == len(cuts) - 1 else 0.0)
        if ends is not None:
            end = ends[k]
        corners = [
            polygon[i % len(polygon)]
            for i, c in enumerate(np.concatenate([cum[:-1], cum[:-1] + total]))
            if start < c < end
        ]
        kp = np.vstack([point_at_arc(polygon, start), *corners, point_at_arc(polygon, end)])
        kp = (kp - kp[0]) @ rot90(rotations[k]).T
        pieces.append(bare_piece(f"p{k}", kp))
    return pieces


def bare_piece(piece_id: str, keypoints: np.ndarray) -> Piece:
    """A piece with only its chain: no end regions, no footprint, no free space."""
    dirs = tuple(direction_index(d) for d in np.diff(keypoints, axis=0))
    empty3, empty2 = np.zeros((0, 3)), np.zeros((0, 2))
    nothing = FreeSpace(
        np.zeros((0, 0), dtype=bool), np.zeros(2), 0.25, np.full(2, np.inf), np.full(2, -np.inf)
    )
    return Piece(piece_id, keypoints, dirs, empty3, empty3, empty2, nothing)


@pytest.fixture
def l_room() -> np.ndarray:
    """An L-shaped room, counter-clockwise."""
    return np.array([[0, 0], [8, 0], [8, 3], [5, 3], [5, 6], [0, 6]], dtype=np.float64)


# Junction end regions (a chain end's travel frame: x along the wall, the cut at x = 0,
# y into the room, z above the floor), for the evidence and refinement tests.
CEILING = 2.6
# A table (four legs and a top) and a wall cabinet near a cut.
FURNITURE = [
    ((-0.62, 0.60, 0.00), (-0.55, 0.67, 0.75)),
    ((0.48, 0.60, 0.00), (0.55, 0.67, 0.75)),
    ((-0.62, 1.33, 0.00), (-0.55, 1.40, 0.75)),
    ((0.48, 1.33, 0.00), (0.55, 1.40, 0.75)),
    ((-0.62, 0.60, 0.72), (0.55, 1.40, 0.76)),
    ((0.10, 0.20, 1.20), (0.35, 0.50, 1.60)),
]


def end_shell(rng: np.random.Generator, seen: tuple[float, float], n: int = 4000) -> np.ndarray:
    """What every junction shares: the wall (y = 0), the floor and the ceiling."""
    x = lambda: rng.uniform(*seen, n)  # noqa: E731
    flat = lambda: rng.normal(0.0, 0.005, n)  # noqa: E731
    wall = np.column_stack([x(), flat(), rng.uniform(0.0, CEILING, n)])
    floor = np.column_stack([x(), rng.uniform(0.0, 2.5, n), flat()])
    ceiling = np.column_stack([x(), rng.uniform(0.0, 2.5, n), CEILING + flat()])
    return np.vstack([wall, floor, ceiling])


def end_boxes(rng, boxes, seen: tuple[float, float], shift: float = 0.0) -> np.ndarray:
    """Points of boxes (one end's frame) that a scan seeing ``seen`` (that frame) has, in a
    frame whose origin is ``shift`` along the wall from that end."""
    pts = np.vstack([rng.uniform(lo, hi, size=(3000, 3)) for lo, hi in boxes])
    pts = pts[(pts[:, 0] >= seen[0]) & (pts[:, 0] <= seen[1])]
    pts[:, 0] -= shift
    return pts


def overlapping_halves(with_structure: bool) -> list[Piece]:
    """A 6 x 4 room cut mid-bottom and mid-top: p0 runs right, up and back along the top;
    p1 left, down and along the bottom, 0.4 m past the cut (the scans overlap there). With
    structure, a table and a cabinet at the bottom cut appear in both scans."""
    room = np.array([[0, 0], [6, 0], [6, 4], [0, 4]], dtype=np.float64)
    p0, p1 = chains_from_polygon(room, [3.0, 16.0], [0, 0])
    keypoints = p1.keypoints.copy()
    keypoints[-1, 0] += 0.4
    p1 = dataclasses.replace(p1, keypoints=keypoints)
    if with_structure:
        rng = np.random.default_rng(3)
        seen = (-1.0, 0.8)  # p1's scan at its target end; p0's sees -0.8 to 1.0 of its own
        target = np.vstack([end_shell(rng, seen), end_boxes(rng, FURNITURE, seen)])
        source = np.vstack(
            [end_shell(rng, (-0.8, 1.0)), end_boxes(rng, FURNITURE, (-1.2, 0.6), -0.4)]
        )
        p1 = dataclasses.replace(p1, target_region=target, ceiling=CEILING)
        p0 = dataclasses.replace(p0, source_region=source, ceiling=CEILING)
    return [p0, p1]
