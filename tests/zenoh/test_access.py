"""Who may do what over zenoh: scoped tokens on fragment and result queries (as over HTTP),
and zenoh's own authentication (mutual TLS, user names) with its access control
(FPJ_ZENOH_ACL), with certificates generated for the test.

The service is the app on uvicorn in this process (its lifespan opens the zenoh front end)
on its own Redis key prefix, so it shares the database with the package's service without
touching its keys; robots are zenoh sessions of the test process on loopback.
"""

from __future__ import annotations

import ipaddress
import json
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
import redis
import zenoh

from api.zenoh import ros2
from store.keys import Keys
from tests.service_fixtures import (
    ROOT,
    ApiServer,
    free_port,
    make_settings,
    ply_bytes,
    random_cloud,
    settings_env,
    wait_until,
)
from tests.zenoh.certs import Authority, CertFiles
from tests.zenoh.conftest import ZenohService
from transport.config import TlsOptions, ZenohOptions, build_config
from transport.keys import ZenohKeys

pytestmark = pytest.mark.timeout(60)

PREFIX = "fpjaccess"  # Redis keys of this module's service
TOKENS = "admin,robot:lab:upload,viewer:lab+hall:read"
KEYS = ZenohKeys("fpj")


def _reply(session: zenoh.Session, key: str, payload: bytes | None, tag: dict[str, str]) -> Any:
    """The JSON of each reply to a query (the error body for an error reply)."""
    attachment = json.dumps(tag).encode() if tag else None
    found = []
    for reply in session.get(key, payload=payload, attachment=attachment, timeout=10):
        sample = reply.ok if reply.ok is not None else reply.err
        assert sample is not None
        found.append(json.loads(sample.payload.to_bytes()))
    return found


def _code(body: dict[str, Any]) -> str:
    return str(body["error"]["code"]) if "error" in body else "ok"


@pytest.fixture
def service(redis7_url: str) -> Iterator[str]:
    """The API with tokens and a zenoh front end on a loopback port; yields its endpoint."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    settings = make_settings(redis7_url, tokens=TOKENS, key_prefix=PREFIX, zenoh_listen=endpoint)
    server = ApiServer(settings).start()
    try:
        yield endpoint
    finally:
        server.stop()
        client = redis.Redis.from_url(redis7_url)
        for key in client.scan_iter(f"{PREFIX}:*"):
            client.delete(key)
        client.close()


@pytest.fixture
def robot(service: str) -> Iterator[zenoh.Session]:
    with zenoh.open(build_config(ZenohOptions(connect=[service]))) as session:
        yield session


def test_tokens_scope_fragment_queries(robot: zenoh.Session) -> None:
    def upload(site: str, tag: dict[str, str], fragment: str = "f") -> str:
        (body,) = _reply(robot, KEYS.fragment(site, fragment), ply_bytes(300), tag)
        return _code(body)

    assert upload("lab", {}) == "unauthorized"
    assert upload("lab", {"token": "guess"}) == "forbidden"
    assert upload("lab", {"token": "viewer"}) == "insufficient_scope"
    assert upload("hall", {"token": "robot"}) == "insufficient_scope"
    assert upload("lab", {"token": "robot", "robot_id": "r1"}) == "ok"
    assert upload("hall", {"token": "admin"}) == "ok"


def test_tokens_scope_result_queries(robot: zenoh.Session, redis7_url: str) -> None:
    client = redis.Redis.from_url(redis7_url)
    for site in ("lab", "hall", "yard"):
        (body,) = _reply(robot, KEYS.fragment(site, "f"), ply_bytes(300), {"token": "admin"})
        assert _code(body) == "ok", body
        client.set(Keys(PREFIX).result(site), json.dumps({"site": site}))
    client.close()

    def read(site: str, tag: dict[str, str]) -> list[Any]:
        return list(_reply(robot, KEYS.result(site), None, tag))

    assert [_code(b) for b in read("lab", {})] == ["unauthorized"]
    assert [_code(b) for b in read("lab", {"token": "robot"})] == ["insufficient_scope"]
    assert [_code(b) for b in read("yard", {"token": "viewer"})] == ["insufficient_scope"]
    assert read("lab", {"token": "viewer"}) == [{"site": "lab"}]
    # A wildcard gets the token's sites only.
    assert sorted(b["site"] for b in read("*", {"token": "viewer"})) == ["hall", "lab"]
    assert len(read("*", {"token": "admin"})) == 3


# ---------------------------------------------------------------- TLS, authentication, ACL

RESULT = {
    "status": "closed",
    "confidence": 0.9,
    "fragments": [{"id": "f", "placed": True, "pose": np.eye(4).tolist(), "loop_index": 0}],
}


@dataclass
class Secured:
    """A service whose zenoh peers must authenticate, and robots' session options."""

    endpoint: str
    known: ZenohOptions  # in FPJ_ZENOH_ACL with upload and read on "lab"
    unnamed: dict[str, ZenohOptions]  # zenoh refuses their session
    unlisted: ZenohOptions  # authenticated, not in FPJ_ZENOH_ACL
    cli: list[str]  # the known robot's credentials as options of jigsaw send


