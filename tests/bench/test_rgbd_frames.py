"""The frames benchmark: scenes go the way ``jigsaw align`` takes them, each local layout
timed once (a merged group's as one)."""

from __future__ import annotations

import argparse
import math
from typing import Any

import numpy as np
import pytest

from bench.rgbd_frames import (
    LayoutClock,
    _fit_stations,
    _fit_view_top,
    _row,
    _scenes,
    _stance,
    bucket_row,
    cached_scenes,
    limits,
    merged_truth,
    result_stations,
    run,
)
from bench.tune_placement import LIMITS, main
from schemas.params import PipelineParams
from services.synthetic.render import CAMERAS, KINECT

pytestmark = pytest.mark.timeout(180)


def test_each_local_layout_is_timed_until_the_next_stage() -> None:
    clock = LayoutClock()
    for stage in ("frame groups", "local layout a", "local layout b", "placement", "done"):
        clock(stage, 0.0)
    assert len(clock.seconds) == len(clock.cpu) == 2
    assert all(s >= 0.0 for s in clock.seconds + clock.cpu)


def test_one_scene_is_scored_with_every_frame_timed() -> None:
    figures = run(1, 1000)
    assert figures["scenes"] == 1 and figures["frames"] >= 3 and figures["skipped"] == 0
    assert 0.0 <= figures["acc_local"] <= 1.0 and figures["acc_global"] in (0.0, 1.0)
    assert figures["cpu_ms_per_frame"] > 0.0 and not math.isnan(figures["ms_per_frame_p90"])
    # The statuses are counted apart: closed (and how many of those are right), ambiguous.
    assert figures["closed"] + figures["ambiguous"] <= 1
    assert figures["closed_right"] <= figures["closed"]
    assert figures["closed_right"] == (figures["closed"] == 1 and figures["acc_global"] == 1.0)
    # Its room is counted in the bucket of its frame count, with the same verdicts.
    [(bucket, counts)] = figures["buckets"].items()
    lo, hi = (int(n) for n in bucket.split("-"))
    assert lo <= figures["frames"] <= hi
    assert counts == [figures["acc_global"], figures["closed"], figures["closed_right"], 1]
    row = bucket_row("one", figures)
    assert row.count("|") == 7 and row.count(" - ") == 4
    assert f"{int(counts[0])}/1 ({100 * counts[0]:.0f} %)" in row


def test_a_room_no_station_can_tile_is_counted_as_not_rendered() -> None:
    hall = np.array([[0.0, 0.0], [40.0, 0.0], [40.0, 40.0], [0.0, 40.0]])  # beyond any range
    figures = run(1, 1000, [hall])
    assert figures["scenes"] == 0 and figures["skipped"] == 1
    assert _row("hall", figures).startswith("| hall | 0 (1 not rendered) | 0 |")


def test_every_rendered_scene_gets_one_limit() -> None:
    found = limits(2, 1000)
    assert sorted(found) == [1000, 1001]
    assert set(found.values()) <= set(LIMITS)


def test_the_scenes_are_rendered_by_the_camera_asked_for() -> None:
    [kinect] = _scenes(1, 1000, None)
    [wide] = _scenes(1, 1000, None, "wide")
    assert kinect is not None and wide is not None
    assert {f.frame.intrinsics for f in kinect.frames} == {KINECT}
    assert {f.frame.intrinsics for f in wide.frames} == {CAMERAS["wide"]}
    assert all(f.frame.depth.shape == (480, 640) for f in wide.frames)
    # The benchmark's figures are of the camera asked for.
    assert run(1, 1000, camera="wide")["frames"] == len(wide.frames) != len(kinect.frames)


def test_the_scenes_are_rendered_with_the_stance_asked_for() -> None:
    # The generator's stations look 5-20 degrees down; --pitch asks for steeper views.
    def pitches(stance: dict[str, object] | None) -> list[float]:
        [scene] = _scenes(1, 1000, None, "realsense", stance)
        assert scene is not None
        forward = [f.pose[:3, 2] for f in scene.frames]  # the optical axis, world
        return [math.degrees(math.asin(axis[2])) for axis in forward]

    assert all(-20.5 <= p <= -4.5 for p in pitches(None))
    assert all(-45.5 <= p <= -29.5 for p in pitches({"pitch_deg": (-45.0, -30.0)}))
    steep = run(1, 1000, camera="realsense", stance={"pitch_deg": (-45.0, -30.0)})
    assert steep["scenes"] == 1 and 0.0 <= steep["acc_local"] <= 1.0
    # A realsense 30-45 degrees down sees up to 2-13 degrees below level, 6-17 degrees below
    # the lowest top of view fitted (4 degrees above level).
    assert len(steep["tops"]) == len(steep["confidences"])
    assert all(0.1 < below < 0.32 for below in steep["tops"])


def test_gap_leaves_metres_of_wall_unseen_between_neighbouring_frames() -> None:
    def held(overlap: float | None, gap: float | None) -> dict[str, Any]:
        options = argparse.Namespace(pitch=None, roll=None, overlap=overlap, gap=gap)
        return _stance(options)

    assert held(None, None) == {}
    assert held(None, 2.5) == {"gap_range": (-0.3, 2.5)}
    assert held(2.0, 2.5) == {"gap_range": (-2.0, 2.5)}
    assert held(2.0, None) == {"gap_range": (-2.0, 0.2)}

    def unseen(stance: dict[str, Any] | None) -> list[float]:
        [scene] = _scenes(1, 1001, None, "kinect", stance)
        assert scene is not None
        ordered = sorted(scene.frames, key=lambda f: f.loop_index)
        ends = [f.loop_end for f in ordered]
        starts = [f.loop_start for f in ordered[1:] + ordered[:1]]
        half = scene.perimeter / 2
        return [(b - a + half) % (2 * half) - half for a, b in zip(ends, starts, strict=True)]

    assert max(unseen(None)) <= 0.2 + 1e-6
    wide = unseen(held(None, 2.5))
    assert max(wide) > 1.0 and all(-0.3 - 1e-6 <= g <= 2.5 + 1e-6 for g in wide)


