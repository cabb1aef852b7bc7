"""A job that always crashes, with real processes: it ends in the dead-letter stream after
``max_tries`` deliveries, ``jigsaw jobs`` shows it, and ``jigsaw jobs --retry`` runs it again
(once the cause is gone) to the end."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from typing import Any

import pytest
import redis

from schemas.settings import Settings
from store.keys import Keys
from tests.service_fixtures import (
    ROOT,
    ApiServer,
    Workers,
    make_settings,
    ply_bytes,
    settings_env,
    wait_until,
)

pytestmark = pytest.mark.timeout(120)


def _jigsaw(settings: Settings, *args: str) -> subprocess.CompletedProcess[str]:
    """``jigsaw ARGS`` as a real process reading ``settings`` from its environment."""
    command = [sys.executable, "-m", "cli.main", *args]
    return subprocess.run(
        command, env=settings_env(settings), cwd=ROOT, capture_output=True, text=True, timeout=60
    )


def _fragment(api: ApiServer, site: str, fragment: str) -> dict[str, Any]:
    with api.client() as http:
        reply: dict[str, Any] = http.get(f"/v1/sites/{site}/fragments/{fragment}").json()
    return reply


def test_crashing_job_is_dead_lettered_listed_and_retried(
    redis_url: str, api_factory: Callable[..., ApiServer], start_workers: Workers
) -> None:
    settings = make_settings(redis_url)
    keys, raw = Keys(settings.key_prefix), redis.Redis.from_url(redis_url)
    api = api_factory(settings)
    with api.client() as http:
        assert http.put("/v1/sites/lab/fragments/f0", content=ply_bytes(500)).status_code == 202
    # The stored bytes go bad before any worker reads them: every delivery crashes
    # (zlib.error in the layout handler, an internal error, retried).
    good: Any = raw.get(keys.fragment_data("lab", "f0"))
    assert isinstance(good, bytes)
    raw.set(keys.fragment_data("lab", "f0"), b"not a zlib stream")
    start_workers.start(settings, count=1)
    wait_until(
        lambda: raw.xlen(keys.dead) == 1, 60, describe=lambda: str(_fragment(api, "lab", "f0"))
    )
    failed = _fragment(api, "lab", "f0")
    assert failed["state"] == "failed" and failed["error"]["code"] == "internal_error"

    listed = _jigsaw(settings, "jobs", "--json")
    assert listed.returncode == 0, listed.stderr
    (letter,) = [json.loads(line) for line in listed.stdout.splitlines()]
    assert (letter["kind"], letter["site_id"], letter["fragment_id"]) == ("layout", "lab", "f0")
    assert letter["tries"] == settings.max_tries and letter["code"] == "internal_error"
    assert "zlib" in letter["message"] or "error" in letter["message"]

    raw.set(keys.fragment_data("lab", "f0"), good)  # the cause is fixed
    retried = _jigsaw(settings, "jobs", "--retry", letter["id"])
    assert retried.returncode == 0 and retried.stdout.strip() == f"{letter['id']}: queued"
    wait_until(lambda: _fragment(api, "lab", "f0")["state"] == "done", 60)
    assert raw.xlen(keys.dead) == 0

    missing = _jigsaw(settings, "jobs", "--retry", letter["id"])
    assert missing.returncode == 2 and "not_found" in missing.stdout
    raw.close()


def test_jobs_needs_redis() -> None:
    settings = make_settings(None)
    result = _jigsaw(settings, "jobs")
    assert result.returncode == 2 and "FPJ_REDIS_URL" in result.stderr
