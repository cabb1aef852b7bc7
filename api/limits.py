"""Limits of what one client may take: upload rate, and time to answer a request.

The rate is counted in Redis (one counter per client and window), so every API process
behind a load balancer counts against the same budget. The window is fixed, not sliding: a
client may send up to twice the limit across a window's boundary, in exchange for one
INCR per upload.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import math
import time

from fastapi import Request
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from api.errors import (
    ProcessingTimeoutError,
    RateLimitedError,
    RequestTimeoutError,
    jigsaw_response,
)
from store.backend import Backend

__all__ = ["RequestTimeout", "check_upload_rate", "client_id", "http_client_id"]


def client_id(token: str | None, fallback: str) -> str:
    """Whom an upload counts against: its token (hashed: a Redis key must not hold a
    secret), else ``fallback`` (the client address, the robot id)."""
    if token:
        return "token:" + hashlib.sha256(token.encode()).hexdigest()[:32]
    return fallback


def http_client_id(request: Request, tokens_checked: bool) -> str:
    """:func:`client_id` of an HTTP request: its bearer token when tokens are configured
    (and so checked before this counts), else its address (an unchecked token would let a
    client dodge the limit by sending a new one each time)."""
    scheme, _, token = request.headers.get("authorization", "").partition(" ")
    given = token.strip() if tokens_checked and scheme.lower() == "bearer" else None
    return client_id(given, "addr:" + (request.client.host if request.client else "unknown"))


async def check_upload_rate(backend: Backend, client_id: str) -> None:
    """Count one upload of ``client_id``; RateLimitedError past ``upload_rate_limit``.

    Called before the body is read or parsed, so a flood costs one INCR per request.
    """
    limit, window = backend.settings.upload_rate_limit, backend.settings.upload_rate_window_s
    if limit == 0:
        return
    now = time.time()
    index = math.floor(now / window)
    key = backend.keys.upload_rate(client_id, index)
    async with backend.redis.pipeline(transaction=False) as pipe:
        pipe.incr(key)
        pipe.expire(key, math.ceil(window) + 1)
        count, _ = await pipe.execute()
    if int(count) > limit:
        retry_after = max(1, math.ceil((index + 1) * window - now))
        raise RateLimitedError(
            f"more than {limit} uploads in {window:g} s; retry in {retry_after} s", retry_after
        )


class RequestTimeout:
    """ASGI middleware: a request whose response has not started after ``seconds`` is
    cancelled and answered 408 (the service was waiting for more of its body: a slow or
    stalled sender) or 503 (the service itself was slow: Redis, parsing). A response that
    has started (an event stream, a large download) runs on."""

    def __init__(self, app: ASGIApp, seconds: float) -> None:
        self.app, self.seconds = app, seconds

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Serve one request; past the deadline without a response, answer the error."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = asyncio.Event()
        reading = False  # the app waits for more of the body: the sender is the slow one

        async def receive_counted() -> Message:
            nonlocal reading
            reading = True
            try:
                return await receive()
            finally:
                reading = False

        async def send_marked(message: Message) -> None:
            if message["type"] == "http.response.start":
                started.set()
            await send(message)

        task = asyncio.ensure_future(self.app(scope, receive_counted, send_marked))
        waiter = asyncio.ensure_future(started.wait())
        try:
            await asyncio.wait({task, waiter}, timeout=self.seconds, return_when="FIRST_COMPLETED")
        finally:
            waiter.cancel()
        if task.done() or started.is_set():
            await task  # finished, or answering: a started response is never cut short
            return
        slow_sender = reading
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        if started.is_set():
            return  # it began answering while being cancelled: nothing more to send
        message = f"no response within {self.seconds:g} s"
        error = (
            RequestTimeoutError(f"{message}: the request body was still arriving")
            if slow_sender
            else ProcessingTimeoutError(message)
        )
        await jigsaw_response(error)(scope, receive, send)
