"""The result JSON of the external contract (section 3), schema version 1."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

__all__ = [
    "FloorplanModel",
    "FragmentResultModel",
    "LocalLayoutModel",
    "ResultModel",
    "RoomModel",
]

SCHEMA_VERSION: Literal[1] = 1

Status = Literal["closed", "open", "failed"]


class _Open(BaseModel):
    # Clients ignore unknown fields, so the result may carry extras (diagnostics).
    model_config = ConfigDict(extra="allow")


class LocalLayoutModel(_Open):
    keypoints: list[list[float]] = Field(
        default_factory=list,
        description="wall keypoints, source to target, fragment-local frame, floor height",
    )


class FragmentResultModel(_Open):
    id: str
    placed: bool
    pose: list[list[float]] | None = Field(
        None, description="4x4 row-major, maps fragment-local points to the site frame"
    )
    loop_index: int | None = Field(None, description="position in the counter-clockwise loop")
    local_layout: LocalLayoutModel = Field(default_factory=LocalLayoutModel)


class RoomModel(_Open):
    id: str
    polygon: list[list[float]] = Field(description="counter-clockwise, first vertex not repeated")
    floor_z: float = 0.0
    ceiling_z: float | None = None


class FloorplanModel(_Open):
    rooms: list[RoomModel] = Field(default_factory=list)


class ResultModel(_Open):
    schema_version: Literal[1] = SCHEMA_VERSION
    status: Status
    fragments: list[FragmentResultModel] = Field(default_factory=list)
    floorplan: FloorplanModel = Field(default_factory=FloorplanModel)
    diagnostics: dict[str, Any] = Field(default_factory=dict)
