"""Faults of the whole service: restarts of `jigsaw serve` (embedded Redis), Redis outages and
restarts, the embedded Redis killed, the data directory's disk full."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
import redis

from services.point_io import encode_ply
from services.synthetic import SyntheticScene
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


class Serve:
    """`jigsaw serve` as a real process, embedded Redis and local workers included."""

    def __init__(self, data_dir: Path, **overrides: Any) -> None:
        settings = make_settings(None, data_dir=data_dir, **overrides)  # 2 local workers
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


def test_restarts_keep_accepted_fragments_and_results(tmp_path: Path, easy_scene) -> None:
    serve = Serve(tmp_path / "data").start()
    try:
        children = serve.children()
        assert len(children) == 3  # Redis and two workers
        with httpx.Client(base_url=serve.url, timeout=30) as http:
            for f in easy_scene.fragments:
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
            first = easy_scene.fragments[0]
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
    redis_process: RedisProcess, api_factory, start_workers: Workers, easy_scene
) -> None:
    settings = make_settings(redis_process.url, redis_timeout_s=1.0)
    start_workers.start(settings, count=1)
    client = redis.Redis.from_url(redis_process.url, decode_responses=True)
    wait_workers_alive(client, "fpj", 1)
    server: ApiServer = api_factory(settings)
    first, *rest = easy_scene.fragments
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
        assert sorted(f["id"] for f in result["fragments"]) == [f.id for f in easy_scene.fragments]
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


def _upload_scene(http: httpx.Client, site: str, scene: SyntheticScene) -> None:
    for f in scene.fragments:
        reply = http.put(f"/v1/sites/{site}/fragments/{f.id}", content=encode_ply(f.points))
        assert reply.status_code == 202, reply.text


def test_redis_restarted_mid_placement_loses_nothing_and_the_job_finishes(
    redis_process: RedisProcess, api_factory, start_workers: Workers, easy_scene
) -> None:
    """Redis (append-only file) killed outright while the site's placement runs, then started
    again on the same file: every fragment and layout is still there, and the placement
    (its job redelivered after the visibility timeout) ends in the closed result."""
    settings = make_settings(redis_process.url, redis_timeout_s=1.0)
    start_workers.start(settings, count=1)
    client = redis.Redis.from_url(redis_process.url, decode_responses=True)
    wait_workers_alive(client, "fpj", 1)
    server: ApiServer = api_factory(settings)
    with server.client() as http:
        _upload_scene(http, "s", easy_scene)
        wait_until(lambda: client.hget("fpj:site:s", "placement_state") == "running", 60, 0.01)
        before = {k: client.type(k) for k in client.scan_iter("fpj:site:s*")}
        assert redis_process.process is not None
        redis_process.process.kill()  # SIGKILL: no shutdown, only what the AOF holds
        redis_process.process.wait(10)
        time.sleep(0.5)
        redis_process.start()
        after = {k: client.type(k) for k in client.scan_iter("fpj:site:s*")}
        assert before.items() <= after.items()  # nothing lost (a result may have come)
        layouts = [client.exists(f"fpj:site:s:frag:{f.id}:layout") for f in easy_scene.fragments]
        assert all(layouts)
        result = wait_result(http, "s", timeout=90, status="closed")
        assert sorted(f["id"] for f in result["fragments"]) == [f.id for f in easy_scene.fragments]
    client.close()


def _redis_child(serve: Serve) -> int:
    found = [
        pid
        for pid in serve.children()
        if b"redis" in Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[0]
    ]
    assert len(found) == 1, found
    return found[0]


def test_the_embedded_redis_killed_is_restarted_with_its_data(tmp_path: Path, easy_scene) -> None:
    """SIGKILL of the embedded Redis: the service answers 503 (never from nothing) until
    it has restarted it on the same append-only file; then every result is there, and new
    uploads are placed."""
    serve = Serve(tmp_path / "data").start()
    try:
        with httpx.Client(base_url=serve.url, timeout=30) as http:
            _upload_scene(http, "s", easy_scene)
            result = wait_result(http, "s", status="closed")
            time.sleep(1.1)  # the append-only file is flushed every second
            first = _redis_child(serve)
            os.kill(first, signal.SIGKILL)
            reply = http.get("/v1/sites/s/result")
            assert reply.status_code in (200, 503), reply.text  # 200 only once restarted
            if reply.status_code == 503:
                assert reply.json()["error"]["code"] == "unavailable"
            wait_until(lambda: http.get("/readyz").status_code == 200, 30, 0.1)
            assert _redis_child(serve) != first
            assert http.get("/v1/sites/s/result").json() == result
            _upload_scene(http, "t", easy_scene)
            wait_result(http, "t", status="closed")
        assert serve.process is not None and serve.process.poll() is None
    finally:
        serve.stop()


def test_the_service_exits_when_its_redis_cannot_be_restarted(tmp_path: Path) -> None:
    """The embedded Redis killed and its binary gone bad: `jigsaw serve` exits with status
    1 and says why, rather than serve on without storage."""
    from api.processes import find_redis_server

    wrapper = tmp_path / "redis-server"
    wrapper.write_text(f'#!/bin/sh\nexec {find_redis_server()} "$@"\n')
    wrapper.chmod(0o755)
    serve = Serve(tmp_path / "data", redis_binary=str(wrapper))
    serve.start()
    assert serve.process is not None
    wrapper.write_text("#!/bin/sh\nexit 3\n")
    os.kill(_redis_child(serve), signal.SIGKILL)
    assert serve.process.wait(30) == 1


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A 48 MiB tmpfs (the data directory's own filesystem, which can be filled); skipped
    where mounting is not allowed (not root, no CAP_SYS_ADMIN)."""
    mount = tmp_path / "disk"
    mount.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=48m", "tmpfs", str(mount)], capture_output=True
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs: {done.stderr.decode().strip()}")
    yield mount
    subprocess.run(["umount", "-l", str(mount)], check=True)


