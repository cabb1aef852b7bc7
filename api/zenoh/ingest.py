"""Zenoh ingest: the one ingest path (:func:`api.ingest.ingest_fragment`) plus the sender.

A query or put may name its robot and carry a bearer token, either in its attachment (UTF-8
JSON ``{"robot_id": "r1", "token": "..."}``, see :class:`schemas.zenoh.RobotTag`) or, for a
query, as selector parameters ``?robot_id=r1`` (the attachment wins). With ``FPJ_TOKENS`` set,
a missing token is ``unauthorized`` and an unknown one ``forbidden``, as over HTTP.
"""

from __future__ import annotations

import hmac
import json

from pydantic import ValidationError

from api.backend import Backend
from api.errors import ForbiddenError, UnauthorizedError
from api.ingest import ingest_fragment
from api.zenoh.presence import record_sender
from schemas.service import UploadReply
from schemas.zenoh import RobotTag, SenderRecord
from services.errors import JigsawError

__all__ = ["InvalidRequestError", "check_token", "ingest_with_sender", "parse_tag"]


class InvalidRequestError(JigsawError):
    """A malformed attachment or parameter (HTTP would answer 422 invalid_request)."""

    code = "invalid_request"


def parse_tag(attachment: bytes | None, parameters: dict[str, str] | None = None) -> RobotTag:
    """The robot id and token of a query or put.

    >>> parse_tag(b'{"robot_id": "r1"}').robot_id
    'r1'
    >>> parse_tag(None, {"robot_id": "r2"}).robot_id
    'r2'
    """
    fields: dict[str, object] = {
        k: v for k, v in (parameters or {}).items() if k in ("robot_id", "token")
    }
    try:
        extra = json.loads(attachment) if attachment else {}
        if not isinstance(extra, dict):
            raise ValueError("the attachment is not a JSON object")
        return RobotTag.model_validate({**fields, **extra})
    except ValidationError as exc:
        details = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
        raise InvalidRequestError(f"bad robot tag: {details}") from exc
    except ValueError as exc:  # not UTF-8, not JSON
        raise InvalidRequestError(f"bad attachment: {exc}") from exc


def check_token(tokens: list[str], tag: RobotTag) -> None:
    """With tokens configured, require one of them (constant-time comparison)."""
    if not tokens:
        return
    if not tag.token:
        raise UnauthorizedError('a token is required (attachment {"token": "..."})')
    given = tag.token.encode()
    if not any(hmac.compare_digest(given, token.encode()) for token in tokens):
        raise ForbiddenError("unknown token")


async def ingest_with_sender(
    backend: Backend,
    site_id: str,
    fragment_id: str,
    data: bytes,
    sender: SenderRecord | None,
) -> UploadReply:
    """Ingest exactly as over HTTP, then remember the sender of a newly stored fragment."""
    reply = await ingest_fragment(backend, site_id, fragment_id, data)
    if sender is not None and reply.created:
        await record_sender(backend, site_id, fragment_id, sender)
    return reply
