"""Ingest over zenoh (contract 5): queries get the HTTP PUT's JSON or its error body, puts
are ingested silently, bad fragments change nothing; the result and service queryables."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import redis
import zenoh

from schemas.service import UploadReply
from schemas.zenoh import ServiceInfo
from tests.service_fixtures import ply_bytes, wait_until
from tests.zenoh.conftest import MAX_UPLOAD, Proc, ZenohService, robot_session

pytestmark = pytest.mark.timeout(60)


def _query(
    session: zenoh.Session, key: str, payload: bytes | None = None, attachment: bytes | None = None
) -> tuple[bool, dict[str, Any]]:
    """(ok, JSON) of the single reply to a query."""
    replies = list(session.get(key, payload=payload, attachment=attachment, timeout=20))
    assert len(replies) == 1, replies
    reply = replies[0]
    if reply.ok is not None:
        return True, json.loads(reply.ok.payload.to_bytes())
    assert reply.err is not None
    return False, json.loads(reply.err.payload.to_bytes())


def _error_code(session: zenoh.Session, key: str, payload: bytes | None) -> str:
    ok, body = _query(session, key, payload)
    assert not ok, body
    assert set(body) == {"error"} and set(body["error"]) == {"code", "message"}, body
    return str(body["error"]["code"])


def test_query_ingest_acknowledges_like_http_put(zenoh_service: ZenohService) -> None:
    keys, data = zenoh_service.keys, ply_bytes(500, seed=1)
    with robot_session(zenoh_service) as session, zenoh_service.http() as http:
        ok, body = _query(session, keys.fragment("zq", "f1"), data)
        assert ok, body
        reply = UploadReply.model_validate(body)
        assert (reply.fragment_id, reply.site_id, reply.created) == ("f1", "zq", True)
        assert (reply.format, reply.n_points, reply.size_bytes) == ("ply", 500, len(data))
        # The same bytes again: HTTP answers 200 with created false, so does zenoh.
        ok, again = _query(session, keys.fragment("zq", "f1"), data)
        assert ok and again["created"] is False and again["sha256"] == body["sha256"]
        # The HTTP front end sees the same fragment, and agrees on the duplicate.
        put = http.put("/v1/sites/zq/fragments/f1", content=data)
        assert put.status_code == 200 and put.json()["sha256"] == body["sha256"]
        status = http.get("/v1/sites/zq").json()
        assert [f["fragment_id"] for f in status["fragments"]] == ["f1"]


def test_bad_fragments_get_the_error_reply_and_change_nothing(
    zenoh_service: ZenohService,
) -> None:
    keys = zenoh_service.keys
    with robot_session(zenoh_service) as session, zenoh_service.http() as http:
        key = keys.fragment("zbad", "f")
        assert _error_code(session, key, b"garbage, not a point cloud") == "unsupported_format"
        assert _error_code(session, key, ply_bytes(20)) == "invalid_fragment"  # too few points
        assert _error_code(session, key, None) == "invalid_fragment"  # empty
        too_big = ply_bytes(500) + bytes(MAX_UPLOAD)
        assert _error_code(session, key, too_big) == "fragment_too_large"
        assert _error_code(session, keys.fragment("zbad", "x" * 65), ply_bytes()) == "invalid_id"
        assert http.get("/v1/sites/zbad").status_code == 404  # nothing was stored
        # A conflict leaves the stored fragment as it was.
        assert _query(session, key, ply_bytes(300, seed=2))[0]
        before = http.get("/v1/sites/zbad").json()["fragments"]
        assert _error_code(session, key, ply_bytes(300, seed=3)) == "conflict"
        after = http.get("/v1/sites/zbad").json()["fragments"]
        assert [(f["fragment_id"], f["sha256"]) for f in after] == [
            (f["fragment_id"], f["sha256"]) for f in before
        ]


def test_put_ingests_without_reply_and_records_the_robot(zenoh_service: ZenohService) -> None:
    keys = zenoh_service.keys
    with robot_session(zenoh_service) as session, zenoh_service.http() as http:
        with session.liveliness().declare_token(keys.robot("putter")):
            tag = json.dumps({"robot_id": "putter"}).encode()
            session.put(keys.fragment("zput", "p1"), ply_bytes(400, seed=4), attachment=tag)
            session.put(keys.fragment("zput", "p2"), b"not a fragment")  # logged, dropped

            def listed() -> list[dict[str, Any]] | None:
                reply = http.get("/v1/sites/zput")
                robots = reply.json()["robots"] if reply.status_code == 200 else []
                found = [r for r in robots if r["robot_id"] == "putter" and r["fragments"]]
                return found or None

            robot = wait_until(listed, 15)[0]
            assert robot["fragments"] == ["p1"]
        ids = [f["fragment_id"] for f in http.get("/v1/sites/zput").json()["fragments"]]
        assert ids == ["p1"]


def test_result_and_service_queryables(zenoh_service: ZenohService) -> None:
    keys = zenoh_service.keys
    with robot_session(zenoh_service) as session:
        ok, info = _query(session, keys.service)
        assert ok
        assert ServiceInfo.model_validate(info).max_upload_bytes == MAX_UPLOAD
        assert info["max_message_bytes"] > MAX_UPLOAD
        assert _error_code(session, keys.result("nowhere"), None) == "site_not_found"
        assert _error_code(session, keys.result("x" * 65), None) == "invalid_id"


def test_send_refuses_what_the_service_would_refuse(
    zenoh_service: ZenohService, procs: Callable[[list[str]], Proc], tmp_path: Path
) -> None:
    """`jigsaw send` learns the limit from `fpj/service` and does not send larger files."""
    big, good = tmp_path / "big.ply", tmp_path / "good.ply"
    big.write_bytes(ply_bytes(500) + bytes(MAX_UPLOAD))
    good.write_bytes(ply_bytes(500, seed=9))
    sent = procs(zenoh_service.robot_command("send", "--site", "zcli", str(big), str(good)))
    assert sent.finish() == 1, sent.describe()
    refused, accepted = (json.loads(line) for line in sent.out)
    assert refused["error"]["code"] == "fragment_too_large"
    assert "the service's" in refused["error"]["message"]  # refused before sending
    assert accepted["fragment_id"] == "good" and accepted["created"] is True
    with zenoh_service.http() as http:
        ids = [f["fragment_id"] for f in http.get("/v1/sites/zcli").json()["fragments"]]
    assert ids == ["good"]


def test_a_robot_past_the_upload_rate_gets_rate_limited(zenoh_service: ZenohService) -> None:
    """The counter of robot 'flood' (no tokens: counted per robot id) set at the limit in
    Redis: its next query is refused with rate_limited and stores nothing; another robot
    still uploads."""
    settings = zenoh_service.settings
    window = settings.upload_rate_window_s
    client = redis.Redis.from_url(str(settings.redis_url))
    now = int(time.time() // window)
    for index in (now, now + 1):  # the query may land in the next window
        client.set(f"fpj:rate:robot:flood:{index}", settings.upload_rate_limit, ex=300)
    keys = zenoh_service.keys
    flood = json.dumps({"robot_id": "flood"}).encode()
    calm = json.dumps({"robot_id": "calm"}).encode()
    with robot_session(zenoh_service) as session, zenoh_service.http() as http:
        ok, body = _query(session, keys.fragment("zrate", "f1"), ply_bytes(300), flood)
        assert not ok and body["error"]["code"] == "rate_limited", body
        assert "retry in" in body["error"]["message"]
        assert http.get("/v1/sites/zrate").status_code == 404
        assert _query(session, keys.fragment("zrate", "f1"), ply_bytes(300), calm)[0]
    client.close()