def _mtls(tmp: Path, port: int) -> tuple[dict[str, Any], Secured]:
    ca, other = Authority(tmp), Authority(tmp, "other-ca")
    service = ca.issue("fpj-service", server=True)
    endpoint = f"tls/127.0.0.1:{port}"
    settings = {
        "zenoh_listen": endpoint,
        "zenoh_tls_certificate": service.certificate,
        "zenoh_tls_private_key": service.private_key,
        "zenoh_tls_root_ca": ca.certificate,
        "zenoh_tls_mtls": True,
    }

    def robot(files: CertFiles | None, root: Path = ca.certificate) -> ZenohOptions:
        cert, key = (files.certificate, files.private_key) if files else (None, None)
        tls = TlsOptions(root_ca=root, certificate=cert, private_key=key, mtls=True)
        return ZenohOptions(connect=[endpoint], tls=tls)

    unnamed = {
        "no client certificate": robot(None),
        # The known robot's name, signed by another CA: a stranger cannot pass for it.
        "another CA's certificate": robot(other.issue("robot1"), other.certificate),
    }
    known = ca.issue("robot1")
    cli = ["--tls-ca", str(ca.certificate), "--tls-cert", str(known.certificate)]
    cli += ["--tls-key", str(known.private_key)]
    return settings, Secured(endpoint, robot(known), unnamed, robot(ca.issue("r2")), cli)


def _usrpwd(tmp: Path, port: int) -> tuple[dict[str, Any], Secured]:
    users = tmp / "users"
    users.write_text("robot1:pw-1\nr2:pw-2\n")
    endpoint = f"tcp/127.0.0.1:{port}"

    def robot(user: str | None, password: str | None) -> ZenohOptions:
        return ZenohOptions(connect=[endpoint], user=user, password=password)

    unnamed = {"no credentials": robot(None, None), "a wrong password": robot("robot1", "pw-2")}
    settings = {"zenoh_listen": endpoint, "zenoh_users_file": users}
    cli = ["--user", "robot1", "--password", "pw-1"]
    return settings, Secured(endpoint, robot("robot1", "pw-1"), unnamed, robot("r2", "pw-2"), cli)


@pytest.fixture(params=["mtls", "usrpwd"])
def secured(
    request: pytest.FixtureRequest, redis7_url: str, tmp_path: Path
) -> Iterator[tuple[Secured, httpx.Client, redis.Redis]]:
    """The API (zenoh front end in this process) with FPJ_ZENOH_ACL: robot1 may upload to
    and read "lab"; everything else is denied."""
    build = _mtls if request.param == "mtls" else _usrpwd
    overrides, secured = build(tmp_path, free_port())
    acl = "robot1:lab:upload+read"
    settings = make_settings(redis7_url, key_prefix=PREFIX, zenoh_acl=acl, **overrides)
    server = ApiServer(settings).start()
    client = redis.Redis.from_url(redis7_url)
    try:
        with server.client() as http:
            yield secured, http, client
    finally:
        server.stop()
        for key in client.scan_iter(f"{PREFIX}:*"):
            client.delete(key)
        client.close()


