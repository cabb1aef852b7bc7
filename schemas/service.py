"""Wire models of the HTTP API and of the events the workers publish (versioned JSON).

Internal records (Redis hashes) are converted to these in :mod:`store.records`; the result
JSON itself is :class:`schemas.result.ResultModel`. Times are ISO 8601 strings in UTC
(``2025-01-31T12:00:00.250000Z``).
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any, Literal

from pydantic import AwareDatetime, BaseModel, ConfigDict, Field

from schemas.jobs import FragmentState, PlacementState
from schemas.result import Status

__all__ = [
    "EVENT_VERSION",
    "ErrorBody",
    "ErrorDetail",
    "FragmentStatus",
    "HealthReply",
    "PendingReply",
    "PlacementStatus",
    "ReadyReply",
    "RobotStatus",
    "SiteEvent",
    "SiteList",
    "SiteStatus",
    "SiteSummary",
    "UploadReply",
    "utc",
]

EVENT_VERSION = 1
Time = AwareDatetime  # serialized as ISO 8601 with its UTC offset


def utc(epoch: float) -> datetime:
    """A unix time (seconds) as an aware UTC datetime.

    Examples
    --------
    >>> utc(0.0).isoformat()
    '1970-01-01T00:00:00+00:00'
    """
    return datetime.fromtimestamp(epoch, tz=UTC)


class _Wire(BaseModel):
    model_config = ConfigDict(frozen=True)


class ErrorDetail(_Wire):
    """What went wrong: a stable code and a message."""

    code: str = Field(description="stable machine-readable identifier", examples=["conflict"])
    message: str = Field(description="human-readable explanation")


class ErrorBody(_Wire):
    """Every 4xx/5xx body: ``{"error": {"code": ..., "message": ...}}``."""

    error: ErrorDetail


class UploadReply(_Wire):
    """Reply to an upload: 202 when new, 200 when the same bytes were already stored."""

    fragment_id: str
    site_id: str
    status: FragmentState = Field(description="the fragment's processing state")
    created: bool = Field(description="false when identical bytes were already stored")
    sha256: str
    size_bytes: int
    format: str = Field(description="ply or pcd")
    n_points: int = Field(description="finite points")
    dropped_nonfinite: int


class FragmentStatus(_Wire):
    """A fragment's processing state, as the site status reports it."""

    fragment_id: str
    state: FragmentState
    stage: str = Field("", description="pipeline stage of the running job")
    progress: float = Field(0.0, ge=0.0, le=1.0)
    error: ErrorDetail | None = Field(None, description="why the fragment failed (or retried)")
    tries: int = 0
    sha256: str
    size_bytes: int
    format: str
    n_points: int
    dropped_nonfinite: int = 0
    created_at: Time = Field(description="when the fragment was accepted, ISO 8601")
    updated_at: Time = Field(description="its last state change, ISO 8601")


class PlacementStatus(_Wire):
    """The state of the site's placement, and what its newest result says."""

    state: PlacementState = PlacementState.IDLE
    stage: str = ""
    progress: float = Field(0.0, ge=0.0, le=1.0)
    error: ErrorDetail | None = None
    generation: int = Field(0, description="changes of the site's set of usable layouts")
    result_generation: int | None = Field(None, description="generation the result is of")
    result_status: Status | None = Field(None, description="status of the newest result")
    confidence: float | None = Field(
        None, ge=0.0, le=1.0, description="the newest result's confidence in its main assembly"
    )
    alternatives: int = Field(0, ge=0, description="runners-up in the newest result")
    loop_closed: bool = Field(
        False, description="the newest result closes a room (status closed or ambiguous)"
    )
    last_placement_at: Time | None = Field(None, description="time of the last result, ISO 8601")
    started_at: Time | None = Field(None, description="when the newest run started, ISO 8601")


class RobotStatus(_Wire):
    """A robot connected over zenoh (its liveliness token), and what it sent to the site."""

    robot_id: str
    connected_since: Time = Field(description="when its liveliness token appeared, ISO 8601")
    fragments: list[str] = Field(
        default_factory=list, description="ids of this site's fragments the robot sent"
    )


class SiteStatus(_Wire):
    """``GET /v1/sites/{site}``: the site's fragments, placement and connected robots."""

    site_id: str
    created_at: Time | None = Field(
        description="first upload or hints, ISO 8601; null only in the event stream of a site "
        "that does not exist yet"
    )
    updated_at: Time | None = Field(description="last upload, hints or deletion, ISO 8601")
    fragments: list[FragmentStatus]
    placement: PlacementStatus
    robots: list[RobotStatus] = Field(
        default_factory=list, description="robots connected over zenoh now (contract 5)"
    )
    hints: bool = Field(False, description="hints are stored (GET /v1/sites/{site}/hints)")


class SiteSummary(_Wire):
    """One site of the site list."""

    site_id: str
    n_fragments: int
    placement: PlacementStatus
    updated_at: Time = Field(description="ISO 8601")


class SiteList(_Wire):
    """``GET /v1/sites``: one page of sites, and how many there are."""

    sites: list[SiteSummary]
    total: int


class PendingReply(_Wire):
    """202 from the result endpoints: nothing has been placed yet."""

    site_id: str
    status: Literal["processing"] = "processing"
    message: str = "fragments are still being processed and nothing has been placed"


class HealthReply(_Wire):
    """``GET /healthz``: the process answers."""

    status: Literal["ok"] = "ok"


class ReadyReply(_Wire):
    """``GET /readyz``: Redis answers and workers are alive."""

    status: Literal["ready"] = "ready"
    redis: Literal["ok"] = "ok"
    workers: int = Field(description="workers with a recent heartbeat")


class SiteEvent(_Wire):
    """A message on a site's Redis channel, forwarded as one server-sent event.

    ``type``: ``fragment`` (state, stage, progress of one fragment; ``data`` a FragmentStatus,
    or ``{"fragment_id", "deleted": true}``), ``placement`` (``data`` a PlacementStatus, with
    the newest result's status and confidence), ``result`` (``data`` the result JSON of the
    contract: status, confidence, alternatives) or ``site`` (``data`` ``{"deleted": true}``:
    the site was deleted; its event stream ends).
    """

    version: Literal[1] = 1
    type: Literal["fragment", "placement", "result", "site"]
    site_id: str
    fragment_id: str | None = None
    generation: int | None = None
    time: Time = Field(description="when the event was published, ISO 8601")
    data: dict[str, Any]
