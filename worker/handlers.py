"""The two job handlers: a fragment's local layout, and a site's global placement.

Handlers are idempotent: a job delivered twice (at-least-once) finds its work done, or its
fragment replaced or deleted (``sha256`` mismatch), or its site deleted, and changes nothing
(see :mod:`worker.updates` for the conditional writes).
"""

from __future__ import annotations

import logging
import time
import zlib
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from pydantic import ValidationError

from schemas.hints import HintsModel
from schemas.jobs import FragmentState, LayoutJob, PlacementJob, PlacementState
from schemas.layout import LocalLayoutWire
from schemas.result import FragmentResultModel, ResultModel
from schemas.service import ErrorDetail
from services.types import LocalLayout
from store.jobs import finish_placement, placement_flag_ttl_ms
from store.layouts import layout_from_wire, layout_to_wire
from store.records import error_fields
from worker.updates import (
    JobContext,
    JobTimeoutError,
    Progress,
    set_site_fields,
    store_result,
    update_fragment,
    update_placement,
)

__all__ = [
    "HANDLERS",
    "Handler",
    "JobContext",
    "JobReport",
    "JobTimeoutError",
    "LayoutHandler",
    "PlacementHandler",
    "Progress",
]

log = logging.getLogger(__name__)

_PENDING = {FragmentState.QUEUED.value, FragmentState.RUNNING.value}

JobReport = dict[str, Any]
"""What a job did, logged as fields of its one log line: at least ``outcome``."""


class Handler(Protocol):
    """One job kind: run it (returning its report), or record that it failed (``final``: no
    more tries)."""

    def run(self, ctx: JobContext, job: LayoutJob | PlacementJob) -> JobReport:
        """Run the job; the report is logged."""
        ...

    def failed(
        self, ctx: JobContext, job: LayoutJob | PlacementJob, error: ErrorDetail, final: bool
    ) -> None:
        """Record that the job failed with ``error`` (``final``: it will not be tried again)."""
        ...


_J = TypeVar("_J", LayoutJob, PlacementJob)


def _expect(job: LayoutJob | PlacementJob, kind: type[_J]) -> _J:
    if not isinstance(job, kind):
        raise TypeError(f"{kind.__name__} handler got a {type(job).__name__}")
    return job


class LayoutHandler:
    """Decode the stored bytes (a cloud or an RGB-D frame) and estimate the fragment's
    local layout."""

    def run(self, ctx: JobContext, job: LayoutJob | PlacementJob) -> JobReport:
        """Lay out the stored fragment and store its layout; queue the site's placement."""
        job = _expect(job, LayoutJob)
        from services.fragments import fragment_layout, reading_count
        from services.uploads import decode_upload

        site, fid, sha = job.site_id, job.fragment_id, job.sha256
        record = ctx.client.hgetall(ctx.keys.fragment(site, fid))
        if record.get("sha256") != sha:
            return {"outcome": "stale"}  # the fragment was replaced or deleted
        if record.get("state") == FragmentState.DONE.value:
            return {"outcome": "already_done"}  # redelivered after its writes
        running = FragmentState.RUNNING.value
        fields = {"state": running, "stage": "decode", "progress": "0", "tries": str(ctx.tries)}
        if not update_fragment(ctx, site, fid, sha, fields):
            return {"outcome": "stale"}
        blob = ctx.raw.get(ctx.keys.fragment_data(site, fid))
        if not isinstance(blob, bytes):
            return {"outcome": "stale"}
        parsed = decode_upload(zlib.decompress(blob), ctx.params, ctx.settings.archive_limits())
        progress = Progress(ctx, site, (fid, sha))
        layout = fragment_layout(parsed, ctx.params, progress=progress)
        wire = layout_to_wire(layout).model_dump_json()
        done = {"state": FragmentState.DONE.value, "stage": "done", "progress": "1"}
        done.update(error_fields("", ""))
        update_fragment(ctx, site, fid, sha, done, layout=wire, place=True)
        return {
            "outcome": "done",
            "points": reading_count(parsed, ctx.params),
            "keypoints": len(layout.keypoints),
        }

    def failed(
        self, ctx: JobContext, job: LayoutJob | PlacementJob, error: ErrorDetail, final: bool
    ) -> None:
        """Mark the fragment failed (``final``) or queued for another try."""
        job = _expect(job, LayoutJob)
        state = FragmentState.FAILED if final else FragmentState.QUEUED
        fields = {"state": state.value, "stage": "failed" if final else "retrying"}
        fields.update(error_fields(error.code, error.message))
        update_fragment(ctx, job.site_id, job.fragment_id, job.sha256, fields, place=final)


@dataclass(frozen=True)
class _SiteSnapshot:
    generation: int
    created: str | None  # the site hash's created_at (None: the site does not exist)
    fragments: list[tuple[str, dict[str, str]]]  # upload order
    layouts: dict[str, str]  # fragment id -> LocalLayoutWire JSON, of done fragments
    hints: str | None  # HintsModel JSON


def _snapshot(ctx: JobContext, site_id: str) -> _SiteSnapshot:
    keys = ctx.keys
    with ctx.client.pipeline(transaction=True) as pipe:
        pipe.hmget(keys.site(site_id), "generation", "created_at")
        pipe.zrange(keys.fragments(site_id), 0, -1)
        pipe.get(keys.hints(site_id))
        (generation, created), ids, hints = pipe.execute()
    with ctx.client.pipeline(transaction=False) as pipe:
        for fid in ids:
            pipe.hgetall(keys.fragment(site_id, fid))
        for fid in ids:
            pipe.get(keys.fragment_layout(site_id, fid))
        replies = pipe.execute()
    records = replies[: len(ids)]
    fragments = [(fid, rec) for fid, rec in zip(ids, records, strict=True) if rec]
    layouts = {
        fid: raw
        for fid, rec, raw in zip(ids, records, replies[len(ids) :], strict=True)
        if rec.get("state") == FragmentState.DONE.value and raw
    }
    return _SiteSnapshot(int(generation or 0), created, fragments, layouts, hints)


