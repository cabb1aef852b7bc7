"""Putting jobs on the stream, per-site placement coalescing, acknowledgements, dead letters.

Placement coalescing. A site's hash holds ``generation``, bumped (atomically, by
:data:`REQUEST_PLACEMENT_LUA`) whenever the set of usable layouts or the site's hints change.
The key ``P:site:S:placement`` names the one placement job queued or running for the site; a
request that finds it taken only bumps the generation. The job remembers the generation it
started from; when it finishes, :func:`finish_placement` re-enqueues exactly one more run if the
generation moved meanwhile (the "dirty" case) and otherwise releases the key, in one
WATCH/MULTI transaction so no request is lost between the check and the release.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import redis
import redis.asyncio as aioredis

from schemas.jobs import DeadLetter, PlacementJob, PlacementState, encode_job
from schemas.settings import Settings
from store.connection import watch
from store.keys import GROUP, Keys

__all__ = [
    "REQUEST_PLACEMENT_FUNCTION",
    "REQUEST_PLACEMENT_LUA",
    "Extra",
    "ack",
    "dead_letter",
    "finish_placement",
    "placement_args",
    "placement_flag_ttl_ms",
    "request_placement",
    "request_placement_async",
    "retry_later",
]

DEAD_LETTER_MAXLEN = 10_000

# More commands to run in the same MULTI as an acknowledgement (e.g. the job statistics).
Extra = Callable[[redis.client.Pipeline], None]

# Lua function shared by scripts: bump the site generation and enqueue a placement job unless
# one is queued or running. Returns {generation, 1 if a job was enqueued else 0}; {0, 0} for
# a site that does not exist (deleted: nothing may bring its hash back).
REQUEST_PLACEMENT_FUNCTION = """
local function request_placement(site, flag, stream, job_id, job_json, ttl_ms, now)
  if redis.call('EXISTS', site) == 0 then return {0, 0} end
  local generation = redis.call('HINCRBY', site, 'generation', 1)
  redis.call('HSET', site, 'updated_at', now)
  if redis.call('SET', flag, job_id, 'NX', 'PX', ttl_ms) then
    redis.call('XADD', stream, '*', 'job', job_json)
    redis.call('HSET', site, 'placement_state', 'queued', 'placement_stage', 'queued',
               'placement_progress', '0')
    return {generation, 1}
  end
  return {generation, 0}
end
"""

# KEYS: site hash, placement key, job stream. ARGV: job id, job JSON, key TTL (ms), now.
# Commands valid on Redis 6.2 and 7.x.
REQUEST_PLACEMENT_LUA = (
    REQUEST_PLACEMENT_FUNCTION
    + "return request_placement(KEYS[1], KEYS[2], KEYS[3], ARGV[1], ARGV[2], ARGV[3], ARGV[4])"
)


def placement_flag_ttl_ms(settings: Settings) -> int:
    """Lifetime of a site's placement key: long enough for every try of one job."""
    per_try = settings.placement_timeout_s + settings.visibility_timeout_s
    return int(1000 * max(600.0, per_try * (settings.max_tries + 1)))


def placement_args(keys: Keys, settings: Settings, site_id: str) -> tuple[list[str], list[Any]]:
    """KEYS and ARGV of :data:`REQUEST_PLACEMENT_LUA` for a site (with a new job)."""
    job = PlacementJob(site_id=site_id)
    return (
        [keys.site(site_id), keys.placement_flag(site_id), keys.jobs],
        [job.job_id, encode_job(job), placement_flag_ttl_ms(settings), repr(time.time())],
    )


def request_placement(client: redis.Redis, keys: Keys, settings: Settings, site_id: str) -> int:
    """Note that the site changed and make sure one placement will run; returns generation
    (0 when the site does not exist)."""
    names, args = placement_args(keys, settings, site_id)
    reply = client.register_script(REQUEST_PLACEMENT_LUA)(keys=names, args=args)
    return int(reply[0])


async def request_placement_async(
    client: aioredis.Redis, keys: Keys, settings: Settings, site_id: str
) -> int:
    """:func:`request_placement` for the asyncio client (fragment deletes, hints)."""
    names, args = placement_args(keys, settings, site_id)
    reply = await client.register_script(REQUEST_PLACEMENT_LUA)(keys=names, args=args)
    return int(reply[0])


def finish_placement(
    client: redis.Redis, keys: Keys, settings: Settings, job: PlacementJob, generation: int
) -> bool:
    """Release the site's placement key, or hand it to one new job if the site changed.

    ``generation`` is the site generation the finishing job started from. Returns True when
    another run was enqueued.
    """
    site, flag = keys.site(job.site_id), keys.placement_flag(job.site_id)
    with client.pipeline() as pipe:
        while True:
            try:
                watch(pipe, site, flag)
                current = int(pipe.hget(site, "generation") or 0)
                holder = pipe.get(flag)
                pipe.multi()
                requeue = holder in (None, job.job_id) and current > generation
                if requeue:
                    nxt = PlacementJob(site_id=job.site_id)
                    pipe.set(flag, nxt.job_id, px=placement_flag_ttl_ms(settings))
                    pipe.xadd(keys.jobs, {"job": encode_job(nxt)})
                    pipe.hset(site, "placement_state", PlacementState.QUEUED.value)
                elif holder == job.job_id:
                    pipe.delete(flag)
                pipe.execute()
                return requeue
            except redis.WatchError:
                continue


def ack(
    client: redis.Redis, keys: Keys, message_id: str, job_id: str | None, extra: Extra | None = None
) -> None:
    """Acknowledge and delete a finished entry (the stream only holds unfinished jobs)."""
    with client.pipeline() as pipe:
        if extra is not None:
            extra(pipe)
        pipe.xack(keys.jobs, GROUP, message_id)
        pipe.xdel(keys.jobs, message_id)
        if job_id:
            pipe.delete(keys.tries(job_id))
        pipe.execute()


def retry_later(
    client: redis.Redis, keys: Keys, message_id: str, raw_job: str, extra: Extra | None = None
) -> None:
    """Put a job back at the end of the stream for another try (its try counter stays)."""
    with client.pipeline() as pipe:
        if extra is not None:
            extra(pipe)
        pipe.xadd(keys.jobs, {"job": raw_job})
        pipe.xack(keys.jobs, GROUP, message_id)
        pipe.xdel(keys.jobs, message_id)
        pipe.execute()


def dead_letter(
    client: redis.Redis,
    keys: Keys,
    message_id: str,
    job_id: str | None,
    letter: DeadLetter,
    extra: Extra | None = None,
) -> None:
    """Move a job to the dead-letter stream and acknowledge it."""
    with client.pipeline() as pipe:
        if extra is not None:
            extra(pipe)
        pipe.xadd(
            keys.dead,
            {"dead": letter.model_dump_json()},
            maxlen=DEAD_LETTER_MAXLEN,
            approximate=True,
        )
        pipe.xack(keys.jobs, GROUP, message_id)
        pipe.xdel(keys.jobs, message_id)
        if job_id:
            pipe.delete(keys.tries(job_id))
        pipe.execute()
