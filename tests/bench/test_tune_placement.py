"""The tuning script's saved assemblies: written and read back as they were."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bench.tune_placement import (
    FITTED,
    SceneCandidates,
    limit_of,
    load_candidates,
    save_candidates,
)


def _scene(missed: bool) -> SceneCandidates:
    rng = np.random.default_rng(3)
    return SceneCandidates(
        5,
        rng.normal(size=(3, len(FITTED))),
        np.array([False, True, False]),
        np.array([0, 1, 0]),
        True,
        rng.normal(size=len(FITTED)) if missed else None,
        missed,
    )


def test_saved_assemblies_read_back_the_same(tmp_path: Path) -> None:
    path = tmp_path / "candidates.json"
    scenes = [_scene(True), _scene(False)]
    save_candidates(scenes, path)
    loaded = load_candidates(path)
    for before, after in zip(scenes, loaded, strict=True):
        assert after.n == before.n and after.truncated == before.truncated
        np.testing.assert_array_equal(after.features, before.features)
        np.testing.assert_array_equal(after.right, before.right)
        np.testing.assert_array_equal(after.groups, before.groups)
        assert after.missed_truth_right == before.missed_truth_right
        if before.missed_truth is None:
            assert after.missed_truth is None
        else:
            np.testing.assert_array_equal(after.missed_truth, before.missed_truth)


def test_assemblies_saved_with_other_features_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "candidates.json"
    save_candidates([_scene(False)], path)
    record = json.loads(path.read_text())
    record["features"] = record["features"][:-1]
    path.write_text(json.dumps(record))
    with pytest.raises(ValueError, match="features"):
        load_candidates(path)


@pytest.mark.parametrize(
    ("right", "missed_right", "limit"),
    [
        ([True, False], False, "ranked first"),
        ([False, True], False, "energy"),
        ([False, False], True, "search"),
        ([False, False], False, "chains"),
        ([], False, "chains"),
    ],
)
def test_a_scene_is_limited_by_the_first_stage_that_loses_the_right_room(
    right: list[bool], missed_right: bool, limit: str
) -> None:
    scene = SceneCandidates(
        4,
        np.zeros((len(right), len(FITTED))),
        np.array(right, dtype=bool),
        np.zeros(len(right), dtype=int),
        False,
        np.zeros(len(FITTED)) if missed_right else None,
        missed_right,
    )
    assert limit_of(scene) == limit
