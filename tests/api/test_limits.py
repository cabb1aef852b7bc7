"""Limits over real HTTP on a real Redis: upload rate, fragments per site, stored bytes
(Redis maxmemory), an evicting Redis refused, request time."""

from __future__ import annotations

import asyncio
import json
import signal
import socket
import time
import zlib
from pathlib import Path
from typing import Any

import httpx
import pytest
import redis

from store.backend import Backend, EvictingStorageError
from tests.service_fixtures import (
    ApiServer,
    RedisProcess,
    Workers,
    make_settings,
    ply_bytes,
    wait_until,
)

pytestmark = pytest.mark.timeout(60)


def _error(reply: httpx.Response, status: int, code: str) -> dict[str, Any]:
    assert reply.status_code == status, reply.text
    body: dict[str, Any] = reply.json()
    assert body["error"]["code"] == code, body
    return body


def test_uploads_past_the_rate_get_429_with_retry_after(redis_url: str, api_factory) -> None:
    server: ApiServer = api_factory(
        make_settings(redis_url, upload_rate_limit=3, upload_rate_window_s=30)
    )
    with server.client() as http:
        codes = [
            http.put(f"/v1/sites/s/fragments/f{k}", content=ply_bytes(200, seed=k)).status_code
            for k in range(3)
        ]
        assert codes == [202] * 3
        # A bearer token the service does not check (no FPJ_TOKENS) buys no new budget.
        refused = http.put(
            "/v1/sites/s/fragments/f3",
            content=ply_bytes(200, seed=3),
            headers={"Authorization": "Bearer made-up"},
        )
        _error(refused, 429, "rate_limited")
        assert 1 <= int(refused.headers["retry-after"]) <= 30
        assert http.get("/v1/sites/s/fragments/f3").status_code == 404  # nothing stored
        assert http.get("/v1/sites/s").status_code == 200  # reads are not counted


def test_the_rate_is_counted_per_token(redis_url: str, api_factory) -> None:
    server: ApiServer = api_factory(
        make_settings(redis_url, tokens=["a", "b"], upload_rate_limit=2, upload_rate_window_s=30)
    )

    def put(token: str, fid: str) -> httpx.Response:
        headers = {"Authorization": f"Bearer {token}"}
        return http.put(f"/v1/sites/s/fragments/{fid}", content=ply_bytes(200), headers=headers)

    with server.client() as http:
        assert [put("a", "f0").status_code, put("a", "f0").status_code] == [202, 200]
        _error(put("a", "f0"), 429, "rate_limited")
        assert put("b", "f0").status_code == 200


def test_a_site_holds_at_most_max_fragments(redis_url: str, api_factory) -> None:
    server: ApiServer = api_factory(make_settings(redis_url, max_fragments_per_site=2))
    with server.client() as http:
        for k in range(2):
            assert http.put(f"/v1/sites/s/fragments/f{k}", content=ply_bytes(200, seed=k)) \
                .status_code == 202  # fmt: skip
        third = http.put("/v1/sites/s/fragments/f2", content=ply_bytes(200, seed=2))
        _error(third, 409, "too_many_fragments")
        assert http.put("/v1/sites/s/fragments/f0", content=ply_bytes(200, seed=0)).status_code \
            == 200  # fmt: skip
        assert http.put("/v1/sites/t/fragments/f2", content=ply_bytes(200)).status_code == 202
        assert http.delete("/v1/sites/s/fragments/f1").status_code == 204
        assert http.put("/v1/sites/s/fragments/f2", content=ply_bytes(200, seed=2)).status_code \
            == 202  # fmt: skip
        assert len(http.get("/v1/sites/s").json()["fragments"]) == 2


def test_concurrent_uploads_cannot_pass_the_site_limit_together(
    redis_url: str, api_factory
) -> None:
    import concurrent.futures

    server: ApiServer = api_factory(make_settings(redis_url, max_fragments_per_site=3))

    def put(k: int) -> int:
        with server.client() as http:
            data = ply_bytes(200, seed=k)
            return http.put(f"/v1/sites/s/fragments/f{k}", content=data).status_code

    with concurrent.futures.ThreadPoolExecutor(8) as pool:
        codes = sorted(pool.map(put, range(8)))
    assert codes == [202] * 3 + [409] * 5


def test_full_storage_is_507_and_keeps_what_is_stored(tmp_path: Path, api_factory) -> None:
    """Redis maxmemory (noeviction) reached: uploads get 507 storage_full, every fragment
    stored before is still there byte for byte, reads and deletes work, and room made by a
    delete is usable again."""
    server_process = RedisProcess(
        tmp_path, "redis-server", "--maxmemory", "4mb", "--maxmemory-policy", "noeviction"
    ).start()
    try:
        server: ApiServer = api_factory(make_settings(server_process.url))
        raw = redis.Redis.from_url(server_process.url)
        sent: dict[str, bytes] = {}
        with server.client() as http:
            for k in range(60):
                data = ply_bytes(20_000, seed=k)
                reply = http.put(f"/v1/sites/s{k % 2}/fragments/f{k}", content=data)
                if reply.status_code != 202:
                    break
                sent[f"s{k % 2}/f{k}"] = data
            _error(reply, 507, "storage_full")
            assert "maxmemory" in reply.json()["error"]["message"]
            assert len(sent) >= 3
            for name, data in sent.items():
                site, fid = name.split("/")
                assert http.get(f"/v1/sites/{site}/fragments/{fid}").status_code == 200
                stored: Any = raw.get(f"fpj:site:{site}:frag:{fid}:data")
                assert zlib.decompress(stored) == data
            gone = http.delete("/v1/sites/s1")
            assert gone.status_code == 204, gone.text
            again = http.put(f"/v1/sites/s0/fragments/f{k}", content=ply_bytes(20_000, seed=k))
            assert again.status_code == 202, again.text
        raw.close()
    finally:
        server_process.stop()


