"""The benchmark's scene sets: which rooms a split draws and where their layouts are cached."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.room_shapes import DEFAULT_PATH
from bench.world_scenes import BUCKETS, bucket_of, scene_jobs

pytestmark = pytest.mark.timeout(60)

needs_shapes = pytest.mark.skipif(not DEFAULT_PATH.exists(), reason="no room shapes file")


@needs_shapes
def test_a_larger_draw_of_real_rooms_keeps_the_smaller_ones(tmp_path: Path) -> None:
    small = [j for j in scene_jobs("test", 0, 20, tmp_path) if j.outline is not None]
    large = [j for j in scene_jobs("test", 0, 60, tmp_path) if j.outline is not None]
    assert len(small) == 20 and len(large) == 60
    assert [(j.seed, j.outline, j.path) for j in large[:20]] == [
        (j.seed, j.outline, j.path) for j in small
    ]


@needs_shapes
def test_a_cached_real_room_is_named_after_its_shape(tmp_path: Path) -> None:
    jobs = [j for j in scene_jobs("tune", 0, 40, tmp_path) if j.outline is not None]
    names = [Path(j.path).name for j in jobs]
    assert len(set(names)) == len(names)
    shapes = {name.split("-shape")[1] for name in names}
    assert len(shapes) == len(jobs)  # no shape drawn twice
    assert all(name.startswith(f"{j.seed}-shape") for name, j in zip(names, jobs, strict=True))


@needs_shapes
def test_the_splits_draw_other_rooms(tmp_path: Path) -> None:
    tune = {str(j.outline) for j in scene_jobs("tune", 0, 40, tmp_path)}
    test = {str(j.outline) for j in scene_jobs("test", 0, 40, tmp_path)}
    assert not tune & test


def test_random_rooms_fill_every_bucket(tmp_path: Path) -> None:
    jobs = scene_jobs("test", 3, 0, tmp_path)
    assert len(jobs) == 3 * len(BUCKETS)
    assert {j.n_range for j in jobs} == set(BUCKETS)
    assert len({j.seed for j in jobs}) == len(jobs)


def test_bucket_of_names_the_range() -> None:
    assert bucket_of(2) == "2-3" and bucket_of(8) == "6-8" and bucket_of(16) == "13-16"
    assert bucket_of(17) == "17"
