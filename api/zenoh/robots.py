"""Robot presence: liveliness tokens ``fpj/robots/{robot_id}`` followed into Redis.

A robot declares the token for as long as its session is open; zenoh withdraws it when the
session closes or its link dies (after the lease, 10 s by default, if the robot vanished
without closing). The tracker keeps the set in memory (a token may be declared by several
sessions at once, so each id is counted) and rewrites it to Redis on every change and every
``ttl / 3`` seconds (:mod:`store.presence`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from typing import Any

import zenoh

from api.zenoh.bridge import LoopBridge
from store.backend import Backend
from store.connection import REDIS_DOWN
from store.presence import clear_presence, write_presence
from transport.keys import ZenohKeys

__all__ = ["RobotTracker"]

log = logging.getLogger(__name__)


class RobotTracker:
    """Follows the robots' liveliness tokens and keeps this front end's view in Redis."""

    def __init__(self, backend: Backend, keys: ZenohKeys, front_id: str, bridge: LoopBridge):
        self.backend, self.keys, self.front_id, self.bridge = backend, keys, front_id, bridge
        self._tokens: dict[str, int] = {}
        self._since: dict[str, float] = {}
        self._lock = threading.Lock()
        self._write = asyncio.Lock()
        self._stopped = asyncio.Event()

    def declare(self, session: zenoh.Session) -> Any:
        """The liveliness subscriber (history: tokens declared before the service started)."""
        liveliness = session.liveliness()
        return liveliness.declare_subscriber(self.keys.all_robots, self._on_sample, history=True)

    def connected(self) -> dict[str, float]:
        """Robot id -> unix time its first token appeared."""
        with self._lock:
            return dict(self._since)

    def _on_sample(self, sample: zenoh.Sample) -> None:  # zenoh thread
        robot_id = self.keys.parse_robot(str(sample.key_expr))
        if robot_id is None:
            log.warning("ignoring liveliness token %s (invalid robot id)", sample.key_expr)
            return
        with self._lock:
            count = self._tokens.get(robot_id, 0)
            count += 1 if sample.kind == zenoh.SampleKind.PUT else -1
            if count > 0:
                self._tokens[robot_id] = count
                self._since.setdefault(robot_id, time.time())
            else:
                self._tokens.pop(robot_id, None)
                self._since.pop(robot_id, None)
        log.info("robot %s %s", robot_id, "connected" if count > 0 else "disconnected")
        self.bridge.submit(self.flush())

    async def flush(self) -> None:
        """Write the current view to Redis (Redis down: logged; the next refresh retries)."""
        async with self._write:
            try:
                await write_presence(self.backend, self.front_id, self.connected())
            except REDIS_DOWN as exc:
                log.warning("cannot store robot presence: %s", exc)

    async def run(self) -> None:
        """Refresh the presence in Redis every ``ttl / 3`` seconds until :meth:`stop`."""
        interval = self.backend.settings.zenoh_presence_ttl_s / 3
        while not self._stopped.is_set():
            await self.flush()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._stopped.wait(), interval)

    async def stop(self) -> None:
        """Stop refreshing and remove this front end's presence from Redis."""
        self._stopped.set()
        async with self._write:
            with contextlib.suppress(*REDIS_DOWN):
                await clear_presence(self.backend, self.front_id)
