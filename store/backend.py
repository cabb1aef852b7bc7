"""What every front end (HTTP here, zenoh next) needs to reach the service's storage."""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass

import redis.asyncio as aioredis

from schemas.settings import Settings
from services.errors import JigsawError
from store.connection import REDIS_DOWN, async_client, ensure_group_async
from store.keys import Keys

__all__ = ["Backend", "EvictingStorageError", "require_noeviction"]


class EvictingStorageError(JigsawError):
    """Redis may evict keys when full: stored fragments could vanish without an error."""

    code = "evicting_storage"


async def require_noeviction(client: aioredis.Redis) -> None:
    """Refuse a Redis whose ``maxmemory-policy`` evicts keys: once full it must refuse
    writes (the API answers 507 storage_full) rather than drop stored fragments. Read from
    INFO, which managed Redis services allow where CONFIG GET is disabled."""
    policy = str((await client.info("memory")).get("maxmemory_policy", "noeviction"))
    if policy != "noeviction":
        raise EvictingStorageError(
            f"Redis maxmemory-policy is {policy}: stored fragments could be evicted; "
            "set it to noeviction (CONFIG SET maxmemory-policy noeviction)"
        )


@dataclass
class Backend:
    """Settings, the asyncio Redis client and the key names, shared by one front end."""

    settings: Settings
    redis: aioredis.Redis
    keys: Keys

    @classmethod
    async def connect(cls, settings: Settings) -> Backend:
        """Connect (waiting up to ``startup_timeout_s`` for Redis), check that Redis never
        evicts (:func:`require_noeviction`) and create the job group."""
        if not settings.redis_url:
            raise ValueError("no Redis URL: run `jigsaw serve` or set FPJ_REDIS_URL")
        client = async_client(settings.redis_url, timeout=settings.redis_timeout_s)
        keys = Keys(settings.key_prefix)
        deadline = time.monotonic() + settings.startup_timeout_s
        while True:
            try:
                await client.ping()
                await require_noeviction(client)
                await ensure_group_async(client, keys)
                break
            except REDIS_DOWN:
                if time.monotonic() > deadline:
                    await client.aclose()
                    raise
                await asyncio.sleep(0.2)
            except EvictingStorageError:
                await client.aclose()
                raise
        return cls(settings, client, keys)

    async def aclose(self) -> None:
        """Close the Redis connection pool."""
        await self.redis.aclose()