def test_workers_wait_for_room_instead_of_failing_jobs(
    redis_process: RedisProcess, api_factory, start_workers: Workers
) -> None:
    """Storage full (this test's own Redis: maxmemory lowered under what it holds) while
    layout jobs are queued: the worker leaves them pending (no try burnt, nothing
    dead-lettered, no fragment failed) and runs them once there is room."""
    settings = make_settings(redis_process.url, max_tries=2, visibility_timeout_s=1.0)
    server: ApiServer = api_factory(settings)
    client = redis.Redis.from_url(redis_process.url, decode_responses=True)
    with server.client() as http:
        for k in range(3):
            data = ply_bytes(2000, seed=k)
            assert http.put(f"/v1/sites/s/fragments/f{k}", content=data).status_code == 202
        client.config_set("maxmemory-policy", "noeviction")
        client.config_set("maxmemory", "1")  # less than it holds: every write refused
        start_workers.start(settings, count=1)
        time.sleep(3)  # > 2 x visibility timeout: each job would have been tried twice
        assert client.xlen("fpj:jobs:dead") == 0
        states = [f["state"] for f in http.get("/v1/sites/s").json()["fragments"]]
        assert states == ["queued"] * 3, states
        client.config_set("maxmemory", "0")

        def all_done(site: str) -> bool:
            fragments = http.get(f"/v1/sites/{site}").json()["fragments"]
            return all(f["state"] == "done" for f in fragments)

        wait_until(lambda: all_done("s"), 40, 0.5)
        # Full again while the worker runs jobs: they wait too, and its heartbeat goes on.
        for k in range(3):
            data = ply_bytes(2000, seed=10 + k)
            assert http.put(f"/v1/sites/t/fragments/f{k}", content=data).status_code == 202
        client.config_set("maxmemory", "1")
        time.sleep(3)
        client.config_set("maxmemory", "0")
        wait_until(lambda: all_done("t"), 40, 0.5)
        assert client.xlen("fpj:jobs:dead") == 0
        wait_until(
            lambda: (
                time.time() - float(client.zrange("fpj:workers", -1, -1, withscores=True)[0][1]) < 2
            ),
            10,
        )
    client.close()


def test_a_redis_that_evicts_is_refused(tmp_path: Path) -> None:
    server_process = RedisProcess(
        tmp_path, "redis-server", "--maxmemory", "64mb", "--maxmemory-policy", "allkeys-lru"
    ).start()
    try:
        with pytest.raises(EvictingStorageError, match="allkeys-lru"):
            asyncio.run(Backend.connect(make_settings(server_process.url)))
    finally:
        server_process.stop()


def test_a_stalled_upload_gets_408_and_a_started_stream_runs_on(
    redis_url: str, api_factory
) -> None:
    server: ApiServer = api_factory(make_settings(redis_url, request_timeout_s=1.0))
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as connection:
        head = "PUT /v1/sites/s/fragments/f HTTP/1.1\r\nHost: x\r\nContent-Length: 100000\r\n\r\n"
        connection.sendall(head.encode() + b"ply\n")  # ... and then nothing more
        started = time.monotonic()
        answer = b""
        while b"}}" not in answer:
            chunk = connection.recv(4096)
            if not chunk:
                break
            answer += chunk
        assert 0.9 < time.monotonic() - started < 5
    status, _, rest = answer.partition(b"\r\n")
    assert status.startswith(b"HTTP/1.1 408"), answer
    assert json.loads(rest.partition(b"\r\n\r\n")[2])["error"]["code"] == "request_timeout"
    with server.client() as http:
        assert http.put("/v1/sites/s/fragments/f", content=ply_bytes(200)).status_code == 202
        # The event stream answers at once and then runs on past the request timeout.
        lines = 0
        with http.stream("GET", "/v1/sites/s/events") as stream:
            for _ in stream.iter_lines():
                lines += 1
                if time.monotonic() - started > 4:
                    break
        assert lines >= 2


def test_a_request_with_no_answer_in_time_gets_503(
    redis_process: RedisProcess, api_factory
) -> None:
    """The body has arrived, but Redis hangs (SIGSTOP): past the request timeout the client
    gets 503 processing_timeout, not a hung connection; answers resume with Redis."""
    settings = make_settings(redis_process.url, request_timeout_s=1.0, redis_timeout_s=10.0)
    server: ApiServer = api_factory(settings)
    assert redis_process.process is not None
    with server.client() as http:
        redis_process.process.send_signal(signal.SIGSTOP)
        try:
            started = time.monotonic()
            reply = http.put("/v1/sites/s/fragments/f", content=ply_bytes(200))
            assert time.monotonic() - started < 5
        finally:
            redis_process.process.send_signal(signal.SIGCONT)
        _error(reply, 503, "processing_timeout")
        assert reply.headers["retry-after"] == "1"
        assert http.put("/v1/sites/s/fragments/f", content=ply_bytes(200)).status_code in (200, 202)
