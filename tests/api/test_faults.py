"""Faults of the whole service: restarts of `jigsaw serve` (embedded Redis), Redis outages."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
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
