"""``/v1/sites/{site_id}/events``: server-sent events of a site's progress and results."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import StreamingResponse

from api.deps import BackendDep, SiteId
from api.errors import error_responses
from api.events import site_event_stream

__all__ = ["router"]

router = APIRouter(prefix="/v1/sites", tags=["events"])


@router.get(
    "/{site_id}/events",
    summary="Server-sent events: status snapshot, then fragment, placement, result events "
    "(also before the site exists)",
    response_class=StreamingResponse,
    responses={
        200: {"content": {"text/event-stream": {}}, "description": "event stream"},
        **error_responses(400, 401, 403, 503),
    },
)
async def site_events(site_id: SiteId, backend: BackendDep) -> StreamingResponse:
    """Works before the site's first upload too: the ``status`` event then has no fragments
    and ``created_at`` null, and the events of the first upload follow. With FPJ_TOKENS set,
    the token may come as ``?access_token=`` (a browser's EventSource cannot set headers)."""
    return StreamingResponse(
        site_event_stream(backend, site_id),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"},
    )
