"""Merging overlapping frames: ORB matches verified by a rigid fit on their depths."""

from __future__ import annotations

import math

import numpy as np
import pytest

from schemas.frames import FrameParams
from schemas.params import PipelineParams
from services.fragments import fragment_layout
from services.frame_merge import (
    frame_features,
    group_frames,
    group_layout,
    match_frames,
    station_groups,
)
from services.pipeline import align_fragments
from services.rgbd import RgbdFrame
from services.synthetic.furniture import Furnishing
from services.synthetic.room import Room
from tests.frame_fixtures import render_views

pytestmark = pytest.mark.timeout(60)


@pytest.fixture(scope="module")
def views() -> dict[str, tuple[RgbdFrame, np.ndarray]]:
    """Frames of one room from one station: a and b overlap (20 degrees apart), c looks away."""
    room = Room.from_polygon(np.array([[0.0, 0], [5, 0], [5, 4], [0, 4]]), 2.6)
    pitch = math.degrees(-0.2)
    stances = {
        name: ((2.5, 1.5, 1.3), yaw, pitch)
        for name, yaw in (("a", 90.0), ("b", 110.0), ("c", 270.0))
    }
    return render_views(room, Furnishing(), stances)


def test_overlapping_frames_merge_with_the_true_motion(views) -> None:
    (a, pose_a), (b, pose_b) = views["a"], views["b"]
    found = match_frames(frame_features(a), frame_features(b))
    assert found.merged and found.transform is not None
    truth = np.linalg.inv(pose_a) @ pose_b  # b's optical frame -> a's
    assert np.linalg.norm(found.transform[:3, 3] - truth[:3, 3]) < 0.05
    assert np.abs(found.transform[:3, :3] - truth[:3, :3]).max() < 0.02
    groups = group_frames({"a": a, "b": b, "c": views["c"][0]})
    assert [sorted(g.transforms) for g in groups] == [["a", "b"], ["c"]]
    layout = group_layout(groups[0], {"a": a, "b": b})
    assert layout.ok
    # One camera per merged frame; both stood at the one station.
    assert layout.cameras.shape == (2, 2)
    assert np.linalg.norm(layout.cameras[0] - layout.cameras[1]) < 0.05


def test_frames_looking_away_do_not_merge(views) -> None:
    found = match_frames(frame_features(views["a"][0]), frame_features(views["c"][0]))
    assert not found.merged


def test_matches_whose_depths_disagree_are_refused(views) -> None:
    (a, _), (b, _) = views["a"], views["b"]
    ramp = np.linspace(0.6, 1.6, b.depth.shape[1])[None, :].astype(np.float32)
    warped = RgbdFrame(b.depth * ramp, b.intrinsics, b.color)
    strict = FrameParams(inlier_distance=0.02)
    found = match_frames(frame_features(a, strict), frame_features(warped, strict), strict)
    assert found.matches >= strict.min_matches  # the images still match...
    assert not found.merged  # ...but no rigid motion explains their depths


def test_frames_without_colour_have_no_features(views) -> None:
    a = views["a"][0]
    assert len(frame_features(RgbdFrame(a.depth, a.intrinsics)).points) == 0


@pytest.mark.parametrize("yaws", [(90.0, 110.0), (200.0, 245.0)])  # a quarter turn apart
def test_frames_of_one_station_group_by_their_views_with_the_true_motion(yaws) -> None:
    room = Room.from_polygon(np.array([[0.0, 0], [5, 0], [5, 4], [0, 4]]), 2.6)
    stances = {
        name: ((2.5, 1.5, 1.3), yaw, math.degrees(-0.2))
        for name, yaw in zip(("a", "b", "c"), (*yaws, yaws[0] + 180.0), strict=True)
    }
    views = render_views(room, Furnishing(), stances)
    plain = {name: RgbdFrame(frame.depth, frame.intrinsics) for name, (frame, _) in views.items()}
    groups = station_groups({name: fragment_layout(frame) for name, frame in plain.items()})
    assert [sorted(g.transforms) for g in groups] == [["a", "b"], ["c"]]
    truth = np.linalg.inv(views["a"][1]) @ views["b"][1]  # b's optical frame -> a's
    motion = groups[0].transforms["b"]
    assert np.abs(motion[:3, :3] - truth[:3, :3]).max() < 0.03  # within 2 degrees
    assert np.allclose(motion[:3, 3], 0.0) and np.linalg.norm(truth[:3, 3]) < 1e-6


@pytest.mark.parametrize("merge", [False, True])
def test_align_merges_plain_frames_of_one_station_only_when_asked(views, merge) -> None:
    plain = {name: RgbdFrame(frame.depth, frame.intrinsics) for name, (frame, _) in views.items()}
    params = PipelineParams()
    frame = params.layout.frame.model_copy(update={"merge_stations": merge})
    params = params.model_copy(update={"layout": params.layout.model_copy(update={"frame": frame})})
    result = align_fragments(plain, params).result
    merged = {f["id"]: f.get("merged_into") for f in result.model_dump()["fragments"]}
    assert merged == ({"a": None, "b": "a", "c": None} if merge else dict.fromkeys("abc"))
