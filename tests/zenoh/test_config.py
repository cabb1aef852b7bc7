"""Zenoh settings, the one config helper, key expressions and robot tags (no session)."""

from __future__ import annotations

import json
from typing import Any

import pytest
from pydantic import ValidationError

from api.errors import ForbiddenError, UnauthorizedError
from api.zenoh.config import ZenohOptions, build_config, service_options
from api.zenoh.ingest import InvalidRequestError, check_token, parse_tag
from api.zenoh.keys import ZenohKeys
from schemas.settings import Settings

pytestmark = pytest.mark.timeout(10)


def test_settings_derive_the_session_options() -> None:
    settings = Settings(
        zenoh_listen="tcp/0.0.0.0:7447, udp/0.0.0.0:7447",
        zenoh_connect="tcp/10.0.0.1:7447",
        max_upload_bytes=1_000_000,
        zenoh_ros_cloud_topics="/robot1/fragments=lab, robot2/cloud=lab2",
    )
    options = service_options(settings)
    assert options.listen == ["tcp/0.0.0.0:7447", "udp/0.0.0.0:7447"]
    assert options.connect == ["tcp/10.0.0.1:7447"]
    assert options.mode == "peer" and options.multicast_scouting is False
    assert options.max_message_bytes == 2 * 1_000_000 + 1024 * 1024
    assert settings.ros_cloud_topics() == {"/robot1/fragments": "lab", "/robot2/cloud": "lab2"}
    assert not Settings(zenoh_listen="none").zenoh_enabled
    assert Settings(zenoh_listen="NONE").zenoh_listen_endpoints == []


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


def test_build_config_sets_what_the_options_say() -> None:
    config = build_config(
        ZenohOptions(
            mode="router",
            listen=["tcp/127.0.0.1:7500"],
            connect=["tcp/127.0.0.1:7501"],
            max_message_bytes=5_000_000,
        )
    )
    assert json.loads(config.get_json("mode")) == "router"
    assert json.loads(config.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7500"]
    assert json.loads(config.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7501"]
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    assert json.loads(config.get_json("transport/link/rx/max_message_size")) == 5_000_000
    client = build_config(
        ZenohOptions(mode="client", listen=["tcp/0.0.0.0:1"], connect=["tcp/127.0.0.1:1"])
    )
    assert json.loads(client.get_json("listen/endpoints")) == []


def test_keys_parse_only_their_own_shapes() -> None:
    keys = ZenohKeys("fleet/a")
    assert keys.parse_fragment(keys.fragment("s", "f")) == ("s", "f")
    assert keys.parse_fragment("fpj/sites/s/fragments/f") is None
    assert keys.parse_fragment(keys.result("s")) is None
    assert keys.parse_result(keys.all_results) == "*"
    assert keys.parse_robot(keys.robot("r-1")) == "r-1"
    assert keys.parse_robot("fleet/a/robots/bad$id") is None


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
