"""The zenoh front end of the service: one session next to the HTTP API (contract section 5).

Started and stopped by the app's lifespan (:func:`api.zenoh.zenoh_front_end`). Everything it
stores goes through the same code as HTTP, on the app's event loop:

- ingest queryable and subscriber on ``fpj/sites/*/fragments/*`` ->
  :func:`api.ingest.ingest_fragment`; a query gets the HTTP PUT's JSON, or the HTTP error
  body as a zenoh error reply; an attachment ``prior`` goes into the site's hints
  (:mod:`api.zenoh.ingest`);
- result queryable on ``fpj/sites/*/result`` -> the stored result (errors: ``site_not_found``,
  ``result_pending``); a wildcard site (``fpj/sites/*/result``) gets every site's result;
- ``fpj/service`` -> :class:`schemas.zenoh.ServiceInfo` (limits robots check before sending);
- results and poses published from the Redis results channel (:mod:`api.zenoh.publisher`);
- robot presence from liveliness tokens (:mod:`api.zenoh.robots`);
- ROS 2 topics over rmw_zenoh, if configured (:mod:`api.zenoh.ros_bridge`).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from functools import partial
from typing import Any

import zenoh

from api.auth import authorize
from api.errors import SiteNotFoundError, check_id
from api.limits import check_upload_rate, client_id
from api.site_data import load_result, site_exists
from api.zenoh.bridge import LoopBridge, error_of, reply_error, reply_json
from api.zenoh.ingest import attachment_prior, ingest_with_sender, parse_tag
from api.zenoh.publisher import ResultPublisher
from api.zenoh.robots import RobotTracker
from api.zenoh.ros_bridge import RosBridge
from schemas.access import Right, Scope
from schemas.service import UploadReply
from schemas.zenoh import RobotTag, SenderRecord, ServiceInfo
from services.errors import JigsawError
from store.backend import Backend
from store.connection import strings
from transport.config import build_config, reachable_from_network, service_options
from transport.keys import ZenohKeys

__all__ = ["Request", "ResultPendingError", "ZenohFront"]

log = logging.getLogger(__name__)

_DRAIN_S = 10.0  # shutdown: wait this long for queries still being answered


@dataclass(frozen=True)
class Request:
    """What a handler needs of a query, copied on the zenoh thread."""

    key: str
    payload: bytes
    attachment: bytes | None
    parameters: dict[str, str]

    @classmethod
    def of(cls, query: zenoh.Query) -> Request:
        """The parts of ``query`` a handler reads (its parameters: robot id and token)."""
        found = {name: query.parameters.get(name) for name in ("robot_id", "token")}
        return cls(
            key=str(query.key_expr),
            payload=query.payload.to_bytes() if query.payload is not None else b"",
            attachment=query.attachment.to_bytes() if query.attachment is not None else None,
            parameters={name: value for name, value in found.items() if value is not None},
        )

    def tag(self) -> RobotTag:
        """Robot id and token (attachment, else ``?robot_id=...;token=...``)."""
        return parse_tag(self.attachment, self.parameters)


Handler = Callable[[Request], Awaitable[list[tuple[str, str]]]]


class ResultPendingError(JigsawError):
    """The site exists but nothing has been placed yet (HTTP: 202 processing)."""

    code = "result_pending"


class ZenohFront:
    """The service's zenoh session and everything declared on it."""

    def __init__(self, backend: Backend, session: zenoh.Session, bridge: LoopBridge) -> None:
        self.backend, self.session, self.bridge = backend, session, bridge
        self.settings = backend.settings
        self.keys = ZenohKeys(self.settings.zenoh_prefix)
        self.front_id = str(session.zid())
        self.ros = RosBridge(backend, session, bridge) if self.settings.ros_enabled else None
        self.robots = RobotTracker(backend, self.keys, self.front_id, bridge)
        self.publisher = ResultPublisher(backend, session, self.keys, self.ros)
        self._declared: list[Any] = []
        self._tasks: list[asyncio.Task[None]] = []
        self._put_order = asyncio.Lock()

    @classmethod
    async def start(cls, backend: Backend) -> ZenohFront:
        """Open the session (``FPJ_ZENOH_*``), declare everything, start the publishers."""
        options = service_options(backend.settings)
        try:
            session = await asyncio.to_thread(zenoh.open, build_config(options))
        except zenoh.ZError as exc:
            log.error(
                "cannot open the zenoh session (%s; FPJ_ZENOH_LISTEN=none turns it off): %s",
                options.listen or options.connect,
                exc,
            )
            raise
        front = cls(backend, session, LoopBridge(asyncio.get_running_loop()))
        try:
            front._declare()
        except zenoh.ZError:
            await asyncio.to_thread(session.close)
            raise
        front._tasks = [
            asyncio.create_task(front.publisher.run(), name="zenoh-results"),
            asyncio.create_task(front.robots.run(), name="zenoh-presence"),
        ]
        open_to = [e for e in options.listen if reachable_from_network(e)]
        if open_to and options.access_control is None:
            log.warning(
                "zenoh listens on %s without access control: any peer that connects can "
                "subscribe to results and poses%s (README, Zenoh security: FPJ_ZENOH_ACL)",
                ", ".join(open_to),
                "" if backend.settings.tokens else " and send fragments",
            )
        log.info(
            "zenoh front end %s (%s) listening on %s, connecting to %s",
            front.front_id,
            options.mode,
            options.listen or "-",
            options.connect or "-",
        )
        return front

    def _declare(self) -> None:
        s, keys = self.session, self.keys
        self._declared = [
            s.declare_queryable(
                keys.all_fragments, partial(self._on_query, self._ingest_query), complete=True
            ),
            s.declare_subscriber(keys.all_fragments, self._on_ingest_put),
            s.declare_queryable(keys.all_results, partial(self._on_query, self._result_query)),
            s.declare_queryable(keys.service, self._on_service_query, complete=True),
            self.robots.declare(s),
        ]
        if self.ros is not None:
            self._declared += self.ros.declare()

    async def stop(self) -> None:
        """Stop taking work, answer the queries in flight, then close the session."""
        for entity in reversed(self._declared):
            entity.undeclare()
        await self.bridge.drain(_DRAIN_S)
        await self.publisher.stop()
        await self.robots.stop()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        await asyncio.to_thread(self.session.close)
        log.info("zenoh front end %s closed", self.front_id)

    # ------------------------------------------------------------ queries

    def _on_query(self, handler: Handler, query: zenoh.Query) -> None:  # zenoh thread
        request = Request.of(query)
        if not self.bridge.submit(self._answer(handler, query, request)):
            with query:
                reply_error(query, "unavailable", "the service is shutting down")

    async def _answer(self, handler: Handler, query: zenoh.Query, request: Request) -> None:
        """Run ``handler`` on the loop and reply; every failure becomes the error body."""
        with query:
            try:
                replies = await handler(request)
            except Exception as exc:  # the querier always gets an answer
                if error_of(exc)[0] == "internal_error":
                    log.error("zenoh query on %s failed", request.key, exc_info=exc)
                reply_error(query, *error_of(exc))
                return
            for key, body in replies:
                reply_json(query, key, body)

    async def _ingest_query(self, request: Request) -> list[tuple[str, str]]:
        reply = await self._ingest(
            request.key, request.payload, request.attachment, request.parameters
        )
        return [(request.key, reply.model_dump_json())]

    def _authorize(self, tag: RobotTag, right: Right, site_id: str) -> Scope:
        """As over HTTP; a wildcard site (a result query on ``fpj/sites/*/result``) needs the
        right on one site and gets the results of the token's sites only."""
        how = 'attachment {"token": "..."} or ?token='
        anywhere = "*" in site_id
        site = None if anywhere else site_id
        return authorize(self.settings.tokens, tag.token, right, site, how, anywhere=anywhere)

    async def _result_query(self, request: Request) -> list[tuple[str, str]]:
        scope = self._authorize(request.tag(), "read", self.keys.parse_result(request.key) or "")
        found = await self._results(request.key)
        return [(self.keys.result(site), body) for site, body in found if scope.covers(site)]

    # ------------------------------------------------------------ puts

    def _on_ingest_put(self, sample: zenoh.Sample) -> None:  # zenoh thread
        if sample.kind != zenoh.SampleKind.PUT:
            return
        key = str(sample.key_expr)
        attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
        self.bridge.submit(self._ingest_put(key, sample.payload.to_bytes(), attachment))

    async def _ingest_put(self, key: str, data: bytes, attachment: bytes | None) -> None:
        """Ingest a put; puts are stored in the order they arrived (no reply to wait for)."""
        try:
            async with self._put_order:
                reply = await self._ingest(key, data, attachment)
        except Exception as exc:  # nobody to answer: log it
            code, message = error_of(exc)
            log.warning("put on %s rejected: %s: %s", key, code, message)
            if code == "internal_error":
                log.error("zenoh put on %s failed", key, exc_info=exc)
            return
        log.info("put on %s accepted (%s)", key, "new" if reply.created else "already stored")

    async def _ingest(
        self,
        key: str,
        data: bytes,
        attachment: bytes | None,
        parameters: dict[str, str] | None = None,
    ) -> UploadReply:
        """Tag and token first, then the prior (refused before anything is stored)."""
        tag = parse_tag(attachment, parameters)
        site_id, fragment_id = self.keys.parse_fragment(key) or ("", "")
        self._authorize(tag, "upload", site_id)
        token = tag.token if self.settings.tokens else None  # unchecked, it proves nothing
        await check_upload_rate(self.backend, client_id(token, f"robot:{tag.robot_id or '-'}"))
        prior = attachment_prior(attachment)
        sender = SenderRecord(robot_id=tag.robot_id) if tag.robot_id else None
        return await ingest_with_sender(self.backend, site_id, fragment_id, data, sender, prior)

    # ------------------------------------------------------------ results and info

    async def _results(self, key: str) -> list[tuple[str, str]]:
        """(site id, result JSON) answering a result query; one site or a wildcard."""
        site = self.keys.parse_result(key) or ""
        if "*" not in site:
            check_id(site, "site id")
            body = await load_result(self.backend, site)
            if body is not None:
                return [(site, body)]
            if await site_exists(self.backend, site):
                raise ResultPendingError(f"nothing of site {site!r} has been placed yet")
            raise SiteNotFoundError(f"unknown site {site!r}")
        asked = zenoh.KeyExpr(key)
        sites = strings(await self.backend.redis.zrange(self.backend.keys.sites, 0, -1))
        found = []
        for site_id in sites:
            if asked.intersects(self.keys.result(site_id)):
                body = await load_result(self.backend, site_id)
                if body is not None:
                    found.append((site_id, body))
        return found

    def _on_service_query(self, query: zenoh.Query) -> None:  # zenoh thread
        with query:
            info = ServiceInfo(
                prefix=self.keys.prefix,
                max_upload_bytes=self.settings.max_upload_bytes,
                max_message_bytes=self.settings.zenoh_rx_max_message_size,
            )
            reply_json(query, self.keys.service, info.model_dump_json())
