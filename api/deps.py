"""Dependencies of the routes, as ``Annotated`` aliases (ids, the backend, auth, sites,
hints)."""

from __future__ import annotations

from typing import Annotated, cast

from fastapi import Depends, Path, Query, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from api.auth import authorize
from api.errors import HintsNotFoundError, SiteNotFoundError, check_id
from api.hints import load_hints
from api.site_data import site_exists
from schemas.access import Right, Scope
from schemas.hints import HintsModel
from schemas.ids import ID_RULE
from store.backend import Backend

__all__ = [
    "Access",
    "BackendDep",
    "ExistingSite",
    "FragmentId",
    "SiteHints",
    "SiteId",
    "get_backend",
    "require_stream_token",
    "require_token",
]


def get_backend(request: Request) -> Backend:
    """The backend the app's lifespan connected."""
    return cast(Backend, request.app.state.backend)


BackendDep = Annotated[Backend, Depends(get_backend)]


def _site_id(site_id: Annotated[str, Path(description=f"site id, {ID_RULE}")]) -> str:
    return check_id(site_id, "site id")


def _fragment_id(
    fragment_id: Annotated[str, Path(description=f"fragment id, {ID_RULE}")],
) -> str:
    return check_id(fragment_id, "fragment id")


SiteId = Annotated[str, Depends(_site_id)]
FragmentId = Annotated[str, Depends(_fragment_id)]


async def _existing_site(site_id: SiteId, backend: BackendDep) -> str:
    if not await site_exists(backend, site_id):
        raise SiteNotFoundError(f"unknown site {site_id!r}")
    return site_id


ExistingSite = Annotated[str, Depends(_existing_site)]


async def _site_hints(site_id: ExistingSite, backend: BackendDep) -> HintsModel:
    hints = await load_hints(backend, site_id)
    if hints is None:
        raise HintsNotFoundError(f"site {site_id!r} has no hints")
    return hints


SiteHints = Annotated[HintsModel, Depends(_site_hints)]

_bearer = HTTPBearer(auto_error=False, description="a token of FPJ_TOKENS")

# The right a request needs follows from its method: every GET only reads, every PUT stores
# (fragments, hints), every DELETE removes; a method not listed needs the strongest right.
_RIGHT_OF_METHOD: dict[str, Right] = {"GET": "read", "HEAD": "read", "PUT": "upload"}

# Site-less routes that answer only with what the token's sites hold (the site list): a
# token with the right on any one site may call them. Every other site-less route (metrics)
# needs the right on every site.
_FILTERED_PATHS = frozenset({"/v1/sites"})


def _authorize(request: Request, given: str | None, how: str) -> Scope:
    settings = get_backend(request).settings
    right = _RIGHT_OF_METHOD.get(request.method, "delete")
    route = getattr(request.scope.get("route"), "path", None)
    site_id = request.path_params.get("site_id")
    anywhere = site_id is None and route in _FILTERED_PATHS
    return authorize(settings.tokens, given, right, site_id, how, anywhere=anywhere)


async def require_token(
    request: Request,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> Scope:
    """With tokens configured: 401 without a bearer token, 403 with an unknown one or one
    without the request's right (GET read, PUT upload, DELETE delete) on the path's site."""
    given = credentials.credentials if credentials else None
    return _authorize(request, given, "Authorization: Bearer <token>")


Access = Annotated[Scope, Depends(require_token)]


async def require_stream_token(
    request: Request,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
    access_token: Annotated[
        str | None,
        Query(
            description="the bearer token, for clients that cannot set headers (a browser's "
            "EventSource); only read when FPJ_TOKENS is set and no Authorization header is sent"
        ),
    ] = None,
) -> Scope:
    """:func:`require_token` that also takes ``?access_token=`` (the event stream only)."""
    given = credentials.credentials if credentials else access_token
    return _authorize(request, given, "Authorization: Bearer <token> or ?access_token=")
