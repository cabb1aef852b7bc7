"""Reading an upload body as a stream, with a size limit."""

from __future__ import annotations

from fastapi import Request

from services.errors import FragmentTooLargeError

__all__ = ["read_limited"]


async def read_limited(request: Request, limit: int) -> bytes:
    """The request body, or FragmentTooLargeError (413) once it passes ``limit`` bytes.

    A declared Content-Length over the limit is refused before reading anything; a chunked
    body is counted as it streams in and never held beyond ``limit`` bytes.
    """
    declared = request.headers.get("content-length", "")
    if declared.isdigit() and int(declared) > limit:
        raise FragmentTooLargeError(f"upload of {declared} bytes exceeds the {limit}-byte limit")
    body = bytearray()
    async for chunk in request.stream():
        body += chunk
        if len(body) > limit:
            raise FragmentTooLargeError(f"upload exceeds the {limit}-byte limit")
    return bytes(body)
