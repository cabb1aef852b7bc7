"""Scoring helpers of the placement benchmarks: a result's main room judged, and the map of
the confidence's logit fitted for one kind of evidence."""

from __future__ import annotations

import numpy as np
import pytest

from bench.scoring import (
    chain_on_truth,
    fit_logit_map,
    main_room_verdict,
    params_with,
    share_interval,
)
from services.evaluation import evaluate_result
from services.pipeline import place_site
from services.synthetic import ground_truth_json
from tests.conftest import scene_layouts, small_scene

pytestmark = pytest.mark.timeout(300)


def test_a_main_room_is_judged_whatever_its_status() -> None:
    truth = ground_truth_json(small_scene("easy", 2, 40_000))
    result = place_site(scene_layouts("easy", 2, 40_000)).model_dump(mode="json")
    assert result["status"] == "closed"
    confidence = result["confidence"]
    reported = evaluate_result(result, truth).global_correct
    assert main_room_verdict(result, reported) == (confidence, True)
    # A lone room the confidence doubts is reported open, with its floorplan: judged alike.
    doubted = {**result, "status": "open"}
    assert main_room_verdict(doubted, reported) == (confidence, True)
    assert main_room_verdict(doubted, False) == (confidence, False)
    # An open loop without a room, or a failure, has no main room to judge.
    unclosed = {**doubted, "floorplan": {"rooms": []}}
    assert main_room_verdict(unclosed, False) is None
    assert main_room_verdict({**result, "status": "failed"}, False) is None


def test_an_overconfident_kind_gets_a_map_that_lowers_its_high_confidences() -> None:
    # Results said 0.99 that are right 70 % of the time, and 0.5 right half the time.
    rng = np.random.default_rng(0)
    confidences = [0.99] * 200 + [0.5] * 200
    right = list(rng.random(200) < 0.7) + list(rng.random(200) < 0.5)
    (bias, slope), summary = fit_logit_map(confidences, right, 0.95)
    mapped = 1.0 / (1.0 + np.exp(-(bias + slope * np.log(0.99 / 0.01))))
    assert 0.6 < mapped < 0.8
    assert "400 main rooms" in summary and "after 0 (0 right)" in summary


def test_a_map_with_another_input_learns_that_more_of_it_is_less_often_right() -> None:
    # The same confidences, right 90 % of the time with a narrow view and 60 % with a wide one.
    rng = np.random.default_rng(1)
    confidences = [0.9] * 400
    view = [0.0] * 200 + [1.0] * 200
    right = list(rng.random(200) < 0.9) + list(rng.random(200) < 0.6)
    (bias, slope, per_view), summary = fit_logit_map(confidences, right, 0.95, view)
    assert per_view < -1.0
    z = np.log(0.9 / 0.1)
    narrow, wide = (1.0 / (1.0 + np.exp(-(bias + slope * z + per_view * v))) for v in (0, 1))
    assert narrow == pytest.approx(0.9, abs=0.05) and wide == pytest.approx(0.6, abs=0.07)
    assert "400 main rooms" in summary


@pytest.mark.parametrize(("right", "total"), [(0, 10), (11, 21), (30, 30), (80, 80)])
def test_a_share_interval_holds_the_share_and_narrows_with_more_scenes(right, total) -> None:
    lo, hi = share_interval(right, total)
    assert 0.0 <= lo <= right / total <= hi <= 1.0
    wider = share_interval(right // 4, total // 4)
    assert hi - lo < wider[1] - wider[0]
    # 30 of 30 right still leaves room for a true share under 90 %.
    if right == total == 30:
        assert lo == pytest.approx(0.886, abs=1e-3)


def test_a_benchmark_sets_nested_parameters_and_is_told_of_unknown_ones() -> None:
    params = params_with(["layout.frame.merge_inlier_share=1.0", "placement.weight_outside=0"])
    assert params.layout.frame.merge_inlier_share == 1.0
    assert params.placement.weight_outside == 0.0
    for wrong in ("layout.frame.no_such=1", "layout.nowhere.x=1", "weight_outside=0"):
        with pytest.raises(ValueError):
            params_with([wrong])
    with pytest.raises(ValueError):  # validated: a share over 1
        params_with(["layout.frame.merge_inlier_share=2"])


def test_a_chain_that_misses_part_of_its_stretch_lies_on_the_truth_and_a_stray_one_does_not() -> (
    None
):
    pose = np.eye(4)
    pose[:3, 3] = [1.0, 2.0, 0.0]  # local -> world
    true_local = [[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [3.0, 2.0, 0.0]]  # the truth, in the world
    fragment = {"pose": pose.tolist(), "keypoints_local": true_local}  # from (1, 2) on
    assert chain_on_truth([[1.0, 0.0, 0.0], [3.0, 0.0, 0.0], [3.0, 1.0, 0.0]], fragment)
    assert not chain_on_truth([[1.0, 0.3, 0.0], [3.0, 0.3, 0.0]], fragment)  # a front
    assert not chain_on_truth([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0]], fragment)  # past the corner
    assert not chain_on_truth([[1.0, 0.0, 0.0]], fragment)
