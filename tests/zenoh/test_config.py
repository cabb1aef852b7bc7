"""Zenoh settings and robot tags (no session)."""

from __future__ import annotations

from typing import Any

import pytest
from pydantic import ValidationError

from api.auth import authorize
from api.errors import ForbiddenError, InsufficientScopeError, UnauthorizedError
from api.zenoh.ingest import InvalidRequestError, parse_tag
from schemas.settings import Settings

pytestmark = pytest.mark.timeout(10)


@pytest.mark.parametrize(
    "fields",
    [
        {"zenoh_mode": "client"},  # a client needs something to connect to
        {"zenoh_connect": "10.0.0.1:7447"},  # no protocol
        {"zenoh_max_message_bytes": 100_000, "max_upload_bytes": 200_000},
        {"zenoh_mode": "broker"},
        {"zenoh_prefix": "fpj/*"},
        {"zenoh_ros_cloud_topics": "/robot1/fragments"},  # no site
        {"zenoh_ros_cloud_topics": "/robot 1/fragments=lab"},
        {"zenoh_ros_pose_topic": "poses!"},
    ],
)
def test_bad_zenoh_settings_are_refused(fields: dict[str, Any]) -> None:
    with pytest.raises(ValidationError):
        Settings(**fields)


def test_robot_tags_and_tokens() -> None:
    assert parse_tag(b'{"robot_id": "r1", "token": "t"}').token == "t"
    assert parse_tag(b'{"robot_id": "r1"}', {"robot_id": "r2"}).robot_id == "r1"
    for bad in (b"\xff", b"[]", b'{"robot_id": ""}'):
        with pytest.raises(InvalidRequestError):
            parse_tag(bad)

    def allow(tokens: object, tag: bytes | None, site: str = "lab") -> None:
        authorize(Settings(tokens=tokens).tokens, parse_tag(tag).token, "upload", site)

    allow("", None)  # no tokens configured: anyone
    with pytest.raises(UnauthorizedError):
        allow("secret", None)
    with pytest.raises(ForbiddenError):
        allow("secret", b'{"token": "guess"}')
    allow("other,secret", b'{"token": "secret"}')
    allow("r1:lab:upload", b'{"token": "r1"}')
    with pytest.raises(InsufficientScopeError):
        allow("r1:lab:upload", b'{"token": "r1"}', site="hall")
    with pytest.raises(InsufficientScopeError):
        allow("r1:lab:read", b'{"token": "r1"}')
