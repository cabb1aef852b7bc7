"""Assembles the FastAPI application: lifespan, error handlers, routers."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import Depends, FastAPI

from api.deps import require_stream_token, require_token
from api.errors import install_error_handlers
from api.limits import RequestTimeout
from api.routers import events, fragments, health, hints, metrics, sites
from api.routers.web import install_web
from api.zenoh import zenoh_front_end
from schemas.settings import Settings, get_settings
from store.backend import Backend

__all__ = ["create_app"]

DESCRIPTION = """\
Upload partial indoor scans (PLY or PCD fragments) of a site, and optionally what the fleet
already knows (hints: prior poses, neighbours, order); the service estimates each fragment's
wall layout, assembles the layouts into one closed floorplan loop and returns per-fragment
poses, the floorplan, its status (closed, ambiguous, open, failed), a confidence and the
runners-up (contract v2, sections 2 to 4).

Every error answers `{"error": {"code": ..., "message": ...}}`. With `FPJ_TOKENS` set, every
route but `/healthz`, `/readyz` and the web pages needs `Authorization: Bearer <token>` (the
event stream also takes `?access_token=<token>`, for browsers' EventSource), and the token's
right on the route's site: `read` for GET, `upload` for PUT, `delete` for DELETE (`/metrics`:
`read` on every site; the site list shows the token's sites). A web view of the sites is at
`/`.
"""


def create_app(settings: Settings | None = None) -> FastAPI:
    """The service's ASGI app; ``settings`` must carry a Redis URL (default: the environment)."""
    settings = settings or get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        backend = await Backend.connect(settings)
        app.state.backend = backend
        try:
            async with zenoh_front_end(backend):  # off with FPJ_ZENOH_LISTEN=none
                yield
        finally:
            await backend.aclose()

    app = FastAPI(
        title="Floorplan-Jigsaw",
        version="1.0.0",
        description=DESCRIPTION,
        lifespan=lifespan,
        docs_url=None,  # /docs comes from install_web, with local assets
        redoc_url=None,
    )
    install_error_handlers(app)
    app.add_middleware(RequestTimeout, seconds=settings.request_timeout_s)
    auth = [Depends(require_token)]
    app.include_router(health.router)
    app.include_router(metrics.router, dependencies=auth)
    app.include_router(sites.router, dependencies=auth)
    app.include_router(fragments.router, dependencies=auth)
    app.include_router(hints.router, dependencies=auth)
    app.include_router(events.router, dependencies=[Depends(require_stream_token)])
    install_web(app)  # /, /sites/{site_id}, /docs and their static files (no token)
    return app
