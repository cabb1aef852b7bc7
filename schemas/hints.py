"""What a fleet may already know about a site (contract section 2): the hints JSON.

Every part is optional. Prior poses map fragment-local points to the hints' frame; when any
is given, the result is expressed in that frame. Hints are evidence, not orders: the
placement reports those the scans contradict instead of obeying them blindly.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from schemas.ids import is_valid_id

__all__ = ["FragmentPrior", "HintsModel"]

_ORTHONORMAL_TOLERANCE = 1e-3


class _Strict(BaseModel):
    # Unknown fields are refused (422): a typo must not silently drop a hint.
    model_config = ConfigDict(extra="forbid", frozen=True)


class FragmentPrior(_Strict):
    """A prior of one fragment's pose, with its standard deviations."""

    pose: list[list[float]] = Field(
        description="4x4 row-major, fragment-local -> hints frame (rotation orthonormal, det +1)"
    )
    sigma_xy: float = Field(1.0, gt=0.0, le=1000.0, description="horizontal std. dev., m")
    sigma_yaw_deg: float = Field(
        10.0, gt=0.0, le=360.0, description="std. dev. of the yaw about the vertical, degrees"
    )

    @field_validator("pose")
    @classmethod
    def _rigid(cls, pose: list[list[float]]) -> list[list[float]]:
        matrix = np.asarray(pose, dtype=np.float64)
        if matrix.shape != (4, 4) or not np.all(np.isfinite(matrix)):
            raise ValueError("pose must be a 4x4 matrix of finite numbers")
        rotation = matrix[:3, :3]
        if not np.allclose(rotation @ rotation.T, np.eye(3), atol=_ORTHONORMAL_TOLERANCE):
            raise ValueError("the pose's rotation part is not orthonormal")
        if np.linalg.det(rotation) < 0.0:
            raise ValueError("the pose's rotation part is a reflection (det -1)")
        if not np.allclose(matrix[3], [0.0, 0.0, 0.0, 1.0]):
            raise ValueError("the pose's last row must be [0, 0, 0, 1]")
        return pose


class HintsModel(_Strict):
    """Prior poses, known neighbour pairs and known loop order of a site's fragments."""

    schema_version: Literal[1] = 1
    frame: str = Field("map", min_length=1, max_length=64, description="name of the hints frame")
    fragments: dict[str, FragmentPrior] = Field(default_factory=dict)
    neighbours: list[tuple[str, str]] = Field(
        default_factory=list, description="pairs adjacent in the room's wall loop"
    )
    order: list[str] = Field(
        default_factory=list, description="fragments known to follow each other CCW"
    )

    @model_validator(mode="after")
    def _valid_ids(self) -> HintsModel:
        ids = [*self.fragments, *self.order, *(i for pair in self.neighbours for i in pair)]
        bad = sorted({i for i in ids if not is_valid_id(i)})
        if bad:
            raise ValueError(f"invalid fragment ids: {', '.join(bad[:5])}")
        if len(set(self.order)) != len(self.order):
            raise ValueError("order lists a fragment twice")
        if any(a == b for a, b in self.neighbours):
            raise ValueError("a fragment cannot neighbour itself")
        return self

    @property
    def has_priors(self) -> bool:
        """True when any prior pose is given (the result is then in the hints' frame)."""
        return bool(self.fragments)
