"""The failure anatomy: each wrong main room gets one cause, and the tables count them."""

from __future__ import annotations

import dataclasses

import pytest
from rich.console import Console

from bench.failure_anatomy import (
    CAUSES,
    Anatomy,
    anatomy_of,
    cause_table,
    frame_scenes,
    main,
    term_table,
)
from bench.world_scenes import CachedScene
from schemas.params import PipelineParams, PlacementParams
from services.synthetic import ground_truth_json
from tests.conftest import scene_layouts, small_scene

pytestmark = pytest.mark.timeout(300)


def _scene(preset: str, seed: int) -> CachedScene:
    truth = ground_truth_json(small_scene(preset, seed))
    return CachedScene("unit", truth, scene_layouts(preset, seed), 0.0)


def _with(**placement: float) -> PipelineParams:
    params = PipelineParams()
    return params.model_copy(update={"placement": params.placement.model_copy(update=placement)})


def test_a_right_room_has_no_cause() -> None:
    anatomy = anatomy_of(_scene("paper", 1), PipelineParams())
    assert anatomy.right
    assert anatomy.cause is None


def test_an_energy_that_prefers_a_rival_is_blamed_with_its_term() -> None:
    # Hull edges made 30 times dearer: a simpler wrong room beats the truth.
    anatomy = anatomy_of(_scene("paper", 1), _with(weight_hull=30.0))
    assert not anatomy.right
    assert anatomy.cause == "energy"
    assert anatomy.gap is not None and anatomy.gap > 0.0
    assert max(anatomy.terms, key=lambda name: anatomy.terms[name]) == "hull"


def test_a_chain_gone_wrong_is_blamed_on_the_layout() -> None:
    scene = _scene("paper", 1)
    fid = sorted(scene.layouts)[1]
    layout = scene.layouts[fid]
    keypoints = layout.keypoints.copy()
    keypoints[-1] += 2.0 * (keypoints[-1] - keypoints[-2])  # its last wall three times as long
    layouts = {**scene.layouts, fid: dataclasses.replace(layout, keypoints=keypoints)}
    anatomy = anatomy_of(dataclasses.replace(scene, layouts=layouts), PipelineParams())
    assert not anatomy.right
    assert anatomy.cause == "layout"


def _row(seed: int, n: int, cause: str | None, gap: float | None = None) -> Anatomy:
    terms = {"turns": 1.0, "hull": -0.5} if cause == "energy" else {}
    return Anatomy("test_real", seed, n, cause is None, "ambiguous", cause, gap, terms)


def test_the_tables_count_causes_per_bucket() -> None:
    rows = [
        _row(1, 2, None),
        _row(2, 3, "layout"),
        _row(3, 3, "energy", 1.0),
        _row(4, 5, "energy", 3.0),
        _row(5, 5, "search", -1.0),
    ]
    console = Console(record=True, width=300)
    console.print(cause_table(rows))
    console.print(term_table(rows))
    lines = console.export_text().splitlines()
    small = next(line.split() for line in lines if "test_real 2-3" in line and "%" not in line)
    # set, bucket, scenes, wrong, then one count per cause, then the median gap.
    assert small[2:4] == ["3", "2"]
    counts = dict(zip(CAUSES, small[4 : 4 + len(CAUSES)], strict=True))
    assert counts["layout"] == "1" and counts["energy"] == "1" and counts["search"] == "0"
    assert small[-1] == "1.00"
    terms = next(line for line in lines if "test_real 4-5" in line and "%" in line)
    assert "+1.00 (100%)" in terms and "-0.50 (0%)" in terms


def test_a_floor_height_off_is_not_blamed_on_the_layout() -> None:
    # Every chain right on the floor plan, one floor 0.5 m off: the hull still decides.
    scene = _scene("paper", 1)
    fid = sorted(scene.layouts)[1]
    layout = scene.layouts[fid]
    lowered = dataclasses.replace(layout.frame, floor_z=layout.frame.floor_z - 0.5)
    layouts = {**scene.layouts, fid: dataclasses.replace(layout, frame=lowered)}
    anatomy = anatomy_of(dataclasses.replace(scene, layouts=layouts), _with(weight_hull=30.0))
    assert anatomy.cause == "energy"


def test_frame_rooms_are_one_set_bucketed_by_frames(capsys: pytest.CaptureFixture[str]) -> None:
    # Two rendered wide-angle rooms of three frames each: one set, the 2-3 bucket.
    scenes = frame_scenes("wide", 2, 2000, False, PipelineParams())
    assert [s.name for s in scenes] == ["wide synthetic"] * 2
    assert [s.n_fragments for s in scenes] == [3, 3]
    assert main(["--frames", "wide", "--scenes", "2", "--seed", "2000"]) == 0
    assert "wide synthetic 2-3" in capsys.readouterr().out


def test_the_true_assembly_at_the_wrong_size_is_geometry_not_energy() -> None:
    # Kinect room 2009, refined expecting no overlap at the junctions (as before
    # refined_junction_mean) and without the cameras its frames' views say they share
    # (either gets its size right): the main room is the true loop, 10 % of the diagonal
    # off in size; the truth's energy evaluated again differs from the result's by float
    # noise (2e-6).
    scene = frame_scenes("kinect", 1, 2009, False, PipelineParams())[0]
    assert anatomy_of(scene, PipelineParams()).right
    overlap_unseen = PlacementParams(refined_junction_mean=0.0)
    assert anatomy_of(scene, PipelineParams(placement=overlap_unseen)).right
    end_to_end = PipelineParams(
        placement=overlap_unseen.model_copy(update={"station_view_overlap": 0.0})
    )
    anatomy = anatomy_of(scene, end_to_end)
    assert not anatomy.right
    assert anatomy.cause == "geometry"
    assert anatomy.gap is not None and abs(anatomy.gap) < 1e-4
