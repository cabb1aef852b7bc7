"""Fixtures of the service tests that need real worker processes."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import pytest

from tests.service_fixtures import ApiServer, Workers, make_settings, wait_workers_alive


@pytest.fixture(scope="module")
def workers(redis7_url: str) -> Iterator[Workers]:
    """Two worker processes for the whole module (they survive the per-test flush)."""
    pool = Workers()
    pool.start(make_settings(redis7_url), count=2)
    yield pool
    pool.stop()


@pytest.fixture
def server(
    redis_url: str, api_factory: Callable[..., ApiServer], workers: Workers, redis_client: Any
) -> ApiServer:
    """The API on Redis 7 (db 15) with the module's two workers alive."""
    wait_workers_alive(redis_client, "fpj", 2)
    return api_factory(make_settings(redis_url))
