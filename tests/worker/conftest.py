"""Service fixtures (real Redis 7 and 6.2, uvicorn, worker processes) for the worker tests."""

from tests.service_fixtures import (  # noqa: F401
    any_redis,
    api,
    api_factory,
    redis7_url,
    redis62_url,
    redis_client,
    redis_process,
    redis_url,
    start_workers,
)
