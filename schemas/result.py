"""The result JSON of the external contract (section 3), schema version 2.

Version 2 adds the status "ambiguous", a calibrated ``confidence`` and ``alternatives``
(the runners-up, each with full poses, floorplan and probability).
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

__all__ = [
    "AlternativeFragmentModel",
    "AlternativeModel",
    "FloorplanModel",
    "FragmentResultModel",
    "LocalLayoutModel",
    "ResultModel",
    "RoomModel",
    "Status",
]

SCHEMA_VERSION: Literal[2] = 2

Status = Literal["closed", "ambiguous", "open", "failed"]

Pose = list[list[float]]


class _Open(BaseModel):
    # Clients ignore unknown fields, so the result may carry extras (diagnostics).
    model_config = ConfigDict(extra="allow")


class LocalLayoutModel(_Open):
    """A fragment's local layout as the result reports it."""

    keypoints: list[list[float]] = Field(
        default_factory=list,
        description="wall keypoints, source to target, fragment-local frame, floor height",
    )


class FragmentResultModel(_Open):
    """One input fragment's entry of the result: whether and where it was placed."""

    id: str
    placed: bool
    pose: Pose | None = Field(
        None, description="4x4 row-major, maps fragment-local points to the site frame"
    )
    loop_index: int | None = Field(None, description="position in the counter-clockwise loop")
    confidence: float | None = Field(
        None,
        ge=0.0,
        le=1.0,
        description="probability that this fragment's pose is right (relative to the main "
        "assembly's first fragment): the main assembly's probability plus that of every "
        "alternative placing it the same way; null when no room was closed",
    )
    local_layout: LocalLayoutModel = Field(default_factory=LocalLayoutModel)


class RoomModel(_Open):
    """A closed room of the floorplan, in the site frame."""

    id: str
    polygon: list[list[float]] = Field(description="counter-clockwise, first vertex not repeated")
    floor_z: float = 0.0
    ceiling_z: float | None = None


class FloorplanModel(_Open):
    """The rooms found (none unless the result is closed or ambiguous)."""

    rooms: list[RoomModel] = Field(default_factory=list)


class AlternativeFragmentModel(_Open):
    """A fragment's pose in an alternative assembly."""

    id: str
    pose: Pose = Field(description="4x4 row-major, fragment-local -> site frame")
    loop_index: int | None = None


class AlternativeModel(_Open):
    """A runner-up assembly: another room the fragments close into."""

    probability: float = Field(ge=0.0, le=1.0, description="probability that this one is right")
    fragments: list[AlternativeFragmentModel] = Field(default_factory=list)
    floorplan: FloorplanModel = Field(default_factory=FloorplanModel)


class ResultModel(_Open):
    """The result of placing a site's fragments (contract section 3)."""

    schema_version: Literal[2] = SCHEMA_VERSION
    status: Status
    confidence: float = Field(
        0.0, ge=0.0, le=1.0, description="calibrated probability that the main assembly is right"
    )
    fragments: list[FragmentResultModel] = Field(default_factory=list)
    floorplan: FloorplanModel = Field(default_factory=FloorplanModel)
    alternatives: list[AlternativeModel] = Field(
        default_factory=list, description="runners-up, most probable first"
    )
    diagnostics: dict[str, Any] = Field(default_factory=dict)
