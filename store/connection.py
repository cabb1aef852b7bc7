"""Redis connections: one factory for the worker (sync) and one for the API (asyncio).

Only commands present in both Redis 6.2 and 7.x are used anywhere in the service.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any, cast

import redis
import redis.asyncio as aioredis
from redis.asyncio.retry import Retry as AsyncRetry
from redis.backoff import ExponentialBackoff
from redis.retry import Retry
from redis.typing import EncodableT, FieldT

from store.keys import GROUP, Keys

__all__ = [
    "REDIS_DOWN",
    "abort_watch",
    "async_client",
    "begin_multi",
    "ensure_group",
    "ensure_group_async",
    "hash_fields",
    "record",
    "redis_reply",
    "storage_refused",
    "strings",
    "sync_client",
    "wait_for_redis",
    "watch",
]

# Errors meaning "Redis is not reachable right now" (as opposed to a wrong command).
REDIS_DOWN: tuple[type[Exception], ...] = (
    redis.exceptions.ConnectionError,
    redis.exceptions.TimeoutError,
    redis.exceptions.BusyLoadingError,
    ConnectionError,
    TimeoutError,
)


def redis_reply(exc: redis.exceptions.RedisError) -> str:
    """Redis' own error reply in ``exc``: a pipeline's error reads "Command # 1 (...) of
    pipeline caused error: <reply>", the reply sometimes as a tuple's repr."""
    return str(exc).rpartition("of pipeline caused error: ")[2].lstrip("('\"")


def storage_refused(exc: BaseException) -> bool:
    """True when Redis refuses a write for want of room: its maxmemory is reached (OOM,
    policy noeviction) or its append-only file cannot be written (MISCONF, a full disk).
    Nothing stored is lost; writes succeed again once there is room."""
    if isinstance(exc, redis.exceptions.OutOfMemoryError):
        return True
    return isinstance(exc, redis.exceptions.ResponseError) and redis_reply(exc).startswith(
        "MISCONF"
    )


def sync_client(url: str, *, timeout: float, decode: bool = True) -> redis.Redis:
    """A thread-safe pooled client for worker processes.

    ``timeout`` bounds connecting and every reply; blocking reads must stay below it.
    """
    return redis.Redis.from_url(url, decode_responses=decode, **_pool_options(timeout, Retry))


def async_client(url: str, *, timeout: float) -> aioredis.Redis:
    """A pooled asyncio client for the API (string replies)."""
    return aioredis.Redis.from_url(url, decode_responses=True, **_pool_options(timeout, AsyncRetry))


def _pool_options(timeout: float, retry: type[Retry] | type[AsyncRetry]) -> dict[str, Any]:
    """Timeouts, health checks and the one quick retry both clients share; ``retry``: the
    client's own Retry class (redis-py 8 warns when an asyncio client gets the sync one)."""
    return {
        "socket_timeout": timeout,
        "socket_connect_timeout": min(timeout, 5.0),
        "health_check_interval": 30,
        "retry": retry(ExponentialBackoff(cap=0.5, base=0.05), retries=1),
    }


def _busy_group(exc: redis.exceptions.ResponseError) -> bool:
    return "BUSYGROUP" in str(exc)


def ensure_group(client: redis.Redis, keys: Keys) -> None:
    """Create the job stream and its consumer group if missing (idempotent)."""
    try:
        client.xgroup_create(keys.jobs, GROUP, id="0", mkstream=True)
    except redis.exceptions.ResponseError as exc:
        if not _busy_group(exc):
            raise


async def ensure_group_async(client: aioredis.Redis, keys: Keys) -> None:
    """:func:`ensure_group` for the asyncio client."""
    try:
        await client.xgroup_create(keys.jobs, GROUP, id="0", mkstream=True)
    except redis.exceptions.ResponseError as exc:
        if not _busy_group(exc):
            raise


def wait_for_redis(client: redis.Redis, timeout: float) -> None:
    """Ping until Redis answers; re-raise the last error after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            client.ping()
            return
        except REDIS_DOWN:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)


def hash_fields(fields: Mapping[str, str]) -> Mapping[FieldT, EncodableT]:
    """A str-to-str mapping typed as redis-py's ``hset(mapping=...)`` wants it."""
    return cast(Mapping[FieldT, EncodableT], fields)


def strings(reply: object) -> list[str]:
    """A list reply of a client with ``decode_responses=True`` (e.g. ZRANGE)."""
    return cast(list[str], reply)


def watch(pipe: redis.client.Pipeline, *names: str) -> None:
    """WATCH keys on a pipeline (redis-py leaves ``Pipeline.watch`` untyped)."""
    pipe.watch(*names)  # type: ignore[no-untyped-call]


def record(reply: object) -> dict[str, str]:
    """A hash reply (HGETALL) of a client with ``decode_responses=True``."""
    return cast(dict[str, str], reply)


async def abort_watch(pipe: aioredis.client.Pipeline) -> None:
    """UNWATCH on an asyncio pipeline (untyped in redis-py)."""
    await pipe.unwatch()  # type: ignore[no-untyped-call]


def begin_multi(pipe: aioredis.client.Pipeline) -> None:
    """MULTI on an asyncio pipeline after WATCH (untyped in redis-py)."""
    pipe.multi()  # type: ignore[no-untyped-call]