def test_the_view_tops_slope_is_fitted_on_rooms_seen_steeply(capsys) -> None:
    _fit_view_top(1, 2000, PipelineParams(), ["realsense"], {"pitch_deg": (-45.0, -30.0)})
    line = capsys.readouterr().out
    assert line.startswith("frame_view_top_slope = ") and "main rooms beyond the fitted" in line
    assert float(line.split("= ")[1].split(":")[0]) <= 0.0


def test_cached_frame_scenes_lay_out_each_frame_alone() -> None:
    [scene] = cached_scenes(1, 1000)
    assert scene.name == "frames-1000" and scene.seed == 1000
    assert sorted(scene.layouts) == sorted(f["id"] for f in scene.truth["fragments"])
    assert all(layout.evidence == "frame" for layout in scene.layouts.values())


def test_the_frames_weights_are_fitted_on_rendered_rooms(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["--frames", "2", "--rounds", "1"]) == 0
    printed = " ".join(capsys.readouterr().out.split())
    assert "round 1: frame_weights = (" in printed
    weights = printed.split("frame_weights = (")[1].split(")")[0].split(",")
    assert len(weights) == 7 and all(float(w) >= 0.0 for w in weights)


def test_the_frames_weights_pool_the_rooms_of_every_camera_given(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["--frames", "1", "--rounds", "1", "--camera", "kinect", "--camera", "wide"]) == 0
    printed = " ".join(capsys.readouterr().out.split())
    seen = [int(printed.split(f"{camera}: ")[1].split()[0]) for camera in ("kinect", "wide")]
    fitted_on = int(printed.split("weights before: ")[1].split()[2])  # "N of M": M rooms
    assert min(seen) >= 1 and fitted_on == sum(seen)


def _frame_truth(fid: str, start: float, end: float) -> dict[str, object]:
    return {"id": fid, "pose": np.eye(4).tolist(), "loop_start": start, "loop_end": end,
            "diagonal": 2.0, "keypoints_local": [[0.0, 0.0, 0.0]]}  # fmt: skip


@pytest.mark.parametrize(
    ("arcs", "union"),
    [
        # 4 m square, CCW from (0, 0): frames overlapping on the wall x = 4
        ({"a": (1.0, 5.0), "b": (4.0, 9.0)}, [[1, 0], [4, 0], [4, 4], [3, 4]]),
        # the same stretch listed the other way round, and one across the loop's start
        ({"b": (4.0, 9.0), "a": (1.0, 5.0)}, [[1, 0], [4, 0], [4, 4], [3, 4]]),
        ({"a": (15.0, 2.0), "b": (1.0, 3.0)}, [[0, 1], [0, 0], [3, 0]]),
    ],
)
def test_a_merged_groups_frames_are_judged_against_the_stretch_the_group_saw(
    arcs: dict[str, tuple[float, float]], union: list[list[float]]
) -> None:
    square = [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]
    fragments = [_frame_truth(fid, *arc) for fid, arc in arcs.items()]
    alone = _frame_truth("alone", 9.5, 12.0)
    truth: dict[str, Any] = {
        "room": {"polygon": square, "floor_z": 0.0, "ceiling_z": 2.5},
        "fragments": [*fragments, alone],
    }
    anchor, member = list(arcs)
    result = {"fragments": [{"id": anchor}, {"id": member, "merged_into": anchor}, {"id": "alone"}]}
    judged = {f["id"]: f for f in merged_truth(truth, result)["fragments"]}
    for fid in arcs:
        np.testing.assert_allclose(judged[fid]["keypoints_world"], union, atol=1e-9)
        np.testing.assert_allclose(np.asarray(judged[fid]["keypoints_local"])[:, :2], union)
        assert judged[fid]["diagonal"] >= float(np.linalg.norm(np.ptp(union, axis=0)))
    assert judged["alone"] == alone  # an unmerged frame keeps its own


def test_a_results_stations_are_where_its_frames_poses_stand() -> None:
    def placed(x: float, y: float) -> dict[str, Any]:
        pose = np.eye(4)
        pose[:2, 3] = x, y
        return {"id": f"f{x}{y}", "pose": pose.tolist()}

    fragments = [placed(0.0, 0.0), placed(0.2, 0.1), placed(3.0, 0.0), {"id": "open", "pose": None}]
    assert result_stations({"fragments": fragments}, 0.6) == 2
    assert result_stations({"fragments": fragments[:2]}, 0.6) == 1
    assert result_stations({"status": "failed", "fragments": []}, 0.6) == 0


def test_the_stations_slope_is_fitted_on_rooms_overlapping_as_told(capsys) -> None:
    figures = run(1, 2000, stance={"gap_range": (-2.0, 0.3)})
    assert len(figures["stations"]) == len(figures["confidences"])
    assert all(beyond >= 0 for beyond in figures["stations"])
    _fit_stations(1, 2000, False, PipelineParams(), ["kinect"], {"gap_range": (-2.0, 0.3)})
    line = capsys.readouterr().out
    assert line.startswith("frame_station_slope = ") and "of 2 main rooms" in line
    assert float(line.split("= ")[1].split(":")[0]) <= 0.0
