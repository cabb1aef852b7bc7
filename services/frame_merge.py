"""Merging overlapping RGB-D frames before layout (paper supplement, "RGB-D images").

Two frames overlap when their colour images share ORB features whose depths agree on one
rigid motion: matches (ratio test) with a reading in both depth images become 3D pairs, a
seeded RANSAC fits the motion (Kabsch on three pairs, refitted on the inliers) and the frames
merge when the fit explains at least ``merge_inlier_share`` of the matches and
``min_inliers`` of them. Many matches that agree on no motion (repeated texture, a moved
object) refuse the merge. Frames joined by accepted pairs form a group, posed in the optical
frame of its first member (as :func:`services.registration.premerge` groups clouds), and are
laid out as one fragment.

Frames of one station whose plain walls give ORB nothing are grouped by their views instead
(:func:`station_groups`): the same directions meet the same walls at the same distances.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from schemas.frames import FrameParams
from schemas.params import PipelineParams, PlacementParams
from schemas.result import LocalLayoutModel, ResultModel
from services.frame_layout import FrameCamera, estimate_frame_layout, frame_points
from services.placement.pieces import rot90
from services.rgbd import RgbdFrame, valid_depth
from services.types import FloatArray, LocalLayout
from services.view_ranges import station_mates

__all__ = [
    "FrameFeatures",
    "FrameGroup",
    "PairMatch",
    "expand_frame_groups",
    "frame_features",
    "group_frames",
    "group_layout",
    "match_frames",
    "station_groups",
]


_DEFAULTS = FrameParams()


@dataclass(frozen=True)
class FrameFeatures:
    """ORB features of a frame that have a depth reading.

    points: (F, 3) float64, optical frame; descriptors: (F, 32) uint8.
    """

    points: FloatArray
    descriptors: NDArray[np.uint8]


@dataclass(frozen=True)
class PairMatch:
    """What matching two frames found. transform: (4, 4) the second frame's optical frame
    -> the first's (None when no motion was fitted); merged: the pair passes the test."""

    matches: int
    inliers: int
    transform: FloatArray | None
    merged: bool


@dataclass(frozen=True)
class FrameGroup:
    """Frames laid out as one fragment: member id -> (4, 4) its optical frame -> the
    anchor's (the anchor's own is the identity)."""

    anchor_id: str
    transforms: dict[str, FloatArray]


def frame_features(frame: RgbdFrame, params: FrameParams = _DEFAULTS) -> FrameFeatures:
    """ORB keypoints of the colour image with a valid depth under them (none without
    colour)."""
    empty = FrameFeatures(np.zeros((0, 3)), np.zeros((0, 32), dtype=np.uint8))
    if frame.color is None:
        return empty
    gray = cv2.cvtColor(frame.color, cv2.COLOR_RGB2GRAY)
    orb = cv2.ORB_create(nfeatures=params.orb_features)  # type: ignore[attr-defined]
    keypoints, descriptors = orb.detectAndCompute(gray, None)
    if descriptors is None or not keypoints:
        return empty
    uv = np.array([kp.pt for kp in keypoints])
    col = np.clip(np.rint(uv[:, 0]).astype(np.int64), 0, frame.shape[1] - 1)
    row = np.clip(np.rint(uv[:, 1]).astype(np.int64), 0, frame.shape[0] - 1)
    z = frame.depth[row, col].astype(np.float64)
    ok = valid_depth(frame.depth[row, col], params)
    k = frame.intrinsics
    points = np.column_stack([(uv[:, 0] - k.cx) * z / k.fx, (uv[:, 1] - k.cy) * z / k.fy, z])
    return FrameFeatures(points[ok], np.asarray(descriptors, dtype=np.uint8)[ok])


def _rigid(a: FloatArray, b: FloatArray) -> FloatArray:
    """(4, 4) least-squares rigid motion taking points b (M, 3) onto a (M, 3) (Kabsch)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((b - cb).T @ (a - ca))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rotation, ca - rotation @ cb
    return out


def _ransac(a: FloatArray, b: FloatArray, params: FrameParams) -> tuple[FloatArray, int]:
    """Motion b -> a with the most pairs within the inlier distance, refitted: (4x4, count)."""
    rng = np.random.default_rng(0)
    samples = rng.integers(0, len(a), size=(params.ransac_iterations, 3))
    tolerance = params.inlier_distance * (1.0 + np.square(a[:, 2] / 3.0))  # noise ~ depth^2
    best = np.zeros(len(a), dtype=bool)
    for triple in samples:
        if len(set(triple.tolist())) < 3:
            continue
        motion = _rigid(a[triple], b[triple])
        inliers = np.linalg.norm(b @ motion[:3, :3].T + motion[:3, 3] - a, axis=1) < tolerance
        if inliers.sum() > best.sum():
            best = inliers
    if best.sum() < 3:
        return np.eye(4), 0
    motion = _rigid(a[best], b[best])
    residual = np.linalg.norm(b @ motion[:3, :3].T + motion[:3, 3] - a, axis=1)
    return motion, int(np.count_nonzero(residual < tolerance))


def match_frames(
    first: FrameFeatures, second: FrameFeatures, params: FrameParams = _DEFAULTS
) -> PairMatch:
    """ORB matches of two frames verified in 3D; see the module's description."""
    if len(first.points) < 3 or len(second.points) < 3:
        return PairMatch(0, 0, None, False)
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
    pairs: Sequence[Any] = matcher.knnMatch(first.descriptors, second.descriptors, k=2)
    good = [
        (m[0].queryIdx, m[0].trainIdx)
        for m in pairs
        if len(m) == 2 and m[0].distance < params.match_ratio * m[1].distance
    ]
    if len(good) < params.min_matches:
        return PairMatch(len(good), 0, None, False)
    index = np.array(good)
    a, b = first.points[index[:, 0]], second.points[index[:, 1]]
    motion, inliers = _ransac(a, b, params)
    merged = inliers >= params.min_inliers and inliers >= params.merge_inlier_share * len(good)
    return PairMatch(len(good), inliers, motion, merged)


