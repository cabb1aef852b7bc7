"""A worker process: ``concurrency`` consumer threads and one keeper thread.

SIGTERM (or SIGINT) stops taking jobs; running ones get ``shutdown_grace_s`` to finish, and
whatever is still running after that stays pending on Redis for another worker to reclaim.
Run with ``jigsaw worker`` or ``python -m worker.main``.
"""

from __future__ import annotations

import logging
import os
import signal
import socket
import threading
import time
from collections.abc import Callable
from types import FrameType

import redis

from schemas.settings import Settings, get_settings
from store.connection import REDIS_DOWN, ensure_group, storage_refused, sync_client
from store.keys import Keys
from store.logs import configure_logging
from worker.consumer import BLOCK_MS, Consumer, Keeper, LeaseBook

__all__ = ["run_worker", "worker_id"]

log = logging.getLogger("worker")


def worker_id() -> str:
    """``host-pid``: unique per process, and tells which container a consumer lives in."""
    return f"{socket.gethostname()}-{os.getpid()}"


def _start(target: Callable[[], None], name: str) -> threading.Thread:
    thread = threading.Thread(target=target, name=name, daemon=True)
    thread.start()
    return thread


def _warm_up() -> None:
    """Import the pipeline now, so the first job does not pay for it."""
    import services.parsing
    import services.pipeline  # noqa: F401


def _prepare(settings: Settings, stop: threading.Event) -> None:
    """Wait for Redis (until stopped) and create the consumer group."""
    assert settings.redis_url is not None
    client = sync_client(settings.redis_url, timeout=5.0)
    while not stop.is_set():
        try:
            ensure_group(client, Keys(settings.key_prefix))
            return
        except REDIS_DOWN as exc:
            log.warning("waiting for Redis at %s: %s", settings.redis_url, exc)
            stop.wait(1.0)
        except redis.ResponseError as exc:
            if not storage_refused(exc):  # full: even an existing group's XGROUP is refused
                raise
            log.warning("waiting for room in Redis at %s: %s", settings.redis_url, exc)
            stop.wait(2.0)


def serve_jobs(settings: Settings, concurrency: int, stop: threading.Event) -> None:
    """Consume jobs until ``stop`` is set, then wait for running jobs (up to the grace)."""
    assert settings.redis_url is not None
    timeout = max(settings.redis_timeout_s, BLOCK_MS / 1000 + 5.0)
    client = sync_client(settings.redis_url, timeout=timeout)
    raw = sync_client(settings.redis_url, timeout=timeout, decode=False)
    wid, leases = worker_id(), LeaseBook()
    _warm_up()
    _prepare(settings, stop)
    keeper = Keeper(wid, client, settings, leases, stop)
    keeper.beat()
    consumers = [
        Consumer(f"{wid}-{slot}", client, raw, settings, leases, stop)
        for slot in range(concurrency)
    ]
    threads = [_start(c.run, c.name) for c in consumers]
    _start(keeper.run, f"{wid}-keeper")
    log.info("worker %s consuming with %d slot(s)", wid, concurrency)
    while not stop.wait(0.5):
        pass
    deadline = time.monotonic() + settings.shutdown_grace_s
    for thread in threads:
        thread.join(max(0.0, deadline - time.monotonic()))
    keeper.leave()
    log.info("worker %s stopped", wid)


def run_worker(concurrency: int | None = None) -> int:
    """Entry point of ``jigsaw worker``; returns the process exit code."""
    settings = get_settings()
    configure_logging(settings.log_level, settings.log_json)
    if not settings.redis_url:
        log.error("FPJ_REDIS_URL is not set: a worker needs the service's Redis")
        return 2
    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        log.info("signal %d: finishing running jobs, then stopping", signum)
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    serve_jobs(settings, concurrency or settings.worker_concurrency, stop)
    return 0


if __name__ == "__main__":
    raise SystemExit(run_worker())
