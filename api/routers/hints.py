"""``/v1/sites/{site_id}/hints``: what a fleet already knows about a site (contract section 2).

``PUT`` replaces the site's hints (creating the site if it is new, so hints may come before
the first scan) and has the site placed again; ``GET`` returns them.
"""

from __future__ import annotations

from fastapi import APIRouter, Request

from api.body import openapi_body, read_limited
from api.deps import BackendDep, SiteHints, SiteId
from api.errors import HintsTooLargeError, error_responses
from api.hints import MAX_HINTS_BYTES, parse_hints, replace_hints
from schemas.hints import HintsModel

__all__ = ["router"]

router = APIRouter(prefix="/v1/sites/{site_id}/hints", tags=["hints"])

# The body is parsed here (not by FastAPI) so that invalid hints answer `invalid_hints`; the
# schema is the component FastAPI generates for the GET reply.
_BODY = openapi_body(
    "the hints JSON: prior poses, known neighbours, known order",
    "application/json",
    {"$ref": "#/components/schemas/HintsModel"},
)


@router.put(
    "",
    summary="Set the site's hints (replacing earlier ones); the site is placed again",
    openapi_extra=_BODY,
    responses={
        200: {"description": "the stored hints"},
        **error_responses(400, 401, 403, 413, 422, 503),
    },
)
async def put_hints(site_id: SiteId, request: Request, backend: BackendDep) -> HintsModel:
    """Validate and store the hints (unknown fields refused), then request a placement."""
    hints = parse_hints(await read_limited(request, MAX_HINTS_BYTES, HintsTooLargeError))
    await replace_hints(backend, site_id, hints)
    return hints


@router.get(
    "",
    summary="The site's hints",
    responses=error_responses(400, 401, 403, 404, 503),
)
async def get_hints(hints: SiteHints) -> HintsModel:
    return hints
