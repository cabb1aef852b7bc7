"""Zenoh settings and robot tags (no session)."""

from __future__ import annotations

from typing import Any

import pytest
from pydantic import ValidationError

from api.errors import ForbiddenError, UnauthorizedError
from api.zenoh.ingest import InvalidRequestError, check_token, parse_tag
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
    check_token([], parse_tag(None))  # no tokens configured: anyone
    with pytest.raises(UnauthorizedError):
        check_token(["secret"], parse_tag(None))
    with pytest.raises(ForbiddenError):
        check_token(["secret"], parse_tag(b'{"token": "guess"}'))
    check_token(["other", "secret"], parse_tag(None, {"token": "secret"}))
