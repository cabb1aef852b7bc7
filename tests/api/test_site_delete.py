"""``DELETE /v1/sites/{site}`` over real HTTP on real Redis: 204, every key of the site gone,
other sites untouched, 404 afterwards; event subscribers get a last ``site`` event."""

from __future__ import annotations

import threading
from typing import Any

import pytest

from tests.service_fixtures import ApiServer, SiteEvents, ply_bytes, read_events, wait_until

pytestmark = pytest.mark.timeout(30)


def _site_keys(redis_client: Any, site: str) -> list[str]:
    return sorted(k for k in redis_client.scan_iter() if k.split(":")[1:3] == ["site", site])


def test_delete_site_removes_everything_it_stored(api: ApiServer, redis_client) -> None:
    with api.client() as http:
        for fid in ("a", "b"):
            put = http.put(f"/v1/sites/s1/fragments/{fid}", content=ply_bytes(300, seed=ord(fid)))
            assert put.status_code == 202
        assert http.put("/v1/sites/s1/hints", json={"order": ["a", "b"]}).status_code == 200
        assert http.put("/v1/sites/s2/fragments/a", content=ply_bytes(300)).status_code == 202
        redis_client.set("fpj:site:s1:result", '{"status": "open"}')  # as a placement would
        redis_client.hset("fpj:site:s1:senders", "a", '{"robot_id": "r1"}')
        assert len(_site_keys(redis_client, "s1")) >= 10
        s2_before = http.get("/v1/sites/s2").json()

        reply = http.delete("/v1/sites/s1")
        assert reply.status_code == 204 and reply.content == b""
        assert _site_keys(redis_client, "s1") == []
        assert redis_client.zscore("fpj:sites", "s1") is None
        for path in ("", "/result", "/hints", "/floorplan.svg", "/layout.gltf", "/fragments/a"):
            got = http.get(f"/v1/sites/s1{path}")
            assert got.status_code == 404 and got.json()["error"]["code"] == "site_not_found"
        assert http.delete("/v1/sites/s1").status_code == 404
        assert [s["site_id"] for s in http.get("/v1/sites").json()["sites"]] == ["s2"]
        assert http.get("/v1/sites/s2").json() == s2_before

        # The id is free again: a new upload starts a new, empty site.
        assert http.put("/v1/sites/s1/fragments/b", content=ply_bytes(300)).status_code == 202
        status = http.get("/v1/sites/s1").json()
        assert [f["fragment_id"] for f in status["fragments"]] == ["b"] and not status["hints"]


def test_delete_errors(api: ApiServer) -> None:
    with api.client() as http:
        unknown = http.delete("/v1/sites/nowhere")
        assert unknown.status_code == 404 and unknown.json()["error"]["code"] == "site_not_found"
        invalid = http.delete("/v1/sites/%2E%2E")
        assert invalid.status_code == 400 and invalid.json()["error"]["code"] == "invalid_id"


def test_event_stream_ends_with_the_deletion(api: ApiServer) -> None:
    events: SiteEvents = []
    ended = threading.Event()

    def listen() -> None:
        read_events(api.url, "s1", events, timeout=20)
        ended.set()  # the server closed the stream

    with api.client() as http:
        assert http.put("/v1/sites/s1/fragments/a", content=ply_bytes(300)).status_code == 202
        listener = threading.Thread(target=listen, daemon=True)
        listener.start()
        wait_until(lambda: events, 10)  # the status snapshot: subscribed
        assert http.delete("/v1/sites/s1").status_code == 204
        assert ended.wait(10), events
    kind, last = events[-1]
    assert kind == "site" and last["type"] == "site" and last["data"] == {"deleted": True}
