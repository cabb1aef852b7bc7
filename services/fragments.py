"""A fragment is a point cloud (PLY/PCD) or an RGB-D frame: one entry for its layout.

Front ends decode a fragment (:mod:`services.uploads`, :mod:`cli.frames`) and call these, so
the layout stage, the CLI's exports and the service's records treat both kinds alike.
"""

from __future__ import annotations

from typing import TypeAlias

from schemas.params import PipelineParams
from services.frame_layout import estimate_rgbd_layout, frame_points
from services.rgbd import RgbdFrame, valid_depth
from services.types import FloatArray, LocalLayout, ParsedFragment, ProgressFn

__all__ = [
    "Fragment",
    "dropped_count",
    "fragment_format",
    "fragment_layout",
    "fragment_points",
    "reading_count",
]

Fragment: TypeAlias = ParsedFragment | RgbdFrame
"""A decoded fragment: a cloud's finite points, or an RGB-D frame."""


def fragment_layout(
    fragment: Fragment,
    params: PipelineParams = PipelineParams(),
    progress: ProgressFn | None = None,
) -> LocalLayout:
    """Local layout of a cloud (:func:`services.pipeline.estimate_layout`) or of a frame
    (:func:`services.frame_layout.estimate_rgbd_layout`)."""
    if isinstance(fragment, RgbdFrame):
        return estimate_rgbd_layout(fragment, params, progress)
    from services.pipeline import estimate_layout

    return estimate_layout(fragment.points, params, progress)


def fragment_points(fragment: Fragment, params: PipelineParams = PipelineParams()) -> FloatArray:
    """(N, 3) float64 points in the fragment's local frame (a frame's: strided, optical)."""
    if isinstance(fragment, RgbdFrame):
        return frame_points(fragment, params)
    return fragment.points


def fragment_format(fragment: Fragment) -> str:
    """``"ply"``, ``"pcd"`` or ``"rgbd"``."""
    return "rgbd" if isinstance(fragment, RgbdFrame) else fragment.format


def reading_count(fragment: Fragment, params: PipelineParams = PipelineParams()) -> int:
    """Points of a cloud, or depth readings of a frame within the depth range."""
    if isinstance(fragment, RgbdFrame):
        return int(valid_depth(fragment.depth, params.layout.frame).sum())
    return len(fragment.points)


def dropped_count(fragment: Fragment) -> int:
    """Non-finite points a cloud's file held (dropped); 0 for a frame."""
    return 0 if isinstance(fragment, RgbdFrame) else fragment.dropped_nonfinite
