"""Who may do what over zenoh: scoped tokens on fragment and result queries (as over HTTP).

The service is the app on uvicorn in this process (its lifespan opens the zenoh front end)
on its own Redis key prefix, so it shares the database with the package's service without
touching its keys; robots are zenoh sessions of the test process on loopback.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest
import redis
import zenoh

from store.keys import Keys
from tests.service_fixtures import ApiServer, free_port, make_settings, ply_bytes
from transport.config import ZenohOptions, build_config
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
