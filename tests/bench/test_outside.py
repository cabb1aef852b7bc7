"""The outside benchmark: its generators repeat a seed exactly, and its scorer calls the
truth right and an assembly with one fragment turned 90 degrees wrong."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench.outside import clouds, frames
from bench.outside.score import score_result, true_fragments, truth_result

pytestmark = pytest.mark.timeout(120)


@pytest.fixture(scope="module")
def cloud_scene(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    out = tmp_path_factory.mktemp("cloud")
    return out, clouds.generate(11, "L", 3, out)


@pytest.fixture(scope="module")
def frame_scene(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    out = tmp_path_factory.mktemp("frames")
    return out, frames.make_scene(out, 5, "wide", "rect")


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _site() -> Any:
    c, s = math.cos(1.234), math.sin(1.234)
    return np.array([[c, -s, 0, 3.0], [s, c, 0, -7.0], [0, 0, 1, 0.5], [0, 0, 0, 1]])


def _turned(truth: dict[str, Any], fid: str) -> dict[str, Any]:
    """The truth as a result with fragment ``fid`` turned 90 degrees about the vertical
    through its reference point, the polygon kept."""
    result = truth_result(truth, _site())
    frag = next(f for f in result["fragments"] if f["id"] == fid)
    pose = np.asarray(frag["pose"])
    c = pose @ np.append(true_fragments(truth)[fid][1], 1.0)
    G = np.eye(4)
    G[:2, :2] = [[0, -1], [1, 0]]
    G[:2, 3] = c[:2] - G[:2, :2] @ c[:2]
    frag["pose"] = (G @ pose).tolist()
    return result


def _check_scorer(truth: dict[str, Any]) -> None:
    for site in (None, _site()):
        s = score_result(truth, truth_result(truth, site))
        m = s["main"]
        assert m["right"] and m["acc"] and m["acc_strict"] and s["top3"]
        assert m["poly_err"] < 1e-9
        assert max(m["yaw_err"].values()) < 1e-6 and max(m["trans_err"].values()) < 1e-6
        assert m["max_consistent"] == len(true_fragments(truth))
    fid = sorted(true_fragments(truth))[0]
    turned = _turned(truth, fid)
    s = score_result(truth, turned)
    assert not s["main"]["right"] and not s["main"]["poses_ok"] and not s["top3"]
    assert max(s["main"]["yaw_err"].values()) == pytest.approx(90.0, abs=1e-6)
    turned["alternatives"] = [dict(truth_result(truth), probability=0.3)]
    assert score_result(truth, turned)["top3"]


def test_a_cloud_scene_is_the_same_for_its_seed(cloud_scene, tmp_path: Path) -> None:
    out, truth = cloud_scene
    assert truth["n"] == 3 and len(list(out.glob("frag_*.ply"))) == 3
    again = clouds.generate(11, "L", 3, tmp_path)
    assert again == truth and _files(tmp_path) == _files(out)


def test_the_cloud_truth_is_right_and_a_turned_fragment_wrong(cloud_scene) -> None:
    _check_scorer(cloud_scene[1])


def test_a_frame_scene_is_the_same_for_its_seed(frame_scene, tmp_path: Path) -> None:
    out, truth = frame_scene
    assert 2 <= truth["n_frames"] <= 8 and len(truth["frames"]) == truth["n_frames"]
    again = frames.make_scene(tmp_path, 5, "wide", "rect")
    assert again == truth and _files(tmp_path) == _files(out)


def test_the_frame_truth_is_right_and_a_turned_frame_wrong(frame_scene) -> None:
    _check_scorer(frame_scene[1])


def test_no_result_scores_wrong(cloud_scene) -> None:
    s = score_result(cloud_scene[1], None)
    assert s["status"] == "none" and not s["main"]["acc"] and not s["top3"]


def test_real_shapes_need_their_file(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="missing"):
        clouds.real_pool(tmp_path / "missing.json")
    with pytest.raises(FileNotFoundError, match="missing"):
        frames.real_shapes(tmp_path / "missing.json")
