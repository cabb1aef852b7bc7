"""The trust benchmark's junction tables on one small world scene (real layouts)."""

from __future__ import annotations

import dataclasses
import itertools

import pytest

from bench.placement_trust import overlap_table
from bench.world_scenes import CachedScene
from services.pipeline import estimate_layout
from services.synthetic import SceneSpec, generate_scene, ground_truth_json

pytestmark = pytest.mark.timeout(120)


@pytest.fixture(scope="module")
def scene() -> CachedScene:
    spec = dataclasses.replace(
        SceneSpec.world(), n_fragments_range=(4, 4), points_per_fragment=(8_000, 10_000)
    )
    generated = generate_scene(spec, 7)
    layouts = {f.id: estimate_layout(f.points) for f in generated.fragments}
    return CachedScene("unit", ground_truth_json(generated), layouts, 0.0)


def test_overlap_table_counts_every_ordered_pair_once(scene: CachedScene) -> None:
    usable = {fid for fid, lay in scene.layouts.items() if lay.ok}
    straight = sum(
        j["turn"] == 0 and {j["from"], j["to"]} <= usable for j in scene.truth["junctions"]
    )
    table = overlap_table([scene])
    pairs, counts = table.columns[0], table.columns[1]
    assert list(pairs.cells) == ["true straight junctions", "false pairs"]
    true_count, false_count = (int(str(c)) for c in counts.cells)
    assert true_count == straight
    assert true_count + false_count == len(list(itertools.permutations(usable, 2)))
