"""The one zenoh config helper: session options from settings, and what a config sets."""

from __future__ import annotations

import json

import pytest

from schemas.settings import Settings
from transport.config import ZenohOptions, build_config, service_options

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
