"""Wire form of a fragment's local layout (stored on Redis between the two job kinds).

The model only: :mod:`store.layouts` converts it from and to :class:`services.types.LocalLayout`.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["Evidence", "LocalLayoutWire"]

Evidence = Literal["cloud", "thin_cloud", "frame"]  # what a local layout rests on


class LocalLayoutWire(BaseModel):
    """A :class:`services.types.LocalLayout` as versioned JSON.

    Boundary points, the footprint, the unchained walls, the cameras and the view ranges are
    base64 little-endian float64 arrays ((M, 3), (F, 2), (W, 2), (C, 2) and (B, 2)) in the
    aligned frame; so are the runner-up chain's boundary points.
    """

    model_config = ConfigDict(frozen=True)

    version: Literal[1] = 1
    keypoints: list[list[float]] = Field(description="(K, 2) aligned frame, source to target")
    rotation: list[list[float]] = Field(description="3x3, aligned = rotation @ local")
    floor_z: float
    ceiling_z: float | None
    source_boundary: str = ""
    target_boundary: str = ""
    footprint: str = ""
    evidence: Evidence = Field(
        "cloud",
        description="what the chain rests on: a cloud, a cloud thinner than the confidence's "
        "calibration saw, or RGB-D frames (the last two calibrated apart)",
    )
    unchained_walls: str = Field(
        "", description="centres of wall cells no wall of the chain runs through (base64)"
    )
    view_angle: float | None = Field(
        None,
        ge=0,
        description="RGB-D frames: the horizontal angle the cameras see across, radians "
        "(summed over merged frames); null for point clouds",
    )
    view_top: float | None = Field(
        None,
        description="RGB-D frames: how high the top of the view reaches at its middle, "
        "radians above level (the highest of merged frames); null for point clouds",
    )
    cameras: str | None = Field(
        None,
        description="RGB-D frames: (C, 2) base64 aligned-frame positions of the cameras' "
        "optical centres, one per merged frame; null for point clouds and for layouts "
        "stored before cameras were kept",
    )
    view_ranges: str | None = Field(
        None,
        description="RGB-D single frames: (B, 2) base64 per half degree of azimuth around the "
        "camera (aligned frame, radians) the horizontal distance of the walls seen, m; null "
        "for point clouds, merged frames and layouts stored before view ranges were kept",
    )
    runner_up: list[list[float]] | None = Field(
        None,
        description="RGB-D frames: (K', 2) aligned frame, the wall graph's second chain where "
        "its two candidates differ, which the placement also tries; null otherwise",
    )
    runner_up_source_boundary: str = Field(
        "", description="(M, 3) base64 boundary points around the runner-up's source"
    )
    runner_up_target_boundary: str = Field(
        "", description="(M, 3) base64 boundary points around the runner-up's target"
    )
