"""Service errors, and the one mapping from errors to HTTP status codes and bodies.

Every error response has the body ``{"error": {"code": ..., "message": ...}}``; no handler
ever answers with a traceback.
"""

from __future__ import annotations

import logging
from typing import Any

import redis
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from schemas.ids import ID_RULE, is_valid_id
from schemas.service import ErrorBody, ErrorDetail
from schemas.validation import summarize_errors
from services.errors import (
    FragmentError,
    FragmentTooLargeError,
    InvalidFragmentError,
    JigsawError,
    UnsupportedFormatError,
)

__all__ = [
    "ConflictError",
    "ForbiddenError",
    "FragmentNotFoundError",
    "HintsNotFoundError",
    "HintsTooLargeError",
    "InsufficientScopeError",
    "InvalidHintsError",
    "InvalidIdError",
    "InvalidPriorError",
    "LayoutNotFoundError",
    "NotFoundError",
    "ServiceError",
    "SiteNotFoundError",
    "UnauthorizedError",
    "UnavailableError",
    "check_id",
    "error_body",
    "error_responses",
    "install_error_handlers",
    "status_for",
]

log = logging.getLogger(__name__)


class ServiceError(JigsawError):
    """Failures of the service itself (as opposed to a fragment's content)."""

    code = "service_error"


class InvalidIdError(ServiceError):
    """An id that does not match :data:`schemas.ids.ID_PATTERN`."""

    code = "invalid_id"


class NotFoundError(ServiceError):
    """Something the request names does not exist."""

    code = "not_found"


class SiteNotFoundError(NotFoundError):
    """No fragment or hints of this site were ever accepted (or it was deleted)."""

    code = "site_not_found"


class FragmentNotFoundError(NotFoundError):
    """The site holds no fragment of this id."""

    code = "fragment_not_found"


class HintsNotFoundError(NotFoundError):
    """No hints were given for this site."""

    code = "hints_not_found"


class LayoutNotFoundError(NotFoundError):
    """The newest result places no fragment: there is no layout model to export."""

    code = "layout_not_found"


class InvalidHintsError(ServiceError):
    """Hints that are not JSON, have unknown fields or invalid values (contract section 2)."""

    code = "invalid_hints"


class InvalidPriorError(InvalidHintsError):
    """A fragment's ``prior`` (zenoh attachment) that is not a valid hints entry."""

    code = "invalid_prior"


class HintsTooLargeError(InvalidHintsError):
    """A hints body larger than the hints limit."""

    code = "hints_too_large"


class ConflictError(ServiceError):
    """Different bytes under an id that already holds a fragment."""

    code = "conflict"


class UnauthorizedError(ServiceError):
    """No token where tokens are configured."""

    code = "unauthorized"


class ForbiddenError(ServiceError):
    """An unknown token."""

    code = "forbidden"


class InsufficientScopeError(ForbiddenError):
    """A known token without the right asked for on this site (schemas.access)."""

    code = "insufficient_scope"


class UnavailableError(ServiceError):
    """Redis (or something else the service needs) cannot be reached right now."""

    code = "unavailable"


# The one mapping. The most specific class in an error's MRO decides.
_STATUS: dict[type[JigsawError], int] = {
    InvalidIdError: 400,
    UnauthorizedError: 401,
    ForbiddenError: 403,
    NotFoundError: 404,
    ConflictError: 409,
    FragmentTooLargeError: 413,
    HintsTooLargeError: 413,
    UnsupportedFormatError: 415,
    InvalidFragmentError: 422,
    FragmentError: 422,
    InvalidHintsError: 422,
    UnavailableError: 503,
}

_DESCRIPTIONS = {
    400: f"invalid id ({ID_RULE})",
    401: "missing bearer token",
    403: "unknown bearer token (forbidden), or one without this right on this site "
    "(insufficient_scope)",
    404: "unknown site or fragment, no hints stored, or nothing placed to export",
    409: "different bytes already stored under this fragment id",
    413: "body too large (bytes or points; an archive with too many or too large entries)",
    415: "not a PLY or PCD file, nor an RGB-D frame's zip archive",
    422: "invalid content: empty, truncated, malformed, too few finite points; a hostile or "
    "truncated archive, a depth image not 16-bit single-channel or all zero, intrinsics "
    "missing or not matching, colour of another size; invalid hints",
    503: "Redis unreachable; retry later",
}


def status_for(exc: JigsawError) -> int:
    """HTTP status of an error (500 for anything not mapped)."""
    for cls in type(exc).__mro__:
        if cls in _STATUS:
            return _STATUS[cls]
    return 500


def check_id(value: str, what: str) -> str:
    """Return ``value`` if it is a valid site or fragment id, else raise InvalidIdError."""
    if not is_valid_id(value):
        raise InvalidIdError(f"invalid {what} {value[:80]!r}: use {ID_RULE}")
    return value


def error_body(code: str, message: str) -> dict[str, Any]:
    """The JSON body of an error response."""
    return ErrorBody(error=ErrorDetail(code=code, message=message)).model_dump()


def error_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` entries declaring the error body for each status."""
    return {s: {"model": ErrorBody, "description": _DESCRIPTIONS[s]} for s in statuses}


def _headers(status: int) -> dict[str, str] | None:
    if status == 401:
        return {"WWW-Authenticate": "Bearer"}
    if status == 503:
        return {"Retry-After": "1"}
    return None


def jigsaw_response(exc: JigsawError) -> JSONResponse:
    status = status_for(exc)
    if status >= 500:
        log.log(logging.INFO if status == 503 else logging.ERROR, "%s: %s", exc.code, exc.message)
    body = error_body(exc.code, exc.message)
    return JSONResponse(body, status_code=status, headers=_headers(status))


async def _on_jigsaw(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, JigsawError)
    return jigsaw_response(exc)


async def _on_redis_down(request: Request, exc: Exception) -> JSONResponse:
    return jigsaw_response(UnavailableError(f"storage unavailable: {type(exc).__name__}: {exc}"))


async def _on_validation(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, RequestValidationError)
    return JSONResponse(error_body("invalid_request", summarize_errors(exc.errors())), 422)


async def _on_http(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, StarletteHTTPException)
    codes = {404: "not_found", 405: "method_not_allowed"}
    body = error_body(codes.get(exc.status_code, "http_error"), str(exc.detail))
    return JSONResponse(body, status_code=exc.status_code, headers=exc.headers)


async def _on_unexpected(request: Request, exc: Exception) -> JSONResponse:
    log.exception("unexpected error on %s %s", request.method, request.url.path, exc_info=exc)
    return JSONResponse(error_body("internal_error", "internal server error"), status_code=500)


def install_error_handlers(app: FastAPI) -> None:
    """Register the handlers that turn every failure into the contract's error body."""
    app.add_exception_handler(JigsawError, _on_jigsaw)
    app.add_exception_handler(redis.exceptions.ConnectionError, _on_redis_down)
    app.add_exception_handler(redis.exceptions.TimeoutError, _on_redis_down)
    app.add_exception_handler(RequestValidationError, _on_validation)
    app.add_exception_handler(StarletteHTTPException, _on_http)
    app.add_exception_handler(Exception, _on_unexpected)
