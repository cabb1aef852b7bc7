"""``/metrics``: Prometheus text exposition."""

from __future__ import annotations

from fastapi import APIRouter, Response
from prometheus_client import CONTENT_TYPE_LATEST

from api.deps import BackendDep
from api.errors import error_responses
from api.metrics import render_metrics

__all__ = ["router"]

router = APIRouter(tags=["metrics"])


@router.get(
    "/metrics",
    summary="Uploads, jobs by state, job durations, queue depth, live workers",
    response_class=Response,
    responses={
        200: {"content": {CONTENT_TYPE_LATEST: {}}, "description": "Prometheus text format"},
        **error_responses(401, 403, 503),
    },
)
async def metrics(backend: BackendDep) -> Response:
    return Response(await render_metrics(backend), media_type=CONTENT_TYPE_LATEST)
