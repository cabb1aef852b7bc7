"""Bearer tokens checked against their scopes (``FPJ_TOKENS``), the one check HTTP routes,
the event stream and the zenoh front end share.

No token configured: everyone may do everything (a service on localhost). Otherwise a
missing token is ``unauthorized`` (401), an unknown one ``forbidden`` (403) and a known one
without the right on the site ``insufficient_scope`` (403, RFC 6750's name for it).
"""

from __future__ import annotations

import hmac
from collections.abc import Mapping

from api.errors import ForbiddenError, InsufficientScopeError, UnauthorizedError
from schemas.access import FULL, Right, Scope

__all__ = ["authorize", "token_scope"]


def token_scope(tokens: Mapping[str, Scope], given: str | None, how: str) -> Scope:
    """The scope of ``given`` (every token compared in constant time, so the time taken
    says nothing about which one nearly matched); ``how`` tells a client where a token goes.
    """
    if not tokens:
        return FULL
    if given is None:
        raise UnauthorizedError(f"a bearer token is required ({how})")
    found = None
    for token, scope in tokens.items():
        if hmac.compare_digest(given.encode(), token.encode()):
            found = scope
    if found is None:
        raise ForbiddenError("unknown bearer token")
    return found


def authorize(
    tokens: Mapping[str, Scope],
    given: str | None,
    right: Right,
    site_id: str | None,
    how: str = "Authorization: Bearer <token>",
    *,
    anywhere: bool = False,
) -> Scope:
    """The scope of ``given`` if it has ``right`` on ``site_id`` (``None``: on every site;
    with ``anywhere``, on at least one site: the caller filters its answer by the scope).

    Raises
    ------
    UnauthorizedError
        Tokens are configured and none was given.
    ForbiddenError
        The token is unknown (``forbidden``) or lacks the right there
        (:class:`InsufficientScopeError`).
    """
    scope = token_scope(tokens, given, how)
    if not (right in scope.rights if anywhere else scope.allows(right, site_id)):
        where = "any site" if anywhere else "every site" if site_id is None else f"site {site_id!r}"
        raise InsufficientScopeError(f"this token has no {right} right on {where}")
    return scope