def _attempt(options: ZenohOptions, client: redis.Redis) -> dict[str, Any]:
    """Everything a robot may try: connect, query and put fragments of "lab", query its
    result, subscribe to its result and poses while a result is published."""
    with zenoh.open(build_config(options)) as session:
        received: list[str] = []
        subscribers = [
            session.declare_subscriber(key, lambda s: received.append(str(s.key_expr)))
            for key in (KEYS.result("lab"), KEYS.site_poses("lab"))
        ]
        connected = bool(list(session.info.peers_zid()))
        replies = _replies(session, KEYS.fragment("lab", "f"), ply_bytes(300))
        session.put(KEYS.fragment("lab", "p"), ply_bytes(300, seed=1))
        results = _replies(session, KEYS.result("lab"), None)
        envelope = json.dumps({"version": 1, "site_id": "lab", "generation": 1, "result": RESULT})
        wait_until(lambda: client.publish(Keys(PREFIX).results_channel, envelope), 10)
        if connected and replies:
            wait_until(lambda: len(set(received)) == 2, 10)
        else:
            time.sleep(1.0)  # what would have come by now
        for subscriber in subscribers:
            subscriber.undeclare()
    return {"connected": connected, "upload": replies, "result": results, "got": set(received)}


def _replies(session: zenoh.Session, key: str, payload: bytes | None) -> list[Any]:
    found = []
    for reply in session.get(key, payload=payload, timeout=2):
        sample = reply.ok if reply.ok is not None else reply.err
        assert sample is not None
        found.append(json.loads(sample.payload.to_bytes()))
    return found


def test_unknown_peers_can_neither_send_nor_read(
    secured: tuple[Secured, httpx.Client, redis.Redis],
) -> None:
    robots, http, client = secured
    client.set(Keys(PREFIX).result("lab"), json.dumps(RESULT))
    nothing: dict[str, Any] = {"upload": [], "result": [], "got": set()}
    for why, options in robots.unnamed.items():
        assert _attempt(options, client) == {"connected": False, **nothing}, why
    # Authenticated, but FPJ_ZENOH_ACL gives it nothing: connected, every message dropped.
    assert _attempt(robots.unlisted, client) == {"connected": True, **nothing}
    assert http.get("/v1/sites/lab").status_code == 404  # no fragment was stored

    known = _attempt(robots.known, client)
    assert known["connected"] and known["result"] == [RESULT]
    assert [(r["fragment_id"], r["created"]) for r in known["upload"]] == [("f", True)]
    assert known["got"] == {KEYS.result("lab"), KEYS.pose("lab", "f")}

    def stored() -> set[str]:
        return {f["fragment_id"] for f in http.get("/v1/sites/lab").json()["fragments"]}

    wait_until(lambda: stored() == {"f", "p"}, 10, describe=lambda: str(stored()))
    # Its rights stop at its site: another site's fragments are dropped.
    with zenoh.open(build_config(robots.known)) as session:
        assert _replies(session, KEYS.fragment("hall", "f"), ply_bytes(300)) == []


def test_the_robot_command_authenticates(
    secured: tuple[Secured, httpx.Client, redis.Redis], tmp_path: Path
) -> None:
    robots, http, _ = secured
    scan = tmp_path / "g.ply"
    scan.write_bytes(ply_bytes(300, seed=2))
    command = [sys.executable, "-m", "cli.main", "send", str(scan), "--site", "lab"]
    command += ["--connect", robots.endpoint, "--mode", "client", "--timeout", "10", *robots.cli]
    env = settings_env(make_settings(None))
    sent = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=40)
    assert sent.returncode == 0, sent.stderr
    assert json.loads(sent.stdout)["fragment_id"] == "g"
    assert [f["fragment_id"] for f in http.get("/v1/sites/lab").json()["fragments"]] == ["g"]


