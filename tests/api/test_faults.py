"""Faults of the whole service: restarts of `jigsaw serve` (embedded Redis), Redis outages."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import zlib
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
import redis

from services.point_io import encode_ply
from services.synthetic import SceneSpec, SyntheticScene, generate_scene
from tests.service_fixtures import (
    ROOT,
    ApiServer,
    RedisProcess,
    Workers,
    free_port,
    make_settings,
    settings_env,
    wait_result,
    wait_until,
    wait_workers_alive,
)

pytestmark = pytest.mark.timeout(180)


@pytest.fixture(scope="module")
def scene() -> SyntheticScene:
    return generate_scene(SceneSpec.easy(), 0)


class Serve:
    """`jigsaw serve` as a real process, embedded Redis and local workers included."""

    def __init__(self, data_dir: Path) -> None:
        settings = make_settings(None, data_dir=data_dir)  # default: 2 local workers
        self.env = settings_env(settings)
        self.port = free_port()
        self.process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> Serve:
        command = [sys.executable, "-m", "cli.main", "serve", "--port", str(self.port)]
        self.process = subprocess.Popen(command, env=self.env, cwd=ROOT)

        def healthy() -> bool:
            assert self.process is not None and self.process.poll() is None, "serve exited"
            try:
                return httpx.get(f"{self.url}/healthz", timeout=1).status_code == 200
            except httpx.TransportError:
                return False

        wait_until(healthy, 30, interval=0.1)
        return self

    def children(self) -> list[int]:
        assert self.process is not None
        tasks = Path(f"/proc/{self.process.pid}/task").glob("*/children")
        return sorted(int(pid) for path in tasks for pid in path.read_text().split())

    def stop(self, sig: int = signal.SIGTERM) -> int:
        assert self.process is not None
        self.process.send_signal(sig)
        return self.process.wait(30)


def _gone(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    # A zombie (exited, not yet reaped by its parent) is gone too, and so is a process
    # reaped between the two looks.
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] == "Z"
    except FileNotFoundError:
        return True


def test_restarts_keep_accepted_fragments_and_results(tmp_path: Path, scene) -> None:
    serve = Serve(tmp_path / "data").start()
    try:
        children = serve.children()
        assert len(children) == 3  # Redis and two workers
        with httpx.Client(base_url=serve.url, timeout=30) as http:
            for f in scene.fragments:
                assert (
                    http.put(
                        f"/v1/sites/s/fragments/{f.id}", content=encode_ply(f.points)
                    ).status_code
                    == 202
                )
            result = wait_result(http, "s", status="closed")
            status = http.get("/v1/sites/s").json()
            wait_until(lambda: http.get("/readyz").status_code == 200, 10)
        time.sleep(1.1)  # the append-only file is flushed every second
        assert serve.stop(signal.SIGTERM) == 0
        assert all(_gone(pid) for pid in children)

        serve.start()
        with httpx.Client(base_url=serve.url, timeout=30) as http:
            assert http.get("/v1/sites/s/result").json() == result
            assert http.get("/v1/sites/s").json() == status
            first = scene.fragments[0]
            again = http.put(f"/v1/sites/s/fragments/{first.id}", content=encode_ply(first.points))
            assert again.status_code == 200
        # Killed outright, the server takes its Redis and workers with it (no orphan keeps
        # the data directory), and the next start finds everything again.
        children = serve.children()
        serve.stop(signal.SIGKILL)
        wait_until(lambda: all(_gone(pid) for pid in children), 10)
        serve.start()
        with httpx.Client(base_url=serve.url, timeout=30) as http:
            assert http.get("/v1/sites/s/result").json() == result
    finally:
        if serve.process is not None and serve.process.poll() is None:
            serve.stop()


def test_redis_outage_gives_503s_then_work_resumes(
    redis_process: RedisProcess, api_factory, start_workers: Workers, scene
) -> None:
    settings = make_settings(redis_process.url, redis_timeout_s=1.0)
    start_workers.start(settings, count=1)
    client = redis.Redis.from_url(redis_process.url, decode_responses=True)
    wait_workers_alive(client, "fpj", 1)
    server: ApiServer = api_factory(settings)
    first, *rest = scene.fragments
    with server.client() as http:
        assert (
            http.put(
                f"/v1/sites/s/fragments/{first.id}", content=encode_ply(first.points)
            ).status_code
            == 202
        )
        redis_process.stop()  # its layout job may be queued or running: it must not be lost
        for reply in (
            http.put(f"/v1/sites/s/fragments/{rest[0].id}", content=encode_ply(rest[0].points)),
            http.get("/v1/sites/s"),
            http.get("/v1/sites/s/result"),
            http.get("/readyz"),
        ):
            assert reply.status_code == 503, reply.text
            assert reply.json()["error"]["code"] == "unavailable"
            assert reply.headers["retry-after"] == "1"
        assert http.get("/healthz").status_code == 200
        time.sleep(1.0)
        redis_process.start()
        for f in rest:
            assert (
                http.put(f"/v1/sites/s/fragments/{f.id}", content=encode_ply(f.points)).status_code
                == 202
            )
        result = wait_result(http, "s", timeout=60, status="closed")
        assert sorted(f["id"] for f in result["fragments"]) == [f.id for f in scene.fragments]
        assert http.get("/readyz").status_code == 200
    client.close()


def _upload_started(port: int, path: str, body: bytes, sent: int) -> socket.socket:
    """A raw HTTP PUT of ``body`` of which only the first ``sent`` bytes go out."""
    connection = socket.create_connection(("127.0.0.1", port), timeout=10)
    head = (
        f"PUT {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/octet-stream\r\n"
        f"Content-Length: {len(body)}\r\n\r\n"
    )
    connection.sendall(head.encode() + body[:sent])
    return connection


def _stored_whole_or_not_at_all(client: redis.Redis, body: bytes) -> bool:
    """True when ``lab/f0`` is stored whole (record, exact bytes, its job), False when
    nothing of it is; fails the test on anything in between."""
    record = client.hgetall("fpj:site:lab:frag:f0")
    data: Any = client.get("fpj:site:lab:frag:f0:data")
    entries: Any = client.xrange("fpj:jobs") if client.exists("fpj:jobs") else []
    jobs = [fields[b"job"] for _, fields in entries]
    if not record:
        assert data is None and not jobs and not client.exists("fpj:site:lab:fragments")
        return False
    assert data is not None and zlib.decompress(data) == body
    assert len(jobs) == 1 and b'"fragment_id":"f0"' in jobs[0]
    return True


def test_api_killed_during_an_upload_stores_no_partial_fragment(
    tmp_path: Path, redis_url: str
) -> None:
    """SIGKILL of `jigsaw serve` (external Redis, no workers) while a body streams in, and
    right after it arrived (while it is checked and stored): never a partial fragment; the
    same upload afterwards is accepted whole."""
    raw = redis.Redis.from_url(redis_url)
    body = encode_ply(np.random.default_rng(0).uniform(-3, 3, size=(300_000, 3)))  # 3.6 MB
    path = "/v1/sites/lab/fragments/f0"
    for sent, pause in ((len(body) // 2, 0.5), (len(body), 0.05), (len(body), 0.2)):
        serve = Serve(tmp_path)
        serve.env = settings_env(make_settings(redis_url))
        serve.start()
        connection = _upload_started(serve.port, path, body, sent)
        time.sleep(pause)
        assert serve.stop(signal.SIGKILL) == -signal.SIGKILL
        connection.close()
        if sent < len(body):
            assert not _stored_whole_or_not_at_all(raw, body)
        elif _stored_whole_or_not_at_all(raw, body):
            break  # the kill came after the commit: stored whole, as it should be
    serve = Serve(tmp_path)
    serve.env = settings_env(make_settings(redis_url))
    serve.start()
    try:
        with httpx.Client(base_url=serve.url, timeout=30) as http:
            assert http.put(path, content=body).status_code in (200, 202)
        assert _stored_whole_or_not_at_all(raw, body)
    finally:
        serve.stop()
        raw.close()
