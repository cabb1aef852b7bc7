"""From zenoh's callback threads to the API's event loop, and replies to queries.

Zenoh runs callbacks on its own threads; they must return quickly and never touch the
asyncio Redis client. :class:`LoopBridge` hands each piece of work to the app's event loop as
a task (so ingest runs exactly as for an HTTP request) and lets shutdown wait for the tasks
still running, so every query in flight gets its reply before the session closes.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import Coroutine
from typing import Any

import redis
import zenoh

from api.errors import UnavailableError, error_body, storage_error
from services.errors import JigsawError
from store.connection import REDIS_DOWN

__all__ = ["LoopBridge", "error_of", "reply_error", "reply_json"]

log = logging.getLogger(__name__)

JSON = zenoh.Encoding.APPLICATION_JSON


class LoopBridge:
    """Runs coroutines submitted from any thread as tasks of one event loop."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.closing = False
        self._tasks: set[asyncio.Task[None]] = set()

    def submit(self, coro: Coroutine[Any, Any, None]) -> bool:
        """Schedule ``coro`` on the loop (thread-safe); False once closing or closed."""
        if self.closing:
            coro.close()
            return False
        try:
            self.loop.call_soon_threadsafe(self._spawn, coro)
        except RuntimeError:  # the loop is closed
            coro.close()
            return False
        return True

    def _spawn(self, coro: Coroutine[Any, Any, None]) -> None:
        task = self.loop.create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._done)

    def _done(self, task: asyncio.Task[None]) -> None:
        self._tasks.discard(task)
        if not task.cancelled() and task.exception() is not None:
            log.error("zenoh handler failed", exc_info=task.exception())

    async def drain(self, timeout: float) -> None:
        """Refuse new work, then wait up to ``timeout`` s for the tasks still running."""
        self.closing = True
        await asyncio.sleep(0)  # let already scheduled _spawn calls create their tasks
        pending = set(self._tasks)
        if not pending:
            return
        _, late = await asyncio.wait(pending, timeout=timeout)
        for task in late:
            task.cancel()
        if late:
            await asyncio.wait(late, timeout=1.0)


def error_of(exc: BaseException) -> tuple[str, str]:
    """``(code, message)`` of the contract's error body for any failure of a handler."""
    if isinstance(exc, JigsawError):
        return exc.code, exc.message
    if isinstance(exc, redis.exceptions.RedisError) and (mapped := storage_error(exc)):
        return mapped.code, mapped.message
    if isinstance(exc, (*REDIS_DOWN, redis.exceptions.RedisError)):
        return UnavailableError.code, f"storage unavailable: {type(exc).__name__}: {exc}"
    return "internal_error", "internal server error"


def reply_json(query: zenoh.Query, key: str, body: str) -> None:
    """Reply with a JSON body on ``key``; a querier that went away is not an error."""
    try:
        query.reply(key, body, encoding=JSON)
    except zenoh.ZError as exc:
        log.info("cannot reply on %s: %s", key, exc)


def reply_error(query: zenoh.Query, code: str, message: str) -> None:
    """Reply with the contract's error body ``{"error": {"code", "message"}}``."""
    try:
        body = json.dumps(error_body(code, message), separators=(",", ":"))
        query.reply_err(body, encoding=JSON)
    except zenoh.ZError as exc:
        log.info("cannot send error reply %s: %s", code, exc)
