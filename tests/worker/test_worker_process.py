"""Worker processes under faults: kill -9 in the middle of a job, SIGTERM."""

from __future__ import annotations

import os
import signal
import time
from typing import Any

import numpy as np
import pytest

from services.point_io import encode_ply
from store.keys import GROUP
from tests.service_fixtures import (
    ApiServer,
    Workers,
    make_settings,
    wait_result,
    wait_until,
    wait_workers_alive,
)

pytestmark = pytest.mark.timeout(120)


def _heavy(points: np.ndarray, copies: int = 40) -> bytes:
    """The fragment's points many times over (jittered): a job that runs long enough to kill."""
    rng = np.random.default_rng(0)
    return encode_ply(
        np.vstack([points + rng.normal(0, 0.002, points.shape) for _ in range(copies)])
    )


def test_kill_9_in_the_middle_of_a_job(
    redis_url: str, redis_client: Any, api_factory, start_workers: Workers, easy_scene
) -> None:
    settings = make_settings(redis_url, visibility_timeout_s=2.0)
    workers = start_workers.start(settings, count=2)
    wait_workers_alive(redis_client, "fpj", 2)
    server: ApiServer = api_factory(settings)
    heavy = easy_scene.fragments[0]
    key = f"fpj:site:site:frag:{heavy.id}"
    with server.client() as http:
        assert (
            http.put(
                f"/v1/sites/site/fragments/{heavy.id}", content=_heavy(heavy.points)
            ).status_code
            == 202
        )
        wait_until(lambda: redis_client.hget(key, "state") == "running", 30, interval=0.002)
        (pending,) = redis_client.xpending_range("fpj:jobs", GROUP, "-", "+", 10)
        victim = int(pending["consumer"].rsplit("-", 2)[-2])
        os.kill(victim, signal.SIGKILL)
        assert victim in [w.pid for w in workers]
        # The entry stays pending on the dead consumer until the visibility timeout.
        assert redis_client.xpending("fpj:jobs", GROUP)["pending"] == 1
        for fragment in easy_scene.fragments[1:]:
            http.put(f"/v1/sites/site/fragments/{fragment.id}", content=encode_ply(fragment.points))
        result = wait_result(http, "site", timeout=60, status="closed")
        assert len(result["fragments"]) == len(easy_scene.fragments)
        record = http.get(f"/v1/sites/site/fragments/{heavy.id}").json()
        assert record["state"] == "done" and record["tries"] == 2
    assert redis_client.xlen("fpj:jobs:dead") == 0
    assert redis_client.xpending("fpj:jobs", GROUP)["pending"] == 0


def test_sigterm_finishes_the_running_job_then_exits(
    redis_url: str, redis_client: Any, api_factory, start_workers: Workers, easy_scene
) -> None:
    settings = make_settings(redis_url)
    (worker,) = start_workers.start(settings, count=1)
    wait_workers_alive(redis_client, "fpj", 1)
    server: ApiServer = api_factory(settings)
    heavy = easy_scene.fragments[0]
    key = f"fpj:site:site:frag:{heavy.id}"
    with server.client() as http:
        http.put(f"/v1/sites/site/fragments/{heavy.id}", content=_heavy(heavy.points))
        wait_until(lambda: redis_client.hget(key, "state") == "running", 30, interval=0.002)
        worker.send_signal(signal.SIGTERM)
        started = time.monotonic()
        assert worker.wait(20) == 0
        assert time.monotonic() - started < 10
    assert redis_client.hget(key, "state") == "done"
    assert redis_client.zcard("fpj:workers") == 0  # heartbeat removed
    assert redis_client.xpending("fpj:jobs", GROUP)["pending"] == 0


def test_worker_without_redis_url_refuses_to_start(start_workers: Workers) -> None:
    import subprocess
    import sys

    from tests.service_fixtures import ROOT

    env = {k: v for k, v in os.environ.items() if not k.startswith("FPJ_")}
    env["PYTHONPATH"] = str(ROOT)
    done = subprocess.run([sys.executable, "-m", "worker.main"], env=env, cwd=ROOT, timeout=30)
    assert done.returncode == 2
