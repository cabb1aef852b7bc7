"""Outside rooms in the project's ground-truth form: the true chain is the stretch of outline
an arc covers, a moved chain is listed as wrong, and the failure anatomy reads the scenes."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from bench.failure_anatomy import anatomy_of
from bench.outside.chains import (
    cached_scene,
    chain_table,
    describe_wrong,
    near_end,
    outline_stretch,
    wrong_chains,
)
from bench.outside.run import Job
from bench.placement_trust import STRUCTURE_CUE, cue_scores, cue_table, evidence_table
from bench.world_scenes import CachedScene
from schemas.params import PipelineParams
from services.model_export import to_site

pytestmark = pytest.mark.timeout(180)

SQUARE = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]])


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> CachedScene:
    job = Job("syn_L_n03_s11", "clouds", 11, "L", "2-3", 3)
    return cached_scene(job, tmp_path_factory.mktemp("outside"))


def test_a_stretch_runs_ccw_through_the_corners_it_covers_even_past_vertex_zero() -> None:
    np.testing.assert_allclose(
        outline_stretch(SQUARE, 3.0, 2.0), [[3.0, 0.0], [4.0, 0.0], [4.0, 1.0]]
    )
    # From 1 m before vertex 0 (perimeter 14) round it.
    np.testing.assert_allclose(
        outline_stretch(SQUARE, 13.0, 2.5), [[0.0, 1.0], [0.0, 0.0], [1.5, 0.0]]
    )
    np.testing.assert_allclose(outline_stretch(SQUARE, 0.5, 1.0), [[0.5, 0.0], [1.5, 0.0]])


def test_a_door_near_an_arc_end_is_named_before_a_window() -> None:
    door = {"edge": 1, "u0": 0.5, "u1": 1.4, "type": "door"}
    window = {"edge": 0, "u0": 1.0, "u1": 2.0, "type": "window"}
    truth = {"polygon": SQUARE.tolist(), "openings": [door, window]}
    assert near_end(truth, 0.0, 4.5) == "door"  # ends at 4.5, the door starts at 4.5
    assert near_end(truth, 2.5, 1.0) == "window"  # the window ends at 2.0, 0.5 m before
    assert near_end(truth, 8.0, 4.0) == "none"
    assert near_end({**truth, "openings": [window]}, 13.5, 1.0) == "window"  # ends at 0.5


def test_the_true_chain_is_the_arcs_outline_and_a_moved_chain_is_wrong(
    scene: CachedScene,
) -> None:
    truth = scene.truth
    polygon = np.asarray(truth["room"]["polygon"])
    for fragment in truth["fragments"]:
        world = to_site(np.asarray(fragment["keypoints_local"]), np.asarray(fragment["pose"]))
        np.testing.assert_allclose(world[:, 2], 0.0, atol=1e-9)
        np.testing.assert_allclose(world[:, :2], outline_stretch(polygon, *fragment["arc"]))
    assert [f["loop_index"] for f in truth["fragments"]] == [0, 1, 2]
    before = {f["id"] for f, _ in wrong_chains(scene)}
    fid = next(f["id"] for f in truth["fragments"] if f["id"] not in before)
    layout = scene.layouts[fid]
    moved = dataclasses.replace(layout, keypoints=layout.keypoints + np.array([1.0, 0.0]))
    shifted = dataclasses.replace(scene, layouts={**scene.layouts, fid: moved})
    assert {f["id"] for f, _ in wrong_chains(shifted)} == before | {fid}
    assert any(line.startswith(f"11 {fid} (") for line in describe_wrong(shifted))
    rows = chain_table([shifted]).splitlines()
    n = len(truth["fragments"])
    assert rows[-1].split()[:3] == ["all", str(n), str(n - len(before) - 1)]
    assert fid in {f["id"] for f, _ in wrong_chains(shifted, "ends")}
    assert fid in {f["id"] for f, _ in wrong_chains(shifted, "shape")}


def test_a_chain_cut_short_between_right_ends_fails_only_the_shape_test(
    scene: CachedScene,
) -> None:
    # The chain with most corners replaced by the straight line between its ends: its ends
    # stay right, its shape does not.
    fid = max(scene.layouts, key=lambda f: len(scene.layouts[f].keypoints))
    layout = scene.layouts[fid]
    assert fid not in {f["id"] for f, _ in wrong_chains(scene, "shape")}
    cut = dataclasses.replace(layout, keypoints=layout.keypoints[[0, -1]])
    cut_scene = dataclasses.replace(scene, layouts={**scene.layouts, fid: cut})
    assert fid not in {f["id"] for f, _ in wrong_chains(cut_scene, "ends")}
    assert fid in {f["id"] for f, _ in wrong_chains(cut_scene, "shape")}
    assert chain_table([cut_scene]).splitlines()[0].split()[-2:] == ["shape", "right"]


def test_the_failure_anatomy_reads_an_outside_scene(scene: CachedScene) -> None:
    anatomy = anatomy_of(scene, PipelineParams())
    assert anatomy.n == 3 and anatomy.seed == 11
    assert anatomy.right == (anatomy.cause is None)
    # The chain with most corners halved in size: a wrong room, and its cause the layout.
    fid = max(scene.layouts, key=lambda f: len(scene.layouts[f].keypoints))
    layout = scene.layouts[fid]
    centre = layout.keypoints.mean(axis=0)
    moved = dataclasses.replace(layout, keypoints=centre + 0.5 * (layout.keypoints - centre))
    wrong = anatomy_of(dataclasses.replace(scene, layouts={**scene.layouts, fid: moved}),
                       PipelineParams())  # fmt: skip
    assert (wrong.right, wrong.cause) == (False, "layout")


def test_a_scene_folder_holds_what_the_cli_reads(tmp_path: Path) -> None:
    job = Job("syn_rect_n02_s12", "clouds", 12, "rect", "2-3", 2)
    built = cached_scene(job, tmp_path)
    assert sorted(p.name for p in tmp_path.glob("*.ply")) == ["frag_00.ply", "frag_01.ply"]
    assert set(built.layouts) == {"frag_00", "frag_01"}
    assert built.name == "outside synthetic"


def test_the_junction_cues_read_outside_scenes(scene: CachedScene) -> None:
    scores = cue_scores([scene], PipelineParams().placement)
    table = cue_table(scores)
    n = len(scene.truth["fragments"])
    true_pairs = list(table.columns[2].cells)
    false_pairs = list(table.columns[3].cells)
    assert true_pairs == [str(n)] * 3  # each fragment's true successor, once per cue
    assert false_pairs == [str(n * (n - 1) - n)] * 3
    # Every pair falls in one bin of the structure evidence.
    bins = evidence_table(*scores[STRUCTURE_CUE])
    assert sum(int(str(c)) for c in bins.columns[1].cells) == n
    assert sum(int(str(c)) for c in bins.columns[2].cells) == n * (n - 1) - n
