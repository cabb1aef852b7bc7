"""``/v1/sites``: the list, a site's status and deletion, its result, a picture of its
floorplan and its 3D layout model (glTF)."""

from __future__ import annotations

import json
from typing import Annotated, Any

from fastapi import APIRouter, Query, Response
from fastapi.responses import JSONResponse

from api.deps import Access, BackendDep, ExistingSite
from api.errors import LayoutNotFoundError, error_responses
from api.floorplan_svg import render_floorplan_svg
from api.site_data import delete_site, list_sites, load_result, load_site_status
from schemas.result import ResultModel
from schemas.service import PendingReply, SiteList, SiteStatus

__all__ = ["router"]

router = APIRouter(prefix="/v1/sites", tags=["sites"])

_PENDING: dict[int | str, dict[str, Any]] = {
    202: {"model": PendingReply, "description": "nothing has been placed yet"}
}


def _pending(site_id: str) -> JSONResponse:
    return JSONResponse(PendingReply(site_id=site_id).model_dump(), status_code=202)


@router.get("", summary="List sites", responses=error_responses(401, 403, 503))
async def get_sites(
    backend: BackendDep,
    access: Access,
    offset: Annotated[int, Query(ge=0)] = 0,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
) -> SiteList:
    """The sites the token may read (all of them without tokens or with a ``*`` token)."""
    only = None if access.all_sites else access.sites
    return await list_sites(backend, offset, limit, only)


@router.get(
    "/{site_id}",
    summary="Status of a site: its fragments' processing and its placement",
    responses=error_responses(400, 401, 403, 404, 503),
)
async def get_site(site_id: ExistingSite, backend: BackendDep) -> SiteStatus:
    return await load_site_status(backend, site_id)


@router.delete(
    "/{site_id}",
    status_code=204,
    summary="Delete a site and everything stored for it (contract section 4)",
    responses=error_responses(400, 401, 403, 404, 503),
)
async def remove_site(site_id: ExistingSite, backend: BackendDep) -> Response:
    """Fragments, layouts, result, hints and status go; queued jobs of the site do nothing."""
    await delete_site(backend, site_id)
    return Response(status_code=204)


@router.get(
    "/{site_id}/result",
    summary="Result JSON of the newest global placement (contract section 3)",
    response_model=ResultModel,
    responses={
        200: {"description": "the result (status closed, ambiguous, open or failed)"},
        **_PENDING,
        **error_responses(400, 401, 403, 404, 503),
    },
)
async def get_result(site_id: ExistingSite, backend: BackendDep) -> Response:
    body = await load_result(backend, site_id)
    if body is None:
        return _pending(site_id)
    return Response(body, media_type="application/json")


@router.get(
    "/{site_id}/floorplan.svg",
    summary="Picture of the current floorplan and fragment placements",
    response_class=Response,
    responses={
        200: {"content": {"image/svg+xml": {}}, "description": "SVG picture"},
        **_PENDING,
        **error_responses(400, 401, 403, 404, 503),
    },
)
async def get_floorplan_svg(site_id: ExistingSite, backend: BackendDep) -> Response:
    body = await load_result(backend, site_id)
    if body is None:
        return _pending(site_id)
    svg = render_floorplan_svg(ResultModel.model_validate_json(body), title=site_id)
    return Response(svg, media_type="image/svg+xml")


@router.get(
    "/{site_id}/layout.gltf",
    summary="3D layout model of the newest result (glTF 2.0, site frame turned y-up)",
    response_class=Response,
    responses={
        200: {"content": {"model/gltf+json": {}}, "description": "glTF 2.0 JSON"},
        **_PENDING,
        **error_responses(400, 401, 403, 404, 503),
    },
)
async def get_layout_gltf(site_id: ExistingSite, backend: BackendDep) -> Response:
    """Walls, floor and ceiling of a closed room; the walls of the placed fragments
    otherwise (as ``jigsaw align --model x.gltf``). 404 ``layout_not_found`` when the newest
    result places nothing."""
    from services.model_export import layout_model, mesh_gltf

    body = await load_result(backend, site_id)
    if body is None:
        return _pending(site_id)
    mesh = layout_model(ResultModel.model_validate_json(body))
    if mesh is None or len(mesh.triangles) == 0:
        raise LayoutNotFoundError(f"site {site_id!r}: the newest result places no fragment")
    gltf = json.dumps(mesh_gltf(mesh, name=site_id))
    headers = {"Content-Disposition": f'attachment; filename="{site_id}-layout.gltf"'}
    return Response(gltf, media_type="model/gltf+json", headers=headers)
