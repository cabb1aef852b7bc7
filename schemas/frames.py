"""RGB-D frames (contract v2, section 1): the intrinsics file, frame parameters, archive limits.

An RGB-D frame is ``depth.png`` (16-bit, one channel; value / depth_scale = meters along the
optical axis, 0 = no reading), ``intrinsics.json`` (:class:`IntrinsicsModel`) and optionally
``color.png`` or ``color.jpg`` of the same size; over HTTP and zenoh one zip archive of them.
"""

from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = ["ArchiveLimits", "FrameParams", "IntrinsicsModel"]


class IntrinsicsModel(BaseModel):
    """``intrinsics.json``: pinhole camera of the depth image (pixels), depth units.

    Unknown extra fields are ignored (datasets carry more, e.g. a distortion model).
    """

    model_config = ConfigDict(frozen=True, extra="ignore")

    width: int = Field(gt=0, le=16384, description="image width, pixels")
    height: int = Field(gt=0, le=16384, description="image height, pixels")
    fx: float = Field(gt=0, description="focal length along x, pixels")
    fy: float = Field(gt=0, description="focal length along y, pixels")
    cx: float = Field(description="principal point x, pixels")
    cy: float = Field(description="principal point y, pixels")
    depth_scale: float = Field(1000.0, gt=0, description="depth value per meter")

    @model_validator(mode="after")
    def _consistent(self) -> IntrinsicsModel:
        values = (self.fx, self.fy, self.cx, self.cy, self.depth_scale)
        if not all(math.isfinite(v) for v in values):
            raise ValueError("fx, fy, cx, cy and depth_scale must be finite")
        if not (0.0 <= self.cx <= self.width and 0.0 <= self.cy <= self.height):
            raise ValueError(
                f"principal point ({self.cx}, {self.cy}) lies outside the "
                f"{self.width}x{self.height} image"
            )
        return self


class FrameParams(BaseModel):
    """How a frame becomes a local layout, and when overlapping frames are merged."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    min_depth: float = Field(0.1, gt=0, description="readings nearer than this are dropped, m")
    max_depth: float = Field(10.0, gt=0, description="readings farther than this are dropped, m")
    stride: int = Field(
        4,
        ge=1,
        le=16,
        description="largest pixel stride over rows and columns (smaller for wide-angle or "
        "small images, so points stay about 3 cm apart at 4 m)",
    )
    max_voxels: int = Field(
        10_000,
        ge=100,
        description="most voxels a frame is thinned to: a wider view (a wide-angle camera sees "
        "about twice the surface of a Kinect's) is thinned with larger voxels, so a 640x480 "
        "frame takes about as long to lay out whatever its lens",
    )
    max_pitch_deg: float = Field(
        60.0,
        gt=0,
        lt=90,
        description="steepest downward look a frame is levelled from: when under a tenth "
        "of its normals lie within the plane search's tilt limit (manhattan.max_tilt_deg), "
        "the well-supported normal direction within this angle of level up that leans back "
        "towards the camera, nearest to level up, is taken as the floor's",
    )
    camera_height: float = Field(
        1.3,
        gt=0,
        description="camera height over the floor assumed when a frame shows too "
        "little floor to measure it, m",
    )
    min_floor_share: float = Field(
        0.03,
        ge=0,
        le=1,
        description="share of a frame's thinned points that must lie on the "
        "floor plane for its height to be measured",
    )
    max_pixels: int = Field(
        16_777_216, ge=1, description="largest depth image (width x height) decoded"
    )
    orb_features: int = Field(1500, ge=50, description="ORB keypoints per colour image")
    match_ratio: float = Field(0.8, gt=0, le=1, description="Lowe's ratio test on ORB matches")
    min_matches: int = Field(
        25, ge=3, description="depth-backed ORB matches a pair needs to be tried"
    )
    merge_inlier_share: float = Field(
        0.5,
        gt=0,
        le=1,
        description="share of the matches a rigid fit must explain for two frames to merge",
    )
    min_inliers: int = Field(20, ge=3, description="matches the rigid fit must explain, at least")
    inlier_distance: float = Field(
        0.05, gt=0, description="3D distance under which a match agrees with the fit, m"
    )
    ransac_iterations: int = Field(400, ge=10, description="rigid-fit RANSAC iterations")
    merge_stations: bool = Field(
        False,
        description="merge single frames whose view ranges say they share a camera (a robot "
        "turning on the spot; placement.station_view_* decide) as ORB-merged frames are "
        "(off: no better on frames overlapping by metres, see the README)",
    )
    corner_price: float = Field(
        0.2,
        ge=0,
        description="covered wall a corner must add to a frame's chain to be worth it, m "
        "(a cloud's chain: 0.3; a frame sees a corner's walls shorter, at its view's edges)",
    )

    @model_validator(mode="after")
    def _range(self) -> FrameParams:
        if self.max_depth <= self.min_depth:
            raise ValueError("max_depth must exceed min_depth")
        return self


class ArchiveLimits(BaseModel):
    """Bounds on a frame's zip archive, checked on the declared sizes and while inflating."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    max_entries: int = Field(8, ge=1, description="most entries (files and folders)")
    max_entry_bytes: int = Field(
        64 * 1024 * 1024, ge=1, description="largest uncompressed entry, bytes"
    )
    max_total_bytes: int = Field(
        128 * 1024 * 1024, ge=1, description="largest uncompressed total, bytes"
    )
    max_ratio: float = Field(
        100.0, ge=1, description="largest uncompressed / compressed size (above ratio_floor)"
    )
    ratio_floor: int = Field(
        1024 * 1024, ge=0, description="uncompressed bytes any archive may reach, at any ratio"
    )

    def budget(self, compressed: int) -> int:
        """Uncompressed bytes an archive of ``compressed`` bytes may inflate to."""
        by_ratio = max(int(compressed * self.max_ratio), self.ratio_floor)
        return min(self.max_total_bytes, by_ratio)