def group_frames(
    frames: Mapping[str, RgbdFrame], params: FrameParams = _DEFAULTS
) -> list[FrameGroup]:
    """Groups of overlapping frames (singletons for the rest), in the input order; each
    group's anchor is its first frame."""
    ids = list(frames)
    features = {fid: frame_features(frames[fid], params) for fid in ids}
    edges: dict[str, dict[str, FloatArray]] = {fid: {} for fid in ids}
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            found = match_frames(features[a], features[b], params)
            if found.merged and found.transform is not None:
                edges[a][b] = found.transform  # b -> a
                edges[b][a] = np.asarray(np.linalg.inv(found.transform), dtype=np.float64)
    return _connected(ids, edges)


def _connected(
    ids: Sequence[str], edges: Mapping[str, Mapping[str, FloatArray]]
) -> list[FrameGroup]:
    """The groups ``edges`` (id -> other id -> (4, 4) the other's frame -> the id's) join,
    in the order of ``ids``, each anchored at its first id."""
    groups, seen = [], set()
    for anchor in ids:
        if anchor in seen:
            continue
        transforms = {anchor: np.eye(4)}
        queue = [anchor]
        while queue:
            current = queue.pop(0)
            for other, motion in edges[current].items():
                if other not in transforms:
                    transforms[other] = transforms[current] @ motion
                    queue.append(other)
        seen |= set(transforms)
        groups.append(FrameGroup(anchor, transforms))
    return groups


def station_groups(
    layouts: Mapping[str, LocalLayout], params: PlacementParams = PlacementParams()
) -> list[FrameGroup]:
    """Groups of single frames whose views say they share a camera
    (:func:`services.view_ranges.station_mates`; singletons for the rest), in the order of
    ``layouts``; each group's anchor is its first frame.

    Two frames of one station are one rotation apart about their common camera: the quarter
    turn between their aligned frames that the view ranges found, between the Manhattan
    frames each was levelled and squared to (``LocalLayout.frame.rotation``, optical ->
    aligned), with no translation.
    """
    mates = station_mates(layouts, params)
    edges: dict[str, dict[str, FloatArray]] = {fid: {} for fid in layouts}
    for first, found in mates.items():
        for second, turn in found.items():
            motion = np.eye(4)  # the second's optical frame -> the first's
            motion[:3, :3] = (
                layouts[first].frame.rotation.T
                @ _quarter_turn(turn)
                @ layouts[second].frame.rotation
            )
            edges[first][second] = motion
    return _connected(list(layouts), edges)


def _quarter_turn(turns: int) -> FloatArray:
    """(3, 3) rotation by ``turns`` quarter turns about the aligned frame's up axis."""
    turn = np.eye(3)
    turn[:2, :2] = rot90(turns)
    return turn


def group_layout(
    group: FrameGroup,
    frames: Mapping[str, RgbdFrame],
    params: PipelineParams = PipelineParams(),
) -> LocalLayout:
    """Local layout of a group: its members' points and cameras in the anchor's frame."""
    parts, cameras = [], []
    for fid, motion in group.transforms.items():
        points = frame_points(frames[fid], params)
        parts.append(points @ motion[:3, :3].T + motion[:3, 3])
        cameras.append(FrameCamera(frames[fid].intrinsics, motion))
    return estimate_frame_layout(np.vstack(parts), cameras, params)


def expand_frame_groups(
    result: ResultModel, groups: Sequence[FrameGroup], order: Sequence[str]
) -> ResultModel:
    """One result entry per input frame: members take their group's placement composed with
    their motion, their keypoints in their own optical frame, ``merged_into`` the anchor."""
    by_id = {f.id: f for f in result.fragments}
    entries = dict(by_id)
    for group in groups:
        anchor = by_id.get(group.anchor_id)
        if anchor is None:
            continue
        keypoints = np.asarray(anchor.local_layout.keypoints, dtype=np.float64).reshape(-1, 3)
        for fid, motion in group.transforms.items():
            if fid == group.anchor_id:
                continue
            back = np.linalg.inv(motion)
            pose = None if anchor.pose is None else (np.asarray(anchor.pose) @ motion).tolist()
            entries[fid] = anchor.model_copy(
                update={
                    "id": fid,
                    "pose": pose,
                    "local_layout": LocalLayoutModel(
                        keypoints=(keypoints @ back[:3, :3].T + back[:3, 3]).tolist()
                    ),
                    "merged_into": group.anchor_id,
                }
            )
    return result.model_copy(
        update={"fragments": [entries[fid] for fid in order if fid in entries]}
    )
