"""Presets. The old ones are pinned: the same (preset, seed) gives the same room, cuts, poses
and truth, whatever options the generator gains (new options default off). The world preset
gives valid scenes of 2 to 16 fragments in seconds.

The sampled points are not pinned across machines: numpy's transcendental functions differ
in their last bits between SIMD levels (AVX2 and AVX-512 give different ``sin``), and one
rejection test that flips shifts every later random draw. Seen on 2026-11-23: the same
scene, room and poses equal, every point different between X86_V3 and X86_V4 machines. So
the digest covers what the generator decides (rounded to 0.1 mm), and the points are
checked for determinism on the machine that runs the test.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import replace

import numpy as np
import pytest

from services.synthetic import SceneSpec, SyntheticScene, generate_scene
from services.synthetic.room import Room, nearest_boundary
from tests.services.synthetic.checks import assert_valid_polygon

pytestmark = pytest.mark.timeout(60)

# Taken on 2026-11-23 from the generator as it was (scenes unchanged since before the arc
# cuts, shape families and scanner options); equal with numpy's SIMD at X86_V2 and X86_V3.
PINNED = {
    ("easy", 0): "c928664c06bd2a20",
    ("easy", 1): "90762940b328113f",
    ("paper", 0): "7806164f65df38b3",
    ("paper", 1): "789d26aa1f03e49e",
    ("hard", 0): "f51c8aaa3757e241",
    ("hard", 1): "4cd5f001f8b7003f",
    ("stress", 0): "3d6f46bd1e7008fc",
    ("stress", 1): "f4550f577d7e2597",
}
PINNED_FULL_PAPER_SEED_3 = "b3aa070f5ab92237"


def scene_digest(scene: SyntheticScene) -> str:
    """SHA-256 (16 hex digits) of the polygon, every fragment's truth and its point count.

    Values are rounded to 1e-4 (and -0.0 folded to 0.0): last-bit differences between
    machines cannot change the digest while any real change to the scene does.
    """
    h = hashlib.sha256()

    def add(values: object) -> None:
        h.update((np.round(np.asarray(values, dtype=np.float64), 4) + 0.0).tobytes())

    add(scene.polygon)
    add([scene.ceiling_z, scene.diagonal])
    for f in scene.fragments:
        h.update(f.id.encode())
        for values in (f.pose, f.keypoints_world, f.keypoints_local, f.centroid_local):
            add(values)
        add([f.diagonal, f.loop_start, f.loop_end, f.loop_index, len(f.points)])
    return h.hexdigest()[:16]


@pytest.mark.parametrize(("preset", "seed"), sorted(PINNED))
def test_presets_are_unchanged(preset: str, seed: int) -> None:
    spec = replace(getattr(SceneSpec, preset)(), points_per_fragment=(2_000, 3_000))
    assert scene_digest(generate_scene(spec, seed)) == PINNED[(preset, seed)]


def test_full_paper_scene_is_unchanged() -> None:
    assert scene_digest(generate_scene(SceneSpec.paper(), 3)) == PINNED_FULL_PAPER_SEED_3


@pytest.mark.parametrize("preset", ["paper", "world"])
def test_the_same_seed_gives_the_same_points(preset: str) -> None:
    spec = replace(getattr(SceneSpec, preset)(), points_per_fragment=(1_000, 1_500))
    first, second = generate_scene(spec, 5), generate_scene(spec, 5)
    assert [f.id for f in first.fragments] == [f.id for f in second.fragments]
    for a, b in zip(first.fragments, second.fragments, strict=True):
        assert np.array_equal(a.points, b.points)
    other = generate_scene(spec, 6)
    assert not np.array_equal(first.fragments[0].points, other.fragments[0].points)


WORLD = replace(SceneSpec.world(), points_per_fragment=(1_500, 2_500))


@pytest.mark.parametrize("n", [2, 9, 16])
def test_world_scenes_are_valid(n: int) -> None:
    spec = replace(WORLD, n_fragments_range=(n, n))
    corners, single = set(), 0
    for seed in range(4):
        scene = generate_scene(spec, seed)
        assert_valid_polygon(scene.polygon, spec.n_corners_range, spec.min_edge)
        assert len(scene.fragments) == n == len(scene.junctions)
        room = Room.from_polygon(scene.polygon, scene.ceiling_z)
        for f in scene.fragments:
            distance, _ = nearest_boundary(f.keypoints_world, room)
            assert np.allclose(distance, 0.0, atol=1e-9), "keypoints off the polygon"
            assert (f.loop_end - f.loop_start) % room.perimeter >= spec.min_stretch - 1e-9
            assert 0.8 * 1_500 * min(1.0, 1.2e6 / (n * 2_500)) <= len(f.points) <= 2_500
        assert all(-0.5 <= j.gap <= 0.3 and j.turn in (-1, 0, 1) for j in scene.junctions)
        corners.add(len(scene.polygon))
        single += sum(f.single_wall for f in scene.fragments)
    assert len(corners) >= 2
    assert single >= (0 if n == 2 else 4 * n // 2)  # of 4 scenes


def test_world_preset() -> None:
    world = SceneSpec.world()
    assert world.cut_model == "arc" and world.shape_family == "mixed"
    assert world.gap_range == (-0.5, 0.3) and world.end_margin == 0.0
    assert world.n_fragments_range == (2, 16) and world.outlier_fraction == 0.02
    assert world.reach_beyond == (0.0, 1.0) and world.clutter == 1.5
    assert world.floor_reach_range == (1.0, 4.0)
    assert world.see_through and world.far_walls == 0.5
    assert world.size_range == ((3.0, 3.0), (10.0, 13.0)) and world.no_ceiling_share == 0.3
    with pytest.raises(ValueError):
        replace(world, no_ceiling_share=-0.1)
    with pytest.raises(ValueError):
        replace(world, far_walls=1.5)
    with pytest.raises(ValueError):
        replace(world, gap_range=(-1.0, 0.3))  # an overlap as long as a whole stretch
    with pytest.raises(ValueError):
        replace(world, cut_model="anywhere")  # type: ignore[arg-type]


def test_a_sixteen_fragment_world_scene_takes_seconds() -> None:
    spec = replace(SceneSpec.world(), n_fragments_range=(16, 16))
    start = time.perf_counter()
    scene = generate_scene(spec, 1)
    elapsed = time.perf_counter() - start
    assert len(scene.fragments) == 16
    assert sum(len(f.points) for f in scene.fragments) <= spec.max_scene_points
    assert elapsed < 20.0


def test_a_share_of_the_scans_sees_no_ceiling() -> None:
    clean = replace(WORLD, n_fragments_range=(4, 4), noise_range=(0.0, 0.0), outlier_fraction=0.0)

    def ceiling_points(spec: SceneSpec) -> list[int]:
        scene = generate_scene(spec, 3)
        counts = []
        for f in scene.fragments:
            z = f.points @ f.pose[2, :3] + f.pose[2, 3]  # world height
            counts.append(int(np.count_nonzero(np.abs(z - scene.ceiling_z) < 1e-4)))
        return counts

    assert all(n == 0 for n in ceiling_points(replace(clean, no_ceiling_share=1.0)))
    seen = replace(clean, no_ceiling_share=0.0, ceiling_fraction=(1.0, 1.0))
    assert all(n > 0 for n in ceiling_points(seen))
