"""Wire form of a fragment's local layout (stored on Redis between the two job kinds)."""

from __future__ import annotations

import base64
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from services.types import FloatArray, LocalLayout, ManhattanFrame

__all__ = ["LocalLayoutWire", "decode_array", "encode_array"]


def encode_array(array: FloatArray) -> str:
    """Base64 of the array as little-endian float64, row-major (shape travels separately)."""
    return base64.b64encode(np.ascontiguousarray(array, dtype="<f8").tobytes()).decode("ascii")


def decode_array(text: str, columns: int) -> FloatArray:
    """Inverse of :func:`encode_array` for an (M, columns) array."""
    flat = np.frombuffer(base64.b64decode(text), dtype="<f8")
    return flat.reshape(-1, columns).astype(np.float64)


class LocalLayoutWire(BaseModel):
    """A :class:`services.types.LocalLayout` as versioned JSON.

    Boundary points and the footprint are base64 little-endian float64 arrays ((M, 3) and
    (F, 2)) in the aligned frame.
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

    @classmethod
    def from_layout(cls, layout: LocalLayout) -> LocalLayoutWire:
        return cls(
            keypoints=layout.keypoints.tolist(),
            rotation=layout.frame.rotation.tolist(),
            floor_z=layout.frame.floor_z,
            ceiling_z=layout.frame.ceiling_z,
            source_boundary=encode_array(layout.source_boundary),
            target_boundary=encode_array(layout.target_boundary),
            footprint=encode_array(layout.footprint),
        )

    def to_layout(self) -> LocalLayout:
        frame = ManhattanFrame(
            rotation=np.asarray(self.rotation, dtype=np.float64),
            floor_z=self.floor_z,
            ceiling_z=self.ceiling_z,
        )
        return LocalLayout(
            keypoints=np.asarray(self.keypoints, dtype=np.float64).reshape(-1, 2),
            frame=frame,
            source_boundary=decode_array(self.source_boundary, 3),
            target_boundary=decode_array(self.target_boundary, 3),
            footprint=decode_array(self.footprint, 2),
        )
