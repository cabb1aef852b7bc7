"""The one zenoh config helper: session options from settings, and what a config sets."""

from __future__ import annotations

import json

import pytest

from schemas.settings import Settings
from transport.config import ZenohOptions, build_config, reachable_from_network, service_options

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


def test_security_settings_reach_the_config() -> None:
    settings = Settings(
        zenoh_listen="tls/127.0.0.1:7447",
        zenoh_tls_certificate="s.pem",
        zenoh_tls_private_key="s.key",
        zenoh_tls_root_ca="ca.pem",
        zenoh_tls_mtls=True,
        zenoh_users_file="users",
        zenoh_user="svc",
        zenoh_password="pw",
        zenoh_acl="robot1:lab:upload,viewer:*:read",
    )
    config = build_config(service_options(settings))
    tls = json.loads(config.get_json("transport/link/tls"))
    assert (tls["listen_certificate"], tls["listen_private_key"]) == ("s.pem", "s.key")
    assert (tls["root_ca_certificate"], tls["enable_mtls"]) == ("ca.pem", True)
    usrpwd = json.loads(config.get_json("transport/auth/usrpwd"))
    assert usrpwd == {"user": "svc", "password": "pw", "dictionary_file": "users"}
    acl = json.loads(config.get_json("access_control"))
    assert acl["enabled"] and acl["default_permission"] == "deny"
    # Known by certificate or by user name: one subject each, in the peer's one policy.
    subjects = {s["id"]: s for s in acl["subjects"]}
    assert subjects["robot1/cn"]["cert_common_names"] == ["robot1"]
    assert subjects["robot1/user"]["usernames"] == ["robot1"]
    rules = {r["id"]: r for r in acl["rules"]}
    assert rules["robot1/upload/in"]["key_exprs"] == ["fpj/sites/lab/fragments/*"]
    assert "robot1/read/in" not in rules
    assert rules["viewer/read/out"]["key_exprs"] == ["fpj/sites/*/poses/*", "fpj/sites/*/result"]
    assert "viewer/upload/in" not in rules
    default = build_config(service_options(Settings()))
    assert json.loads(default.get_json("access_control/enabled")) is False


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"zenoh_listen": "tls/127.0.0.1:7447"}, "_PRIVATE_KEY"),
        (
            {"zenoh_tls_mtls": True, "zenoh_tls_certificate": "c", "zenoh_tls_private_key": "k"},
            "CA",
        ),
        ({"zenoh_user": "svc"}, "go together"),
        ({"zenoh_acl": "robot1"}, "every peer is unknown"),
        ({"zenoh_acl": "robot1:lab:write", "zenoh_users_file": "u"}, "rights"),
    ],
)
def test_insecure_or_incomplete_security_settings_are_refused(
    fields: dict[str, object], message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        Settings(**fields)  # type: ignore[arg-type]


def test_ros_topics_follow_the_rights() -> None:
    settings = Settings(
        zenoh_users_file="users",
        zenoh_acl="robot1:lab:upload,viewer:*:read,r2:hall:read+upload",
        zenoh_ros_cloud_topics="/robot1/fragments=lab",
        zenoh_ros_depth_topics="/cam/depth:/cam/info=hall",
        zenoh_ros_tf_topic="/tf",
        zenoh_ros_domain_id=3,
    )
    acl = service_options(settings).access_control
    assert acl is not None
    rules = {r["id"]: r["key_exprs"] for r in acl["rules"]}
    assert rules["robot1/upload/ros"] == ["3/robot1/fragments/*/*"]
    assert rules["r2/upload/ros"] == ["3/cam/depth/*/*", "3/cam/info/*/*"]
    assert rules["viewer/read/ros/out"] == ["3/tf/*/*"]
    assert "r2/read/ros/out" not in rules  # the transforms carry every site's fragments
    assert rules["known/ros/graph/in"] == ["@ros2_lv/3/**"]


def test_endpoints_reachable_from_the_network() -> None:
    assert not reachable_from_network("tcp/localhost:7447")
    assert not reachable_from_network("unixsock-stream//tmp/zenoh.sock")
    assert reachable_from_network("tcp/192.168.1.5:7447")
    assert reachable_from_network("tcp/robots.example:7447")
    assert not Settings().zenoh_secured
