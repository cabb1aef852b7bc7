"""Reading a request body as a stream, with a size limit; its OpenAPI description."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from fastapi import Request

from services.errors import FragmentTooLargeError, JigsawError

__all__ = ["openapi_body", "read_limited"]


def openapi_body(description: str, media_type: str, schema: dict[str, Any]) -> dict[str, Any]:
    """``openapi_extra`` of a route that reads its body itself (with :func:`read_limited`)."""
    content = {media_type: {"schema": schema}}
    return {"requestBody": {"required": True, "description": description, "content": content}}


async def read_limited(
    request: Request,
    limit: int,
    too_large: Callable[[str], JigsawError] = FragmentTooLargeError,
) -> bytes:
    """The request body, or ``too_large`` (a 413 error) once it passes ``limit`` bytes.

    A declared Content-Length over the limit is refused before reading anything; a chunked
    body is counted as it streams in and never held beyond ``limit`` bytes.
    """
    declared = request.headers.get("content-length", "")
    if declared.isdigit() and int(declared) > limit:
        raise too_large(f"upload of {declared} bytes exceeds the {limit}-byte limit")
    body = bytearray()
    async for chunk in request.stream():
        body += chunk
        if len(body) > limit:
            raise too_large(f"upload exceeds the {limit}-byte limit")
    return bytes(body)
