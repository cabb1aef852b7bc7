"""Container health check of a worker: ``python -m worker.health``.

Exit 0 when a worker process on this host (container) has written a heartbeat within
``FPJ_WORKER_ALIVE_S``; 1 otherwise (or when Redis cannot be reached).
"""

from __future__ import annotations

import socket
import time

from schemas.settings import get_settings
from store.connection import REDIS_DOWN, strings, sync_client
from store.keys import Keys

__all__ = ["main"]


def main() -> int:
    """The exit code: 0 when a worker of this host is alive, else 1."""
    settings = get_settings()
    if not settings.redis_url:
        return 1
    client = sync_client(settings.redis_url, timeout=3.0)
    since = time.time() - settings.worker_alive_s
    try:
        alive = strings(client.zrangebyscore(Keys(settings.key_prefix).workers, since, "+inf"))
    except REDIS_DOWN:
        return 1
    host = socket.gethostname()
    return 0 if any(worker.startswith(f"{host}-") for worker in alive) else 1


if __name__ == "__main__":
    raise SystemExit(main())
