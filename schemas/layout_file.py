"""The JSON that ``jigsaw layout`` writes: each fragment's local layout, no placement.

Schema version 1. The keypoints are those of the result's ``local_layout`` (contract
section 3); the Manhattan rotation and the floor and ceiling heights say how the fragment was
levelled, so a client can draw the layout in the fragment's aligned frame.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from schemas.result import LocalLayoutModel

__all__ = ["LayoutFileModel", "LayoutFragmentModel"]


class LayoutFragmentModel(BaseModel):
    """One fragment's local layout, as ``jigsaw layout`` estimated it."""

    model_config = ConfigDict(frozen=True)

    id: str
    local_layout: LocalLayoutModel
    manhattan_rotation: list[list[float]] = Field(
        description="3x3 row-major, aligned = rotation @ fragment-local"
    )
    floor_z: float = Field(description="floor height in the aligned frame, m")
    ceiling_z: float | None = Field(
        description="ceiling height in the aligned frame, m; null when no ceiling was seen"
    )
    walls_found: bool = Field(description="false: no wall chain, the fragment cannot be placed")


class LayoutFileModel(BaseModel):
    """The whole ``jigsaw layout`` output: one entry per usable input fragment, in input order."""

    model_config = ConfigDict(frozen=True)

    schema_version: Literal[1] = 1
    fragments: list[LayoutFragmentModel] = Field(default_factory=list)
