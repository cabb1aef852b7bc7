"""A site's server-sent-event stream, fed by the site's Redis channel.

The stream starts with ``retry``, an ``event: status`` (the SiteStatus; for a site that does not
exist yet, one with no fragment and ``created_at`` null) and, if the site has been placed, an
``event: result``; then every SiteEvent published by workers and the API
(``fragment``, ``placement``, ``result``), and a comment line when idle so proxies keep it open.
It ends after a ``site`` event (the site was deleted).
"""

from __future__ import annotations

import json
from collections.abc import AsyncIterator

import anyio

from api.site_data import load_result, load_site_status, site_exists
from schemas.service import PlacementStatus, SiteStatus
from store.backend import Backend
from store.records import site_event

__all__ = ["format_sse", "site_event_stream"]


def format_sse(event: str, data: str) -> str:
    """One server-sent event (``data`` is a single JSON line)."""
    return f"event: {event}\ndata: {data}\n\n"


async def _initial(backend: Backend, site_id: str) -> list[str]:
    if await site_exists(backend, site_id):
        status = await load_site_status(backend, site_id)
    else:  # subscribed before the first upload: an empty site, not yet created
        status = SiteStatus(
            site_id=site_id,
            created_at=None,
            updated_at=None,
            fragments=[],
            placement=PlacementStatus(),
        )
    messages = [format_sse("status", status.model_dump_json())]
    result = await load_result(backend, site_id)
    if result is not None:
        generation = status.placement.result_generation
        event = site_event("result", site_id, json.loads(result), generation=generation)
        messages.append(format_sse("result", event))
    return messages


async def site_event_stream(backend: Backend, site_id: str) -> AsyncIterator[str]:
    """Yield the SSE text of a site until the client goes away (or Redis does)."""
    pubsub = backend.redis.pubsub()
    try:
        # Subscribe before reading the snapshot, so nothing falls between the two.
        await pubsub.subscribe(backend.keys.site_channel(site_id))
        yield "retry: 2000\n\n"
        for message in await _initial(backend, site_id):
            yield message
        keepalive = backend.settings.sse_keepalive_s
        while True:
            message = await pubsub.get_message(ignore_subscribe_messages=True, timeout=keepalive)
            if message is None:
                yield ": keepalive\n\n"
                continue
            data = str(message["data"])
            kind = str(json.loads(data).get("type", "message"))
            yield format_sse(kind, data)
            if kind == "site":  # deleted: nothing more will come
                return
    finally:
        with anyio.CancelScope(shield=True):
            await pubsub.aclose()