def _fill(path: Path) -> None:
    with path.open("wb") as filler:
        try:
            while True:
                filler.write(bytes(1 << 20))
                filler.flush()
        except OSError:
            pass


def test_a_full_data_disk_is_507_and_harms_nothing_stored(small_disk: Path, easy_scene) -> None:
    """The embedded Redis's data directory on a small filesystem, filled up: uploads get
    507 storage_full (Redis cannot write its append-only file), what was stored reads
    unchanged; with room again uploads are accepted, and after a restart everything is
    there."""
    serve = Serve(small_disk / "data").start()
    try:
        with httpx.Client(base_url=serve.url, timeout=30) as http:
            _upload_scene(http, "s", easy_scene)
            result = wait_result(http, "s", status="closed")
            status = http.get("/v1/sites/s").json()
            time.sleep(1.1)
            _fill(small_disk / "filler")
            # Redis learns of the full disk writing its AOF after a reply, so a write or two
            # may still be acknowledged (kept in memory, written once there is room).
            codes = []
            for k in range(20):
                fid = f"late{k}"
                reply = http.put(
                    f"/v1/sites/t/fragments/{fid}",
                    content=encode_ply(
                        easy_scene.fragments[k % len(easy_scene.fragments)].points + k
                    ),
                )
                codes.append(reply.status_code)
                if reply.status_code == 507:
                    assert reply.json()["error"]["code"] == "storage_full", reply.text
                    break
                time.sleep(0.2)
            assert codes[-1] == 507, codes
            assert http.get("/v1/sites/s/result").json() == result
            assert http.get("/v1/sites/s").json()["fragments"] == status["fragments"]
            (small_disk / "filler").unlink()

            def accepted() -> bool:
                data = encode_ply(easy_scene.fragments[0].points + 100)
                return http.put("/v1/sites/u/fragments/f", content=data).status_code == 202

            wait_until(accepted, 30, 0.5)
            wait_until(lambda: http.get("/readyz").status_code == 200, 30, 0.2)
            time.sleep(1.1)
        assert serve.stop() == 0
        serve.start()
        with httpx.Client(base_url=serve.url, timeout=30) as http:
            assert http.get("/v1/sites/s/result").json() == result
            assert http.get("/v1/sites/u/fragments/f").status_code == 200
    finally:
        if serve.process is not None and serve.process.poll() is None:
            serve.stop()