def _own_address() -> str | None:
    """The address of this machine on its default route, if it has one beyond loopback."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("198.51.100.1", 9))  # no packet is sent: it only picks a route
        except OSError:
            return None
        address = str(probe.getsockname()[0])
    return None if ipaddress.ip_address(address).is_loopback else address


def test_http_listens_on_loopback_only_by_default(zenoh_service: ZenohService) -> None:
    """The package's service runs ``jigsaw serve --port N`` without --host."""
    address = _own_address()
    if address is None:
        pytest.skip("this machine has no address beyond loopback")
    assert httpx.get(f"{zenoh_service.url}/healthz", timeout=5).status_code == 200
    with pytest.raises(httpx.ConnectError):
        httpx.get(f"http://{address}:{zenoh_service.http_port}/healthz", timeout=5)


def test_ros_topics_follow_the_acl(redis7_url: str, tmp_path: Path) -> None:
    """rmw_zenoh traffic obeys FPJ_ZENOH_ACL too: a cloud topic takes clouds from peers with
    upload on its site only; the transforms (every site's) go to peers reading every site."""
    users = tmp_path / "users"
    users.write_text("robot1:pw-1\nviewer:pw-v\nr2:pw-2\n")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    settings = make_settings(
        redis7_url,
        key_prefix=PREFIX,
        zenoh_listen=endpoint,
        zenoh_users_file=users,
        zenoh_acl="robot1:lab:upload,viewer:*:read,r2:hall:upload+read",
        zenoh_ros_cloud_topics="/robot1/fragments=lab",
        zenoh_ros_tf_topic="/tf",
    )
    cloud_key = ros2.topic_key(
        0, "/robot1/fragments", ros2.CLOUD_TYPE, ros2.type_hash(ros2.CLOUD_TYPE)
    )
    tf_key = ros2.topic_key(0, "/tf", ros2.TF_TYPE)

    def peer(user: str, password: str) -> ZenohOptions:
        return ZenohOptions(connect=[endpoint], user=user, password=password)

    def publish_cloud(session: zenoh.Session, sec: int) -> None:
        with session.declare_publisher(cloud_key) as publisher:
            wait_until(lambda: publisher.matching_status.matching, 10)  # type: ignore[attr-defined]
            cdr = ros2.encode_pointcloud2(random_cloud(300, sec), sec, 0, "lidar")
            gid = ros2.entity_gid(f"publisher {sec}")
            publisher.put(cdr, attachment=ros2.encode_attachment(1, time.time_ns(), gid))

    server = ApiServer(settings).start()
    client = redis.Redis.from_url(redis7_url)
    try:
        with (
            server.client() as http,
            zenoh.open(build_config(peer("r2", "pw-2"))) as other,
            zenoh.open(build_config(peer("viewer", "pw-v"))) as viewer,
            zenoh.open(build_config(peer("robot1", "pw-1"))) as robot,
        ):
            got: dict[str, list[bytes]] = {"r2": [], "viewer": []}
            subscribers = [
                other.declare_subscriber(tf_key, lambda s: got["r2"].append(s.payload.to_bytes())),
                viewer.declare_subscriber(
                    tf_key, lambda s: got["viewer"].append(s.payload.to_bytes())
                ),
            ]
            publish_cloud(other, 1_700_000_001)  # r2 has no upload right on lab
            publish_cloud(robot, 1_700_000_002)

            def stored() -> list[str]:
                reply = http.get("/v1/sites/lab")
                fragments = reply.json()["fragments"] if reply.status_code == 200 else []
                return [f["fragment_id"] for f in fragments]

            wait_until(lambda: stored(), 15)
            time.sleep(0.5)  # r2's cloud, sent first, would be stored by now
            assert stored() == ["robot1_1700000002_000000000"]

            envelope = json.dumps(
                {"version": 1, "site_id": "lab", "generation": 1, "result": RESULT}
            )
            wait_until(lambda: client.publish(Keys(PREFIX).results_channel, envelope), 10)
            wait_until(lambda: got["viewer"], 10)
            time.sleep(0.5)
            assert got["r2"] == []
            for subscriber in subscribers:
                subscriber.undeclare()
    finally:
        server.stop()
        for key in client.scan_iter(f"{PREFIX}:*"):
            client.delete(key)
        client.close()
