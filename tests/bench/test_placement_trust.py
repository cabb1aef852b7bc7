"""The trust benchmark's tables: junction tables on one small world scene (real layouts),
the bucket table on outcomes made up here."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from rich.console import Console

from bench.placement_trust import (
    Outcome,
    bucket_table,
    evidence_table,
    fragment_checks,
    hints_table,
    overlap_table,
    reliability_table,
)
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


def test_evidence_table_gives_each_bin_its_likelihood_ratio() -> None:
    # 10 true pairs: 2 without evidence, 8 with full; 100 false: 96 without, 4 at 0.5.
    true = [0.0] * 2 + [1.0] * 8
    false = [0.0] * 96 + [0.5] * 4
    table = evidence_table(true, false)
    labels = list(table.columns[0].cells)
    assert labels == ["0.0", "(0.0, 0.3]", "(0.3, 0.6]", "(0.6, 0.9]", "(0.9, 1.0]"]
    assert list(table.columns[1].cells) == ["2", "0", "0", "0", "8"]
    assert list(table.columns[2].cells) == ["96", "0", "4", "0", "0"]
    # log((2 / 10) / (96 / 100)); a bin missing from either side has no ratio.
    assert list(table.columns[3].cells) == ["-1.57", "-", "-", "-", "-"]


def test_fragment_checks_judge_each_pose_relative_to_the_first(scene: CachedScene) -> None:
    truth = scene.truth
    fragments = [
        {"id": f["id"], "pose": f["pose"], "loop_index": f["loop_index"], "confidence": 0.9}
        for f in truth["fragments"]
    ]
    result = {"fragments": fragments}
    assert [right for _, right in fragment_checks(result, truth)] == [True] * len(fragments)
    # The whole site moved: every pose is still right relative to the first.
    shifted = np.eye(4)
    shifted[:3, 3] = [5.0, -3.0, 0.0]
    moved = [{**f, "pose": (shifted @ np.asarray(f["pose"])).tolist()} for f in fragments]
    assert all(right for _, right in fragment_checks({"fragments": moved}, truth))
    # One fragment 2 m off: only it is wrong; no confidence, no check.
    last = max(fragments, key=lambda f: f["loop_index"])
    off = np.asarray(last["pose"]).copy()
    off[0, 3] += 2.0
    broken = [{**f, "pose": off.tolist()} if f is last else f for f in fragments]
    verdicts = fragment_checks({"fragments": broken}, truth)
    checks = dict(zip([f["id"] for f in broken], verdicts, strict=True))
    assert [fid for fid, (_, right) in checks.items() if not right] == [last["id"]]
    unsure = [{**f, "confidence": None} for f in fragments]
    assert fragment_checks({"fragments": unsure}, truth) == []


def _outcome(seed: int, status: str, correct: bool) -> Outcome:
    return Outcome(
        "test_real", seed, 2, status, 0.99, correct, correct, [True, True], [], None, 0.1
    )


def test_bucket_table_gives_the_closed_results_right_share_with_its_interval() -> None:
    closed = [_outcome(k, "closed", k != 0) for k in range(50)]
    outcomes = [*closed, _outcome(99, "ambiguous", False)]
    console = Console(record=True, width=400)
    console.print(bucket_table(outcomes, "unit"))
    text = console.export_text()
    # 49 of 50 closed right: 98.0 %, Wilson interval 89.5-99.6 %.
    assert "50: 98.0 (90-100)" in text
    assert "96.1 (87-99)" in text  # ACC_global: 49 of 51


def test_hints_table_records_each_scenes_outcome_with_priors(scene: CachedScene) -> None:
    record: list[Outcome] = []
    table = hints_table([scene], 1.5, 20.0, record=record)
    assert [(o.name, o.seed, o.n) for o in record] == [("unit", scene.seed, scene.n_fragments)]
    assert table.row_count == 1  # one bucket
    calibration = reliability_table(record, "with priors of 1.5 m and 20.0 deg")
    assert "with priors of 1.5 m" in str(calibration.title)
    assert calibration.row_count == 1 and str(calibration.caption).endswith("over 1 results")
