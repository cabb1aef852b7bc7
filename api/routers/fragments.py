"""``/v1/sites/{site_id}/fragments/{fragment_id}``: upload, inspect, delete a fragment."""

from __future__ import annotations

from fastapi import APIRouter, Request, Response
from fastapi.responses import JSONResponse

from api.body import openapi_body, read_limited
from api.deps import BackendDep, ExistingSite, FragmentId, SiteId
from api.errors import error_responses
from api.ingest import ingest_fragment
from api.limits import check_upload_rate, http_client_id
from api.site_data import delete_fragment, load_fragment
from schemas.service import FragmentStatus, UploadReply

__all__ = ["router"]

router = APIRouter(prefix="/v1/sites/{site_id}/fragments", tags=["fragments"])

_BODY = openapi_body(
    "the fragment file's bytes (PLY or PCD)",
    "application/octet-stream",
    {"type": "string", "format": "binary"},
)


@router.put(
    "/{fragment_id}",
    status_code=202,
    response_model=UploadReply,
    summary="Upload a fragment",
    openapi_extra=_BODY,
    responses={
        200: {"model": UploadReply, "description": "identical bytes already stored (no-op)"},
        202: {"model": UploadReply, "description": "accepted; its layout job is queued"},
        **error_responses(400, 401, 403, 408, 409, 413, 415, 422, 429, 503, 507),
    },
)
async def upload_fragment(
    site_id: SiteId, fragment_id: FragmentId, request: Request, backend: BackendDep
) -> JSONResponse:
    """Store a fragment (idempotent by content hash) and queue its processing."""
    await check_upload_rate(backend, http_client_id(request, bool(backend.settings.tokens)))
    data = await read_limited(request, backend.settings.max_upload_bytes)
    reply = await ingest_fragment(backend, site_id, fragment_id, data)
    return JSONResponse(reply.model_dump(mode="json"), status_code=202 if reply.created else 200)


@router.get(
    "/{fragment_id}",
    summary="Status of one fragment",
    responses=error_responses(400, 401, 403, 404, 503),
)
async def get_fragment(
    site_id: ExistingSite, fragment_id: FragmentId, backend: BackendDep
) -> FragmentStatus:
    return await load_fragment(backend, site_id, fragment_id)


@router.delete(
    "/{fragment_id}",
    status_code=204,
    summary="Delete a fragment (the site is re-placed)",
    responses=error_responses(400, 401, 403, 404, 503),
)
async def remove_fragment(
    site_id: ExistingSite, fragment_id: FragmentId, backend: BackendDep
) -> Response:
    await delete_fragment(backend, site_id, fragment_id)
    return Response(status_code=204)