def _hints(site_id: str, raw: str | None) -> HintsModel | None:
    """The stored hints; unreadable ones (written by a newer version) are left out."""
    if raw is None:
        return None
    try:
        return HintsModel.model_validate_json(raw)
    except ValidationError as exc:
        log.warning("site %s: stored hints ignored, not valid: %s", site_id, exc)
        return None


def _failed_result(fragments: list[tuple[str, dict[str, str]]]) -> ResultModel:
    reasons = {fid: rec.get("error_code", "") for fid, rec in fragments}
    return ResultModel(
        status="failed",
        fragments=[FragmentResultModel(id=fid, placed=False) for fid, _ in fragments],
        diagnostics={"reason": "no fragment has a usable local layout", "errors": reasons},
    )


def _place(ctx: JobContext, site_id: str, snap: _SiteSnapshot) -> ResultModel:
    from services.pipeline import place_site

    if not snap.layouts:
        return _failed_result(snap.fragments)
    layouts: dict[str, LocalLayout] = {
        fid: layout_from_wire(LocalLayoutWire.model_validate_json(raw))
        for fid, raw in snap.layouts.items()
    }
    progress = Progress(ctx, site_id, None)
    hints = _hints(site_id, snap.hints)
    result: ResultModel = place_site(layouts, ctx.params, progress=progress, hints=hints)
    return result


def _result_fields(result: ResultModel) -> JobReport:
    """What the log says of a placement: status, confidence, fragments placed of all."""
    return {
        "status": result.status,
        "confidence": round(result.confidence, 4),
        "placed": sum(1 for f in result.fragments if f.placed),
        "fragments": len(result.fragments),
        "alternatives": len(result.alternatives),
    }


class PlacementHandler:
    """Place the site's laid-out fragments; coalesced so one runs per site at a time."""

    def run(self, ctx: JobContext, job: LayoutJob | PlacementJob) -> JobReport:
        """Place the site's laid-out fragments and store the result (nothing when superseded,
        the site is gone or layouts are still pending)."""
        job = _expect(job, PlacementJob)
        site_id, flag = job.site_id, ctx.keys.placement_flag(job.site_id)
        holder = ctx.client.get(flag)
        if holder is not None and holder != job.job_id:
            return {"outcome": "superseded", "by": holder}
        if not ctx.client.exists(ctx.keys.site(site_id)):
            return {"outcome": "site_deleted"}
        ctx.client.set(flag, job.job_id, px=placement_flag_ttl_ms(ctx.settings))
        snap = _snapshot(ctx, site_id)
        set_site_fields(ctx, site_id, {"placement_generation": str(snap.generation)})
        report: JobReport = {"outcome": "done", "generation": snap.generation}
        if snap.created is None:  # deleted meanwhile: write nothing; the flag is released
            report["outcome"] = "site_deleted"
        elif any(rec.get("state") in _PENDING for _, rec in snap.fragments):
            self._wait_for_layouts(ctx, site_id)
            report["outcome"] = "waiting_for_layouts"
        elif not snap.fragments:
            self._clear(ctx, site_id)
            report["outcome"] = "cleared"
        else:
            update_placement(
                ctx,
                site_id,
                placement_state=PlacementState.RUNNING.value,
                placement_stage="placement",
                placement_progress="0",
                placement_started_at=repr(time.time()),
            )
            result = _place(ctx, site_id, snap)
            store_result(ctx, site_id, snap.generation, result, site_created=snap.created)
            report.update(_result_fields(result))
        finish_placement(ctx.client, ctx.keys, ctx.settings, job, snap.generation)
        return report

    @staticmethod
    def _wait_for_layouts(ctx: JobContext, site_id: str) -> None:
        # The pending fragments request a placement when their layout ends.
        placed = ctx.client.hget(ctx.keys.site(site_id), "result_generation")
        state = PlacementState.DONE if placed else PlacementState.IDLE
        update_placement(
            ctx, site_id, placement_state=state.value, placement_stage="waiting_for_layouts"
        )

    @staticmethod
    def _clear(ctx: JobContext, site_id: str) -> None:
        # Every fragment was deleted: nothing is placed any more.
        ctx.client.delete(ctx.keys.result(site_id))
        ctx.client.hdel(
            ctx.keys.site(site_id),
            "result_generation",
            "result_status",
            "result_confidence",
            "result_alternatives",
            "loop_closed",
            "last_placement_at",
        )
        update_placement(
            ctx, site_id, placement_state=PlacementState.IDLE.value, placement_stage=""
        )

    def failed(
        self, ctx: JobContext, job: LayoutJob | PlacementJob, error: ErrorDetail, final: bool
    ) -> None:
        """Mark the placement failed (``final``) or queued for another try."""
        job = _expect(job, PlacementJob)
        state = PlacementState.FAILED if final else PlacementState.QUEUED
        fields = {"placement_state": state.value, "placement_stage": "failed" if final else ""}
        update_placement(
            ctx, job.site_id, **fields, **error_fields(error.code, error.message, "placement_")
        )
        if final:
            started = ctx.client.hget(ctx.keys.site(job.site_id), "placement_generation")
            finish_placement(ctx.client, ctx.keys, ctx.settings, job, int(started or 0))


HANDLERS: dict[str, Handler] = {"layout": LayoutHandler(), "placement": PlacementHandler()}
