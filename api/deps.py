"""Dependencies of the routes, as ``Annotated`` aliases (ids, the backend, auth, sites,
hints)."""

from __future__ import annotations

import hmac
from typing import Annotated, cast

from fastapi import Depends, Path, Query, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from api.errors import (
    ForbiddenError,
    HintsNotFoundError,
    SiteNotFoundError,
    UnauthorizedError,
    check_id,
)
from api.hints import load_hints
from api.site_data import site_exists
from schemas.hints import HintsModel
from schemas.ids import ID_RULE
from store.backend import Backend

__all__ = [
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

_bearer = HTTPBearer(auto_error=False, description="one of the tokens of FPJ_TOKENS")


def _check_token(tokens: list[str], given: str | None) -> None:
    if not tokens:
        return
    if given is None:
        raise UnauthorizedError("a bearer token is required (Authorization: Bearer <token>)")
    if not any(hmac.compare_digest(given.encode(), token.encode()) for token in tokens):
        raise ForbiddenError("unknown bearer token")


async def require_token(
    backend: BackendDep,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> None:
    """With tokens configured: 401 without a bearer token, 403 with an unknown one."""
    _check_token(backend.settings.tokens, credentials.credentials if credentials else None)


async def require_stream_token(
    backend: BackendDep,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
    access_token: Annotated[
        str | None,
        Query(
            description="the bearer token, for clients that cannot set headers (a browser's "
            "EventSource); only read when FPJ_TOKENS is set and no Authorization header is sent"
        ),
    ] = None,
) -> None:
    """:func:`require_token` that also takes ``?access_token=`` (the event stream only)."""
    given = credentials.credentials if credentials else access_token
    _check_token(backend.settings.tokens, given)
