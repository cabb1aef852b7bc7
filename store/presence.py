"""Robot presence and fragment senders in Redis, for the site status of every front end.

Each zenoh front end (one per API process, named by its zenoh session id) rewrites its whole
view of the connected robots on every liveliness change and every ``ttl / 3`` seconds; the
hash expires after ``ttl``, so a front end that dies without cleaning up stops counting.
Who sent which fragment is kept per site, so the status lists each robot's fragments.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping
from typing import Any

from pydantic import ValidationError

from schemas.service import RobotStatus, utc
from schemas.zenoh import SenderRecord
from store.backend import Backend
from store.connection import record, strings

__all__ = [
    "clear_presence",
    "connected_robots",
    "load_senders",
    "load_site_robots",
    "record_sender",
    "write_presence",
]


async def write_presence(backend: Backend, front_id: str, robots: Mapping[str, float]) -> None:
    """Replace front end ``front_id``'s set of connected robots (robot id -> since)."""
    keys, ttl = backend.keys, backend.settings.zenoh_presence_ttl_s
    now = time.time()
    key = keys.presence(front_id)
    async with backend.redis.pipeline(transaction=True) as pipe:
        pipe.delete(key)
        if robots:
            pipe.hset(key, mapping={rid: repr(since) for rid, since in robots.items()})
            pipe.pexpire(key, int(ttl * 1000))
        pipe.zadd(keys.presence_fronts, {front_id: now})
        pipe.zremrangebyscore(keys.presence_fronts, "-inf", now - ttl)
        await pipe.execute()


async def clear_presence(backend: Backend, front_id: str) -> None:
    """Forget front end ``front_id`` (clean shutdown)."""
    keys = backend.keys
    async with backend.redis.pipeline(transaction=True) as pipe:
        pipe.delete(keys.presence(front_id))
        pipe.zrem(keys.presence_fronts, front_id)
        await pipe.execute()


async def connected_robots(backend: Backend) -> dict[str, float]:
    """Robots connected to any live front end: robot id -> earliest ``since``."""
    keys, r = backend.keys, backend.redis
    since = time.time() - backend.settings.zenoh_presence_ttl_s
    fronts = strings(await r.zrangebyscore(keys.presence_fronts, since, "+inf"))
    if not fronts:
        return {}
    async with r.pipeline(transaction=False) as pipe:
        for front in fronts:
            pipe.hgetall(keys.presence(front))
        views: list[Any] = await pipe.execute()
    robots: dict[str, float] = {}
    for view in views:
        for rid, value in (view or {}).items():
            robots[rid] = min(float(value), robots.get(rid, float("inf")))
    return robots


async def record_sender(
    backend: Backend, site_id: str, fragment_id: str, sender: SenderRecord
) -> None:
    """Remember who sent a newly accepted fragment."""
    key = backend.keys.site_senders(site_id)
    await backend.redis.hset(key, fragment_id, sender.model_dump_json(exclude_none=True))


async def load_senders(backend: Backend, site_id: str) -> dict[str, SenderRecord]:
    """Fragment id -> sender, for the fragments whose sender is known."""
    raw = record(await backend.redis.hgetall(backend.keys.site_senders(site_id)))
    senders = {}
    for fid, text in raw.items():
        try:
            senders[fid] = SenderRecord.model_validate_json(text)
        except ValidationError:
            continue  # written by a newer version; ignore rather than fail the status
    return senders


async def load_site_robots(
    backend: Backend, site_id: str, fragment_ids: Iterable[str]
) -> list[RobotStatus]:
    """Connected robots (by id), each with the site's fragments it sent, in upload order."""
    robots = await connected_robots(backend)
    if not robots:
        return []
    senders = await load_senders(backend, site_id)
    sent: dict[str, list[str]] = {rid: [] for rid in robots}
    for fid in fragment_ids:
        sender = senders.get(fid)
        if sender is not None and sender.robot_id in sent:
            sent[sender.robot_id].append(fid)
    return [
        RobotStatus(robot_id=rid, connected_since=utc(robots[rid]), fragments=sent[rid])
        for rid in sorted(robots)
    ]
