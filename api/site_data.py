"""The API's own use of the data layer (:mod:`store`): what it reads from Redis (site status,
results, lists, queue counts) as wire models, and the deletes."""

from __future__ import annotations

import time
from typing import Any

import redis
import redis.asyncio as aioredis

from api.errors import FragmentNotFoundError, SiteNotFoundError
from schemas.service import FragmentStatus, SiteList, SiteStatus, SiteSummary, utc
from store.backend import Backend
from store.connection import abort_watch, begin_multi, record, strings
from store.jobs import request_placement_async
from store.keys import GROUP, Keys
from store.presence import load_site_robots
from store.records import fragment_status, placement_status, site_event, site_status

__all__ = [
    "delete_fragment",
    "delete_site",
    "list_sites",
    "live_workers",
    "load_fragment",
    "load_result",
    "load_site_status",
    "queue_counts",
    "site_exists",
    "touch_site",
]


async def site_exists(backend: Backend, site_id: str) -> bool:
    """True once a fragment (or hints) of the site has been accepted, until it is deleted."""
    return await backend.redis.zscore(backend.keys.sites, site_id) is not None


def touch_site(pipe: aioredis.client.Pipeline, keys: Keys, site_id: str, now: float) -> None:
    """Queue the commands that create the site if new and mark it updated (inside a MULTI)."""
    site = keys.site(site_id)
    pipe.hsetnx(site, "created_at", repr(now))
    pipe.hset(site, "updated_at", repr(now))
    pipe.zadd(keys.sites, {site_id: now}, nx=True)


async def load_site_status(backend: Backend, site_id: str) -> SiteStatus:
    """The status of every fragment (upload order), of the site's placement, and the robots
    connected over zenoh with the fragments each sent."""
    keys, r = backend.keys, backend.redis
    ids = strings(await r.zrange(keys.fragments(site_id), 0, -1))
    async with r.pipeline(transaction=False) as pipe:
        pipe.hgetall(keys.site(site_id))
        pipe.exists(keys.hints(site_id))
        for fid in ids:
            pipe.hgetall(keys.fragment(site_id, fid))
        replies: list[Any] = await pipe.execute()
    fragments = list(zip(ids, replies[2:], strict=True))
    status = site_status(site_id, replies[0], fragments, hints=bool(replies[1]))
    robots = await load_site_robots(backend, site_id, [f.fragment_id for f in status.fragments])
    return status.model_copy(update={"robots": robots})


async def load_fragment(backend: Backend, site_id: str, fragment_id: str) -> FragmentStatus:
    """The fragment's status record.

    Raises
    ------
    FragmentNotFoundError
        The site holds no fragment of this id.
    """
    found = record(await backend.redis.hgetall(backend.keys.fragment(site_id, fragment_id)))
    if not found:
        raise FragmentNotFoundError(f"site {site_id!r} has no fragment {fragment_id!r}")
    return fragment_status(fragment_id, found)


async def load_result(backend: Backend, site_id: str) -> str | None:
    """The stored result JSON of the newest placement, if any."""
    value = await backend.redis.get(backend.keys.result(site_id))
    return str(value) if value is not None else None


async def _site_page(
    backend: Backend, offset: int, limit: int, only: tuple[str, ...] | None
) -> tuple[list[str], int]:
    """One page of site ids in creation order, and how many there are in all."""
    keys, r = backend.keys, backend.redis
    if only is not None:  # a token's few sites: those that exist, in creation order
        scores = await r.zmscore(keys.sites, list(only)) if only else []
        found = sorted(
            (float(s), sid) for sid, s in zip(only, scores, strict=True) if s is not None
        )
        return [sid for _, sid in found[offset : offset + limit]], len(found)
    total = int(await r.zcard(keys.sites))
    # Past the end the page is empty (an offset beyond Redis' 64-bit range is an error there).
    ids = strings(await r.zrange(keys.sites, offset, offset + limit - 1)) if offset < total else []
    return ids, total


async def list_sites(
    backend: Backend, offset: int, limit: int, only: tuple[str, ...] | None = None
) -> SiteList:
    """Sites in creation order, with their fragment counts and placement state; ``only``:
    just these sites (what a site-scoped token may see)."""
    keys, r = backend.keys, backend.redis
    ids, total = await _site_page(backend, offset, limit, only)
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
            updated_at=utc(float(rec.get("updated_at") or 0.0)),
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


async def delete_site(backend: Backend, site_id: str) -> None:
    """Remove the site and everything stored for it (fragments, layouts, result, hints,
    status, senders); its queued jobs then find nothing to do. Subscribers of its events get
    a last ``site`` event ``{"deleted": true}``.

    Raises
    ------
    SiteNotFoundError
        No such site (or it was deleted meanwhile).
    """
    keys, r = backend.keys, backend.redis
    async with r.pipeline(transaction=True) as pipe:
        while True:
            try:
                # An upload or hints arriving meanwhile change one of these: then start over.
                await pipe.watch(keys.site(site_id), keys.fragments(site_id))
                if await pipe.zscore(keys.sites, site_id) is None:
                    await abort_watch(pipe)
                    raise SiteNotFoundError(f"unknown site {site_id!r}")
                ids = strings(await pipe.zrange(keys.fragments(site_id), 0, -1))
                begin_multi(pipe)
                pipe.delete(*keys.site_keys(site_id, ids))
                pipe.zrem(keys.sites, site_id)
                await pipe.execute()
                break
            except redis.WatchError:
                continue
            except redis.exceptions.OutOfMemoryError:
                # Full (maxmemory), Redis refuses every command inside MULTI, and deleting is
                # how room is made. No upload can land meanwhile (each needs MULTI), so the
                # plain commands are safe; DEL of all keys is itself atomic.
                await r.delete(*keys.site_keys(site_id, ids))
                await r.zrem(keys.sites, site_id)
                break
    event = site_event("site", site_id, {"deleted": True})
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
