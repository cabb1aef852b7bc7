"""Results and poses out to zenoh, fed by the Redis channel the workers publish results on.

After each placement a worker publishes ``{"version", "site_id", "generation", "result"}`` on
``P:results`` (:func:`worker.updates.store_result`). For each such message this publishes the
result JSON on ``fpj/sites/{site}/result``, each placed fragment's :class:`PoseUpdate` on
``fpj/sites/{site}/poses/{fragment}`` (status closed, ambiguous or open) and, if configured,
the ROS 2 messages of :class:`api.zenoh.ros_bridge.RosBridge`. Puts block under
congestion instead of dropping, off the event loop.

A result published while Redis is unreachable is missed here; the result queryable still
serves it.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging

import zenoh
from pydantic import ValidationError

from api.zenoh.ros_bridge import RosBridge
from schemas.result import ResultModel
from schemas.zenoh import pose_updates
from store.backend import Backend
from store.connection import REDIS_DOWN
from transport.keys import ZenohKeys

__all__ = ["ResultPublisher"]

log = logging.getLogger(__name__)


class ResultPublisher:
    """Follows the Redis results channel and republishes every result on zenoh."""

    def __init__(
        self, backend: Backend, session: zenoh.Session, keys: ZenohKeys, ros: RosBridge | None
    ) -> None:
        self.backend, self.session, self.keys, self.ros = backend, session, keys, ros
        self._stopped = asyncio.Event()
        self.subscribed = asyncio.Event()

    async def run(self) -> None:
        """Republish results until :meth:`stop`; resubscribes after a Redis outage."""
        while not self._stopped.is_set():
            try:
                await self._follow()
            except REDIS_DOWN as exc:
                self.subscribed.clear()
                log.warning("results channel lost (%s); resubscribing", exc)
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._stopped.wait(), 1.0)

    async def stop(self) -> None:
        """Make :meth:`run` return."""
        self._stopped.set()

    async def _follow(self) -> None:
        pubsub = self.backend.redis.pubsub()
        try:
            await pubsub.subscribe(self.backend.keys.results_channel)
            self.subscribed.set()
            while not self._stopped.is_set():
                message = await pubsub.get_message(ignore_subscribe_messages=True, timeout=1.0)
                if message is not None:
                    await self.publish(str(message["data"]))
        finally:
            with contextlib.suppress(*REDIS_DOWN):
                await pubsub.aclose()

    async def publish(self, envelope: str) -> None:
        """Publish one results-channel message (a malformed one is logged and skipped)."""
        try:
            data = json.loads(envelope)
            site_id = str(data["site_id"])
            result = ResultModel.model_validate(data["result"])
        except (ValueError, KeyError, TypeError, ValidationError) as exc:
            log.warning("skipping malformed result message: %s", exc)
            return
        await asyncio.to_thread(self._put_result, site_id, result)
        if self.ros is not None:
            await self.ros.publish_result(site_id, result)

    def _put_result(self, site_id: str, result: ResultModel) -> None:
        block = zenoh.CongestionControl.BLOCK
        json_encoding = zenoh.Encoding.APPLICATION_JSON
        self.session.put(
            self.keys.result(site_id),
            result.model_dump_json(),
            encoding=json_encoding,
            congestion_control=block,
        )
        for update in pose_updates(result):
            self.session.put(
                self.keys.pose(site_id, update.fragment_id),
                update.model_dump_json(),
                encoding=json_encoding,
                congestion_control=block,
            )
