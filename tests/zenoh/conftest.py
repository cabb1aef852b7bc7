"""The zenoh front end under test: ``jigsaw serve`` as a real process on loopback.

One service per test package (Redis 7 database 15, two local workers, zenoh listening on a
free loopback port, multicast scouting off, ROS 2 topics configured); robots are separate
processes (``jigsaw send`` / ``jigsaw watch``, see :class:`Proc`) or sessions of the test
process (:func:`robot_session`). Tests use their own site ids, so they share the service.
"""

from __future__ import annotations

import contextlib
import signal
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest
import redis
import zenoh

from schemas.settings import Settings
from tests.service_fixtures import (  # noqa: F401
    ROOT,
    free_port,
    make_settings,
    redis7_url,
    settings_env,
    wait_until,
)
from transport.config import ZenohOptions, build_config
from transport.keys import ZenohKeys

MAX_UPLOAD = 2_000_000
ROS_CLOUD_TOPIC = "/robot1/fragments"
ROS_SITE = "ros_site"
ROS_POSE_TOPIC = "/floorplan/poses"
ROS_DEPTH_TOPIC = "/robot2/depth/image_raw"  # CameraInfo on /robot2/depth/camera_info
ROS_DEPTH_SITE = "ros_depth_site"
ROS_DEPTH2_TOPIC = "/robot3/depth"  # CameraInfo on ROS_DEPTH2_INFO_TOPIC
ROS_DEPTH2_INFO_TOPIC = "/robot3/info"
ROS_DEPTH2_SITE = "ros_depth2_site"
ROS_MAP_TOPIC = "/floorplan/map"
ROS_TF_TOPIC = "/tf"
ROS_DEPTH_WAIT_S = 1.0


@dataclass
class ZenohService:
    """A running ``jigsaw serve`` with its zenoh front end."""

    settings: Settings
    http_port: int
    endpoint: str
    log: Path
    process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.http_port}"

    @property
    def keys(self) -> ZenohKeys:
        return ZenohKeys(self.settings.zenoh_prefix)

    def start(self) -> ZenohService:
        command = [sys.executable, "-m", "cli.main", "serve", "--port", str(self.http_port)]
        with self.log.open("ab") as out:
            self.process = subprocess.Popen(
                command, env=settings_env(self.settings), cwd=ROOT, stdout=out, stderr=out
            )

        def healthy() -> bool:
            assert self.process is not None and self.process.poll() is None, self.log_tail()
            try:
                return httpx.get(f"{self.url}/healthz", timeout=1).status_code == 200
            except httpx.TransportError:
                return False

        wait_until(healthy, 30, interval=0.1, describe=self.log_tail)
        return self

    def stop(self) -> int:
        assert self.process is not None
        self.process.send_signal(signal.SIGTERM)
        try:
            return self.process.wait(30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            raise

    def log_tail(self) -> str:
        return self.log.read_text(errors="replace")[-3000:]

    def http(self) -> httpx.Client:
        return httpx.Client(base_url=self.url, timeout=30)

    def robot_command(self, *args: str, robot: str | None = None) -> list[str]:
        """A ``jigsaw send|watch`` command line connecting to this service."""
        command = [sys.executable, "-m", "cli.main", *args, "--connect", self.endpoint]
        return [*command, "--timeout", "20", *(["--robot", robot] if robot else [])]


@pytest.fixture(scope="package")
def zenoh_service(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[ZenohService]:
    """The service for every test of this package; stopping it with SIGTERM must exit 0."""
    redis_url = str(request.getfixturevalue("redis7_url"))  # skips without Redis
    client = redis.Redis.from_url(redis_url)
    client.flushdb()
    zenoh_port = free_port()
    settings = make_settings(
        redis_url,
        local_workers=2,
        max_upload_bytes=MAX_UPLOAD,
        log_level="info",
        zenoh_listen=f"tcp/127.0.0.1:{zenoh_port}",
        zenoh_ros_cloud_topics=f"{ROS_CLOUD_TOPIC}={ROS_SITE}",
        zenoh_ros_pose_topic=ROS_POSE_TOPIC,
        zenoh_ros_depth_topics=f"{ROS_DEPTH_TOPIC}={ROS_DEPTH_SITE},"
        f"{ROS_DEPTH2_TOPIC}:{ROS_DEPTH2_INFO_TOPIC}={ROS_DEPTH2_SITE}",
        zenoh_ros_depth_wait_s=ROS_DEPTH_WAIT_S,
        zenoh_ros_map_topic=ROS_MAP_TOPIC,
        zenoh_ros_tf_topic=ROS_TF_TOPIC,
        zenoh_presence_ttl_s=3.0,
    )
    log = tmp_path_factory.mktemp("zenoh") / "serve.log"
    service = ZenohService(settings, free_port(), f"tcp/127.0.0.1:{zenoh_port}", log).start()
    try:
        yield service
    finally:
        code = service.stop()
        client.flushdb()
        client.close()
    assert code == 0, service.log_tail()


@contextlib.contextmanager
def robot_session(service: ZenohService) -> Iterator[zenoh.Session]:
    """A robot's zenoh session in the test process, connected to the service."""
    options = ZenohOptions(mode="peer", connect=[service.endpoint])
    with zenoh.open(build_config(options)) as session:
        yield session


@dataclass
class Proc:
    """A robot as a separate process; its output lines are collected as they come."""

    command: list[str]
    out: list[str] = field(default_factory=list)
    err: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.process = subprocess.Popen(
            self.command,
            cwd=ROOT,
            env=settings_env(make_settings(None)),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self._readers = [
            threading.Thread(target=self._read, args=(self.process.stdout, self.out), daemon=True),
            threading.Thread(target=self._read, args=(self.process.stderr, self.err), daemon=True),
        ]
        for reader in self._readers:
            reader.start()

    @staticmethod
    def _read(stream: Any, lines: list[str]) -> None:
        for line in stream:
            lines.append(line.rstrip("\n"))

    def wait_for(self, predicate: Callable[[list[str]], Any], timeout: float = 30) -> Any:
        """Wait until ``predicate(stdout lines)`` is truthy."""
        return wait_until(lambda: predicate(list(self.out)), timeout, describe=self.describe)

    def wait_err(self, text: str, timeout: float = 30) -> None:
        wait_until(lambda: any(text in line for line in self.err), timeout, describe=self.describe)

    def finish(self, timeout: float = 30) -> int:
        code = self.process.wait(timeout)
        for reader in self._readers:
            reader.join(5)
        return code

    def stop(self, sig: int = signal.SIGTERM) -> int:
        if self.process.poll() is None:
            self.process.send_signal(sig)
        return self.finish()

    def close(self) -> None:
        """Close the output pipes (after :meth:`finish`; left open they warn when collected)."""
        for stream in (self.process.stdout, self.process.stderr):
            if stream is not None:
                stream.close()

    def describe(self) -> str:
        return f"stdout {self.out[-5:]}, stderr {self.err[-5:]}"


@pytest.fixture
def procs() -> Iterator[Callable[[list[str]], Proc]]:
    """Start robot processes; any still running after the test is killed."""
    started: list[Proc] = []

    def start(command: list[str]) -> Proc:
        proc = Proc(command)
        started.append(proc)
        return proc

    yield start
    for proc in started:
        if proc.process.poll() is None:
            proc.process.kill()
        proc.finish()
        proc.close()
