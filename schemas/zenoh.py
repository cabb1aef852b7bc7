"""Wire models of the zenoh front end (contract section 5 and its additions).

Everything the service and robots exchange over zenoh is JSON from these models, except the
fragment payload (the file's bytes) and the ROS 2 topics (CDR, as rmw_zenoh sends them).
"""

from __future__ import annotations

from typing import Annotated, Literal, get_args

from pydantic import AfterValidator, BaseModel, ConfigDict, Field

from schemas.ids import ID_RULE, is_valid_id
from schemas.result import ResultModel

__all__ = [
    "POSE_STATUSES",
    "PoseStatus",
    "PoseUpdate",
    "RobotTag",
    "SenderRecord",
    "ServiceInfo",
    "pose_updates",
]

PoseStatus = Literal["closed", "ambiguous", "open"]  # result statuses whose poses go out
POSE_STATUSES: tuple[str, ...] = get_args(PoseStatus)


class _Wire(BaseModel):
    model_config = ConfigDict(frozen=True)


def _valid_id(value: str | None) -> str | None:
    if value is not None and not is_valid_id(value):
        raise ValueError(f"an id is {ID_RULE}")
    return value


class PoseUpdate(_Wire):
    """One fragment's pose, published on ``fpj/sites/{site_id}/poses/{fragment_id}``
    (contract section 5, plus the result's confidence)."""

    fragment_id: str
    pose: list[list[float]] = Field(description="4x4 row-major, fragment-local to site frame")
    status: PoseStatus = Field(description="status of the site's result")
    confidence: float = Field(
        0.0, ge=0.0, le=1.0, description="the result's confidence in its main assembly"
    )
    fragment_confidence: float | None = Field(
        None,
        ge=0.0,
        le=1.0,
        description="probability that this fragment's own pose is right (the result's "
        "fragments[].confidence); null when no room closed",
    )


def pose_updates(result: ResultModel) -> list[PoseUpdate]:
    """The pose messages of a result: its placed fragments, with its status and confidence
    (none for a failed result).

    >>> pose_updates(ResultModel(status="failed"))
    []
    """
    if result.status not in POSE_STATUSES:
        return []
    return [
        PoseUpdate(
            fragment_id=f.id,
            pose=f.pose,
            status=result.status,
            confidence=result.confidence,
            fragment_confidence=f.confidence,
        )
        for f in result.fragments
        if f.placed and f.pose is not None
    ]


class ServiceInfo(_Wire):
    """Reply of the queryable ``fpj/service``: what a robot must know before sending."""

    version: Literal[1] = 1
    prefix: str = Field(description="key expression prefix of the service")
    max_upload_bytes: int = Field(description="larger fragments get fragment_too_large")
    max_message_bytes: int = Field(
        description="zenoh drops larger messages without any reply (rx max_message_size)"
    )


class RobotTag(_Wire):
    """Optional attachment of an ingest query or put: UTF-8 JSON of this object.

    ``robot_id`` names the sender (listed in the site status while its liveliness token
    ``fpj/robots/{robot_id}`` is alive); ``token`` is a bearer token of ``FPJ_TOKENS``,
    required when the service has tokens configured.
    """

    model_config = ConfigDict(frozen=True, extra="ignore")

    robot_id: Annotated[str | None, AfterValidator(_valid_id)] = Field(None, description=ID_RULE)
    token: str | None = None


class SenderRecord(_Wire):
    """Who sent a fragment (stored per site); ROS fragments keep their message header."""

    robot_id: str
    via: Literal["zenoh", "ros2"] = "zenoh"
    topic: str | None = None
    stamp_sec: int | None = None
    stamp_nanosec: int | None = None
    frame_id: str | None = None
