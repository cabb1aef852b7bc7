"""Writes of the job handlers to Redis, each followed by its event on the site's channel.

Fragment writes are conditional on the fragment's ``sha256`` (one Lua script), so a deleted or
replaced fragment is never brought back; site writes are conditional on the site's hash
existing, so a deleted site is never brought back either; a placement result is stored only
if its generation is not older than the stored one and the site is the one the job started
on (WATCH/MULTI).
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import redis

from schemas.jobs import PlacementState
from schemas.params import PipelineParams
from schemas.result import ResultModel
from schemas.settings import Settings
from services.errors import JigsawError
from store.connection import hash_fields, watch
from store.jobs import REQUEST_PLACEMENT_FUNCTION, placement_args
from store.keys import Keys
from store.records import (
    CLOSED_STATUSES,
    error_fields,
    fragment_status,
    placement_status,
    site_event,
)

__all__ = [
    "JobContext",
    "JobTimeoutError",
    "Progress",
    "set_site_fields",
    "store_result",
    "update_fragment",
    "update_placement",
]

# KEYS: fragment hash, layout key, then the 3 keys of REQUEST_PLACEMENT_LUA.
# ARGV: sha256, layout JSON or '', '1' to request a placement, the 4 ARGV of
# REQUEST_PLACEMENT_LUA, then field/value pairs. Updates the fragment only if it still holds
# those bytes (and in the same step asks for a placement); returns its new hash, or nil.
_UPDATE_FRAGMENT_LUA = (
    REQUEST_PLACEMENT_FUNCTION
    + """
if redis.call('HGET', KEYS[1], 'sha256') ~= ARGV[1] then return false end
if ARGV[2] ~= '' then redis.call('SET', KEYS[2], ARGV[2]) end
redis.call('HSET', KEYS[1], unpack(ARGV, 8))
if ARGV[3] == '1' then
  request_placement(KEYS[3], KEYS[4], KEYS[5], ARGV[4], ARGV[5], ARGV[6], ARGV[7])
end
return redis.call('HGETALL', KEYS[1])
"""
)


# KEYS: site hash. ARGV: field/value pairs. Sets them only if the site exists; returns its
# new hash, or nil.
_SET_SITE_LUA = """
if redis.call('EXISTS', KEYS[1]) == 0 then return false end
redis.call('HSET', KEYS[1], unpack(ARGV))
return redis.call('HGETALL', KEYS[1])
"""


class JobTimeoutError(JigsawError):
    """A job ran past its time limit (checked at each progress report)."""

    code = "job_timeout"


@dataclass(frozen=True)
class JobContext:
    """What a handler needs: clients, key names, settings and the job's limits."""

    client: redis.Redis  # string replies
    raw: redis.Redis  # bytes replies (fragment data)
    keys: Keys
    settings: Settings
    params: PipelineParams
    tries: int = 1
    deadline: float = float("inf")  # time.monotonic() limit


def _pairs(flat: list[str] | None) -> dict[str, str]:
    if not flat:
        return {}
    return dict(zip(flat[::2], flat[1::2], strict=True))


def update_fragment(
    ctx: JobContext,
    site_id: str,
    fragment_id: str,
    sha256: str,
    fields: Mapping[str, str],
    *,
    layout: str = "",
    place: bool = False,
) -> bool:
    """Set fields of a fragment that still holds ``sha256`` and publish its new status.

    ``place``: in the same atomic step, have the site placed again (layout done or failed).
    """
    keys = ctx.keys
    script = ctx.client.register_script(_UPDATE_FRAGMENT_LUA)
    placement_keys, placement_argv = placement_args(keys, ctx.settings, site_id)
    args: list[Any] = [sha256, layout, "1" if place else "0", *placement_argv]
    args += ["updated_at", repr(time.time())]
    for name, value in fields.items():
        args += [name, value]
    frag_keys = [keys.fragment(site_id, fragment_id), keys.fragment_layout(site_id, fragment_id)]
    flat = script(keys=[*frag_keys, *placement_keys], args=args)
    record = _pairs(flat)
    if not record:
        return False
    status = fragment_status(fragment_id, record).model_dump(mode="json")
    ctx.client.publish(
        keys.site_channel(site_id),
        site_event("fragment", site_id, status, fragment_id=fragment_id),
    )
    return True


