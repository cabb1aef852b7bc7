"""Redis hash records of fragments and sites, and their conversion to wire models.

Both the API (asyncio) and the workers (threads) read and write the same hashes; the field
names and conversions live here once. Hash values are strings.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from datetime import datetime
from typing import Any, Literal, get_args

from schemas.jobs import FragmentState, PlacementState
from schemas.result import Status
from schemas.service import (
    ErrorDetail,
    FragmentStatus,
    PlacementStatus,
    SiteEvent,
    SiteStatus,
    utc,
)

__all__ = [
    "CLOSED_STATUSES",
    "error_fields",
    "fragment_status",
    "new_fragment_record",
    "placement_status",
    "site_event",
    "site_status",
]

EventKind = Literal["fragment", "placement", "result", "site"]
_RESULT_STATUSES: dict[str, Status] = {status: status for status in get_args(Status)}
CLOSED_STATUSES = ("closed", "ambiguous")  # the main assembly closes a room (loop_closed)


def _float(record: Mapping[str, str], name: str, default: float = 0.0) -> float:
    value = record.get(name)
    return float(value) if value else default


def _time(record: Mapping[str, str], name: str) -> datetime | None:
    value = record.get(name)
    return utc(float(value)) if value else None


def _int(record: Mapping[str, str], name: str, default: int = 0) -> int:
    value = record.get(name)
    return int(value) if value else default


def _error(record: Mapping[str, str], prefix: str = "") -> ErrorDetail | None:
    code = record.get(f"{prefix}error_code")
    if not code:
        return None
    return ErrorDetail(code=code, message=record.get(f"{prefix}error_message", ""))


def error_fields(code: str, message: str, prefix: str = "") -> dict[str, str]:
    """Hash fields recording an error (empty strings clear it)."""
    return {f"{prefix}error_code": code, f"{prefix}error_message": message}


def new_fragment_record(
    *, sha256: str, size_bytes: int, fmt: str, n_points: int, dropped: int, now: float
) -> dict[str, str]:
    """The hash of a freshly accepted fragment, queued for its layout job."""
    return {
        "sha256": sha256,
        "size_bytes": str(size_bytes),
        "format": fmt,
        "n_points": str(n_points),
        "dropped_nonfinite": str(dropped),
        "state": FragmentState.QUEUED.value,
        "stage": "queued",
        "progress": "0",
        "tries": "0",
        "created_at": repr(now),
        "updated_at": repr(now),
        **error_fields("", ""),
    }


def fragment_status(fragment_id: str, record: Mapping[str, str]) -> FragmentStatus:
    """The wire status of one fragment from its hash."""
    return FragmentStatus(
        fragment_id=fragment_id,
        state=FragmentState(record.get("state", FragmentState.QUEUED.value)),
        stage=record.get("stage", ""),
        progress=min(1.0, max(0.0, _float(record, "progress"))),
        error=_error(record),
        tries=_int(record, "tries"),
        sha256=record.get("sha256", ""),
        size_bytes=_int(record, "size_bytes"),
        format=record.get("format", ""),
        n_points=_int(record, "n_points"),
        dropped_nonfinite=_int(record, "dropped_nonfinite"),
        created_at=utc(_float(record, "created_at")),
        updated_at=utc(_float(record, "updated_at")),
    )


def placement_status(record: Mapping[str, str]) -> PlacementStatus:
    """The wire status of a site's placement from the site hash."""
    result_status = _RESULT_STATUSES.get(record.get("result_status", ""))
    result_generation = record.get("result_generation")
    confidence = record.get("result_confidence")
    return PlacementStatus(
        state=PlacementState(record.get("placement_state") or PlacementState.IDLE.value),
        stage=record.get("placement_stage", ""),
        progress=min(1.0, max(0.0, _float(record, "placement_progress"))),
        error=_error(record, "placement_"),
        generation=_int(record, "generation"),
        result_generation=int(result_generation) if result_generation else None,
        result_status=result_status,
        confidence=min(1.0, max(0.0, float(confidence))) if confidence else None,
        alternatives=_int(record, "result_alternatives"),
        loop_closed=record.get("loop_closed") == "1",
        last_placement_at=_time(record, "last_placement_at"),
        started_at=_time(record, "placement_started_at"),
    )


def site_status(
    site_id: str,
    site: Mapping[str, str],
    fragments: list[tuple[str, Mapping[str, str]]],
    *,
    hints: bool = False,
) -> SiteStatus:
    """The wire status of a site from its hash and its fragments' hashes (in order);
    ``hints``: the site has stored hints."""
    return SiteStatus(
        site_id=site_id,
        created_at=utc(_float(site, "created_at")),
        updated_at=utc(_float(site, "updated_at")),
        fragments=[fragment_status(fid, rec) for fid, rec in fragments if rec],
        placement=placement_status(site),
        hints=hints,
    )


def site_event(
    kind: EventKind,
    site_id: str,
    data: Mapping[str, Any],
    *,
    fragment_id: str | None = None,
    generation: int | None = None,
) -> str:
    """The JSON of one :class:`SiteEvent` for the site's channel."""
    event = SiteEvent(
        type=kind,
        site_id=site_id,
        fragment_id=fragment_id,
        generation=generation,
        time=utc(time.time()),
        data=dict(data),
    )
    return event.model_dump_json()
