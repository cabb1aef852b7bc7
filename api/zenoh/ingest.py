"""Zenoh ingest: the one ingest path (:func:`api.ingest.ingest_fragment`) plus the sender
and the fragment's prior.

A query or put may carry an attachment, UTF-8 JSON of one object:

- ``robot_id`` and ``token`` (:class:`schemas.zenoh.RobotTag`): who sends it, and a bearer
  token; a query may give these as selector parameters ``?robot_id=r1`` instead (the
  attachment wins). With ``FPJ_TOKENS`` set, a missing token is ``unauthorized``, an
  unknown one ``forbidden`` and one without the ``upload`` right on the key's site
  ``insufficient_scope``, as over HTTP (:func:`api.auth.authorize`);
- ``prior``: ``{"pose", "sigma_xy", "sigma_yaw_deg"}``, the fragment's entry of the site's
  hints (contract section 5). An invalid prior is refused (``invalid_prior``) before anything
  is stored; a valid one is merged into the hints once the fragment is accepted, and the site
  is placed again.
"""

from __future__ import annotations

import json
from typing import Any

from pydantic import ValidationError

from api.hints import merge_prior, parse_prior
from api.ingest import ingest_fragment
from schemas.hints import FragmentPrior
from schemas.service import UploadReply
from schemas.validation import summarize_errors
from schemas.zenoh import RobotTag, SenderRecord
from services.errors import JigsawError
from store.backend import Backend
from store.presence import record_sender

__all__ = [
    "InvalidRequestError",
    "attachment_prior",
    "ingest_with_sender",
    "parse_tag",
]


class InvalidRequestError(JigsawError):
    """A malformed attachment or parameter (HTTP would answer 422 invalid_request)."""

    code = "invalid_request"


def _attachment_object(attachment: bytes | None) -> dict[str, Any]:
    try:
        value = json.loads(attachment) if attachment else {}
    except ValueError as exc:  # not UTF-8, not JSON
        raise InvalidRequestError(f"bad attachment: {exc}") from exc
    if not isinstance(value, dict):
        raise InvalidRequestError("bad attachment: not a JSON object")
    return value


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
        return RobotTag.model_validate({**fields, **_attachment_object(attachment)})
    except ValidationError as exc:
        raise InvalidRequestError(f"bad robot tag: {summarize_errors(exc.errors())}") from exc


def attachment_prior(attachment: bytes | None) -> FragmentPrior | None:
    """The ``prior`` of a query's or put's attachment, if it has one.

    Raises
    ------
    InvalidPriorError
        The prior is not a valid hints entry (``invalid_prior``).

    >>> attachment_prior(b'{"robot_id": "r1"}') is None
    True
    """
    value = _attachment_object(attachment).get("prior")
    return None if value is None else parse_prior(value)


async def ingest_with_sender(
    backend: Backend,
    site_id: str,
    fragment_id: str,
    data: bytes,
    sender: SenderRecord | None,
    prior: FragmentPrior | None = None,
) -> UploadReply:
    """Ingest exactly as over HTTP, then remember the sender of a newly stored fragment and
    make ``prior`` the fragment's entry of the site's hints (also when the same bytes were
    already stored: a robot may send a better prior)."""
    reply = await ingest_fragment(backend, site_id, fragment_id, data)
    if sender is not None and reply.created:
        await record_sender(backend, site_id, fragment_id, sender)
    if prior is not None:
        await merge_prior(backend, site_id, fragment_id, prior)
    return reply