def set_site_fields(ctx: JobContext, site_id: str, fields: Mapping[str, str]) -> dict[str, str]:
    """Set fields of an existing site's hash; returns the new hash (empty: no such site)."""
    args = [item for pair in {**fields, "updated_at": repr(time.time())}.items() for item in pair]
    script = ctx.client.register_script(_SET_SITE_LUA)
    return _pairs(script(keys=[ctx.keys.site(site_id)], args=args))


def update_placement(ctx: JobContext, site_id: str, **fields: str) -> None:
    """Set placement fields of the site hash and publish the placement status (nothing for a
    site that was deleted)."""
    record = set_site_fields(ctx, site_id, fields)
    if not record:
        return
    status = placement_status(record)
    ctx.client.publish(
        ctx.keys.site_channel(site_id),
        site_event("placement", site_id, status.model_dump(mode="json")),
    )


class Progress:
    """The ``progress(stage, fraction)`` callback given to the pipeline.

    Writes at most every ``interval`` seconds (and on each new stage), and raises
    :class:`JobTimeoutError` once the job's deadline has passed.
    """

    def __init__(self, ctx: JobContext, site_id: str, fragment: tuple[str, str] | None) -> None:
        self.ctx, self.site_id, self.fragment = ctx, site_id, fragment
        self.interval = 0.25
        self._last = (0.0, "")

    def __call__(self, stage: str, fraction: float) -> None:
        """Report progress: write it (throttled), or raise once past the deadline."""
        now = time.monotonic()
        if now > self.ctx.deadline:
            raise JobTimeoutError(f"job exceeded its time limit during {stage!r}")
        if stage == self._last[1] and now - self._last[0] < self.interval:
            return
        self._last = (now, stage)
        value = f"{min(1.0, max(0.0, float(fraction))):.3f}"
        if self.fragment is None:
            update_placement(
                self.ctx, self.site_id, placement_stage=stage, placement_progress=value
            )
        else:
            fid, sha = self.fragment
            update_fragment(self.ctx, self.site_id, fid, sha, {"stage": stage, "progress": value})


def store_result(
    ctx: JobContext,
    site_id: str,
    generation: int,
    result: ResultModel,
    *,
    site_created: str | None = None,
) -> bool:
    """Store a result unless a newer generation's result is already there.

    Nothing is stored for a site that does not exist, nor, with ``site_created`` (the site
    hash's ``created_at`` when the job started), for a site deleted and created again since.
    """
    site = ctx.keys.site(site_id)
    body = result.model_dump_json()
    fields = {
        "result_generation": str(generation),
        "result_status": result.status,
        "result_confidence": repr(result.confidence),
        "result_alternatives": str(len(result.alternatives)),
        "loop_closed": "1" if result.status in CLOSED_STATUSES else "0",
        "last_placement_at": repr(time.time()),
        "placement_state": PlacementState.DONE.value,
        "placement_stage": "done",
        "placement_progress": "1",
        **error_fields("", "", "placement_"),
    }
    with ctx.client.pipeline() as pipe:
        while True:
            try:
                watch(pipe, site)
                stored, created = pipe.hmget(site, "result_generation", "created_at")
                gone = created is None or site_created not in (None, created)
                if gone or (stored and int(stored) > generation):
                    pipe.unwatch()
                    return False
                pipe.multi()
                pipe.set(ctx.keys.result(site_id), body)
                pipe.hset(site, mapping=hash_fields(fields))
                pipe.execute()
                break
            except redis.WatchError:
                continue
    _publish_result(ctx, site_id, generation, result)
    return True


def _publish_result(ctx: JobContext, site_id: str, generation: int, result: ResultModel) -> None:
    data = result.model_dump(mode="json")
    event = site_event("result", site_id, data, generation=generation)
    ctx.client.publish(ctx.keys.site_channel(site_id), event)
    envelope = {"version": 1, "site_id": site_id, "generation": generation, "result": data}
    ctx.client.publish(ctx.keys.results_channel, json.dumps(envelope, separators=(",", ":")))
    update_placement(ctx, site_id)
