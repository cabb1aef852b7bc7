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
from store.connection import redis_reply, storage_refused

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
    "ProcessingTimeoutError",
    "RateLimitedError",
    "RequestTimeoutError",
    "ServiceError",
    "SiteNotFoundError",
    "StorageFullError",
    "TooManyFragmentsError",
    "UnauthorizedError",
    "UnavailableError",
    "check_id",
    "error_body",
    "error_responses",
    "install_error_handlers",
    "status_for",
    "storage_error",
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


class TooManyFragmentsError(ServiceError):
    """The site already holds ``max_fragments_per_site`` fragments."""

    code = "too_many_fragments"


class RateLimitedError(ServiceError):
    """More uploads than ``upload_rate_limit`` in the current window; retry after
    ``retry_after`` seconds."""

    code = "rate_limited"

    def __init__(self, message: str, retry_after: int) -> None:
        super().__init__(message)
        self.retry_after = retry_after


class RequestTimeoutError(ServiceError):
    """The request's body was still arriving after ``request_timeout_s``."""

    code = "request_timeout"


class StorageFullError(ServiceError):
    """Redis refuses writes: its maxmemory is reached (``OOM``), or its data directory's disk
    is full (``MISCONF``, the append-only file cannot be written). Nothing stored is lost;
    reads and deletes still work."""

    code = "storage_full"


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


class ProcessingTimeoutError(UnavailableError):
    """The whole request arrived, but no answer started within ``request_timeout_s``."""

    code = "processing_timeout"


# The one mapping. The most specific class in an error's MRO decides.
_STATUS: dict[type[JigsawError], int] = {
    InvalidIdError: 400,
    UnauthorizedError: 401,
    ForbiddenError: 403,
    NotFoundError: 404,
    RequestTimeoutError: 408,
    ConflictError: 409,
    TooManyFragmentsError: 409,
    FragmentTooLargeError: 413,
    HintsTooLargeError: 413,
    UnsupportedFormatError: 415,
    InvalidFragmentError: 422,
    FragmentError: 422,
    InvalidHintsError: 422,
    RateLimitedError: 429,
    UnavailableError: 503,
    StorageFullError: 507,
}

_DESCRIPTIONS = {
    400: f"invalid id ({ID_RULE})",
    401: "missing bearer token",
    403: "unknown bearer token (forbidden), or one without this right on this site "
    "(insufficient_scope)",
    404: "unknown site or fragment, no hints stored, or nothing placed to export",
    408: "the request body was still arriving after FPJ_REQUEST_TIMEOUT_S",
    409: "different bytes already stored under this fragment id (conflict), or the site "
    "already holds FPJ_MAX_FRAGMENTS_PER_SITE fragments (too_many_fragments)",
    413: "body too large (bytes or points; an archive with too many or too large entries)",
    415: "not a PLY or PCD file, nor an RGB-D frame's zip archive",
    422: "invalid content: empty, truncated, malformed, too few finite points; a hostile or "
    "truncated archive, a depth image not 16-bit single-channel or all zero, intrinsics "
    "missing or not matching, colour of another size; invalid hints",
    429: "more uploads than FPJ_UPLOAD_RATE_LIMIT in the window; retry after Retry-After s",
    503: "Redis unreachable, or no answer within FPJ_REQUEST_TIMEOUT_S; retry later",
    507: "storage full (Redis maxmemory, or its data directory's disk): nothing stored is "
    "lost; delete sites or add room, then retry",
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


def _headers(exc: JigsawError, status: int) -> dict[str, str] | None:
    if status == 401:
        return {"WWW-Authenticate": "Bearer"}
    if isinstance(exc, RateLimitedError):
        return {"Retry-After": str(exc.retry_after)}
    if status == 503:
        return {"Retry-After": "1"}
    return None


def storage_error(exc: redis.exceptions.RedisError) -> JigsawError | None:
    """The service error of a Redis failure: StorageFullError for a refused write (maxmemory
    reached, or the append-only file's disk full), UnavailableError for an unreachable Redis;
    None for anything else (a bug, answered 500)."""
    text = redis_reply(exc)
    if isinstance(exc, redis.exceptions.OutOfMemoryError):
        return StorageFullError(f"storage full: Redis maxmemory reached ({text})")
    if storage_refused(exc):
        return StorageFullError(f"storage full: Redis cannot persist writes ({text})")
    if isinstance(exc, (redis.exceptions.ConnectionError, redis.exceptions.TimeoutError)):
        return UnavailableError(f"storage unavailable: {type(exc).__name__}: {exc}")
    return None


def jigsaw_response(exc: JigsawError) -> JSONResponse:
    status = status_for(exc)
    if status >= 500:
        quiet = status in (503, 507)  # the service works; its storage needs an operator
        log.log(logging.INFO if quiet else logging.ERROR, "%s: %s", exc.code, exc.message)
    body = error_body(exc.code, exc.message)
    return JSONResponse(body, status_code=status, headers=_headers(exc, status))


async def _on_jigsaw(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, JigsawError)
    return jigsaw_response(exc)


async def _on_redis_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, redis.exceptions.RedisError)
    mapped = storage_error(exc)
    if mapped is None:
        return await _on_unexpected(request, exc)
    return jigsaw_response(mapped)


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
    app.add_exception_handler(redis.exceptions.RedisError, _on_redis_error)
    app.add_exception_handler(RequestValidationError, _on_validation)
    app.add_exception_handler(StarletteHTTPException, _on_http)
    app.add_exception_handler(Exception, _on_unexpected)
