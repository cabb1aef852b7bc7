"""``jigsaw serve``: the API on uvicorn, plus (by default) an embedded Redis and local workers.

With ``FPJ_REDIS_URL`` unset, a private Redis server is started with its append-only file
under ``FPJ_DATA_DIR`` (so a restart keeps every accepted fragment and result; if it dies it
is restarted, and if that fails the service exits with status 1 rather than serve on without
storage), and ``FPJ_LOCAL_WORKERS`` (default 2) worker processes. With ``FPJ_REDIS_URL``
set, that server is used and no worker is started unless ``FPJ_LOCAL_WORKERS`` asks for some.
SIGTERM or SIGINT: stop accepting requests, let workers finish their jobs, stop Redis.
"""

from __future__ import annotations

import logging
import os
import signal
from contextlib import ExitStack
from types import FrameType

import uvicorn

from api.main import create_app
from api.processes import EmbeddedRedis, WorkerSupervisor
from schemas.settings import Settings, get_settings
from store.logs import configure_logging

__all__ = ["run_server"]

log = logging.getLogger("api.server")


class _Stopping:
    """SIGTERM/SIGINT before uvicorn runs (or re-raised by it afterwards): note, don't die."""

    def __init__(self) -> None:
        self.requested = False
        self.failure: str | None = None
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, self)

    def __call__(self, signum: int, frame: FrameType | None) -> None:
        self.requested = True

    def fail(self, reason: str) -> None:
        """Stop with an error (from any thread): the service never serves on without its
        storage. SIGTERM goes through the same graceful path as an operator's."""
        self.failure = reason
        log.error("%s: stopping the service", reason)
        os.kill(os.getpid(), signal.SIGTERM)


def _start_backing(settings: Settings, stack: ExitStack, stopping: _Stopping) -> Settings:
    """Start the embedded Redis (restarted if it dies) and local workers as configured;
    returns settings with the Redis URL."""
    count = settings.local_worker_count()  # before the URL is filled in: 2 when embedded
    if settings.embedded:
        embedded = EmbeddedRedis(
            settings.data_dir, settings.redis_binary, maxmemory=settings.max_stored_bytes
        )
        stack.callback(embedded.stop)
        settings = settings.model_copy(update={"redis_url": embedded.start()})
        embedded.watch(stopping.fail)
    if count:
        assert settings.redis_url is not None
        env = {**os.environ, "FPJ_REDIS_URL": settings.redis_url}
        supervisor = WorkerSupervisor(count, env)
        stack.callback(supervisor.stop, settings.shutdown_grace_s)
        supervisor.start()
        log.info("started %d local worker(s): %s", count, supervisor.pids())
    return settings


def run_server(host: str, port: int) -> int:
    """Run the service until SIGTERM/SIGINT; returns the process exit code."""
    settings = get_settings()
    configure_logging(settings.log_level, settings.log_json)
    stopping = _Stopping()
    with ExitStack() as stack:
        try:
            settings = _start_backing(settings, stack, stopping)
        except (OSError, RuntimeError) as exc:
            log.error("cannot start: %s", exc)
            return 1
        if stopping.requested:
            return 1 if stopping.failure else 0
        config = uvicorn.Config(
            create_app(settings),
            host=host,
            port=port,
            log_level=settings.log_level.lower(),
            log_config=None,  # keep configure_logging's one format (access lines included)
            timeout_graceful_shutdown=5,
        )
        server = uvicorn.Server(config)
        server.run()
        if not server.started and not stopping.requested:
            log.error("the HTTP server did not start")
            return 1
    if stopping.failure:
        log.error("stopped: %s", stopping.failure)
        return 1
    log.info("stopped")
    return 0
