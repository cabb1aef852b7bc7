"""What the API reads from Redis (site status, results, lists) and the fragment delete."""

from __future__ import annotations

import time
from typing import Any

import redis

from api.backend import Backend
from api.errors import FragmentNotFoundError
from api.zenoh.presence import load_site_robots
from schemas.service import FragmentStatus, SiteList, SiteStatus, SiteSummary
from worker.connection import abort_watch, begin_multi, record, strings
from worker.jobs import request_placement_async
from worker.keys import GROUP
from worker.records import fragment_status, placement_status, site_event, site_status

__all__ = [
    "delete_fragment",
    "list_sites",
    "live_workers",
    "load_fragment",
    "load_result",
    "load_site_status",
    "queue_counts",
    "site_exists",
]


async def site_exists(backend: Backend, site_id: str) -> bool:
    """True once a fragment of the site has been accepted."""
    return await backend.redis.zscore(backend.keys.sites, site_id) is not None


async def load_site_status(backend: Backend, site_id: str) -> SiteStatus:
    """The status of every fragment (upload order), of the site's placement, and the robots
    connected over zenoh with the fragments each sent."""
    keys, r = backend.keys, backend.redis
    ids = strings(await r.zrange(keys.fragments(site_id), 0, -1))
    async with r.pipeline(transaction=False) as pipe:
        pipe.hgetall(keys.site(site_id))
        for fid in ids:
            pipe.hgetall(keys.fragment(site_id, fid))
        replies: list[Any] = await pipe.execute()
    status = site_status(site_id, replies[0], list(zip(ids, replies[1:], strict=True)))
    robots = await load_site_robots(backend, site_id, [f.fragment_id for f in status.fragments])
    return status.model_copy(update={"robots": robots})


async def load_fragment(backend: Backend, site_id: str, fragment_id: str) -> FragmentStatus:
    found = record(await backend.redis.hgetall(backend.keys.fragment(site_id, fragment_id)))
    if not found:
        raise FragmentNotFoundError(f"site {site_id!r} has no fragment {fragment_id!r}")
    return fragment_status(fragment_id, found)


async def load_result(backend: Backend, site_id: str) -> str | None:
    """The stored result JSON of the newest placement, if any."""
    value = await backend.redis.get(backend.keys.result(site_id))
    return str(value) if value is not None else None


async def list_sites(backend: Backend, offset: int, limit: int) -> SiteList:
    """Sites in creation order, with their fragment counts and placement state."""
    keys, r = backend.keys, backend.redis
    total = int(await r.zcard(keys.sites))
    ids = strings(await r.zrange(keys.sites, offset, offset + limit - 1))
    async with r.pipeline(transaction=False) as pipe:
        for sid in ids:
            pipe.hgetall(keys.site(sid))
            pipe.zcard(keys.fragments(sid))
        replies: list[Any] = await pipe.execute()
    sites = [
        SiteSummary(
            site_id=sid,
            n_fragments=int(count),
            placement=placement_status(rec),
            updated_at=float(rec.get("updated_at") or 0.0),
        )
        for sid, rec, count in zip(ids, replies[::2], replies[1::2], strict=True)
    ]
    return SiteList(sites=sites, total=total)


async def delete_fragment(backend: Backend, site_id: str, fragment_id: str) -> None:
    """Remove a fragment and everything derived from it, then have the site re-placed."""
    keys, r = backend.keys, backend.redis
    fragment = keys.fragment(site_id, fragment_id)
    async with r.pipeline(transaction=True) as pipe:
        while True:
            try:
                await pipe.watch(fragment)
                if not await pipe.exists(fragment):
                    await abort_watch(pipe)
                    raise FragmentNotFoundError(f"site {site_id!r} has no fragment {fragment_id!r}")
                begin_multi(pipe)
                pipe.delete(
                    fragment,
                    keys.fragment_data(site_id, fragment_id),
                    keys.fragment_layout(site_id, fragment_id),
                )
                pipe.zrem(keys.fragments(site_id), fragment_id)
                await pipe.execute()
                break
            except redis.WatchError:
                continue
    await request_placement_async(r, keys, backend.settings, site_id)
    event = site_event(
        "fragment", site_id, {"fragment_id": fragment_id, "deleted": True}, fragment_id=fragment_id
    )
    await r.publish(keys.site_channel(site_id), event)


async def live_workers(backend: Backend) -> int:
    """Workers whose heartbeat is younger than ``worker_alive_s``."""
    since = time.time() - backend.settings.worker_alive_s
    return int(await backend.redis.zcount(backend.keys.workers, since, "+inf"))


async def queue_counts(backend: Backend) -> dict[str, int]:
    """Jobs by state: waiting in the stream, delivered and running, dead-lettered."""
    keys, r = backend.keys, backend.redis
    async with r.pipeline(transaction=False) as pipe:
        pipe.xlen(keys.jobs)
        pipe.xpending(keys.jobs, GROUP)
        pipe.xlen(keys.dead)
        replies: list[Any] = await pipe.execute(raise_on_error=False)
    length = replies[0] if isinstance(replies[0], int) else 0
    pending = replies[1].get("pending", 0) if isinstance(replies[1], dict) else 0
    dead = replies[2] if isinstance(replies[2], int) else 0
    return {"queued": max(0, length - pending), "running": int(pending), "dead": dead}
