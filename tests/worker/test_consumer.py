"""The consumer loop on real Redis 7.0 and 6.2: ack, retry, dead letter, reclaim, leases.

The handlers here are small recorders standing in for the pipeline; Redis is real.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import pytest
import redis

from schemas.jobs import DeadLetter, LayoutJob, encode_job
from schemas.service import ErrorDetail
from services.errors import InvalidFragmentError
from store.connection import ensure_group
from store.keys import GROUP, Keys
from store.stats import parse_stats
from tests.service_fixtures import make_settings
from worker.consumer import Consumer, Keeper, LeaseBook
from worker.updates import JobContext

pytestmark = pytest.mark.timeout(30)

KEYS = Keys("fpj")


class Recorder:
    """A handler that records its calls and behaves as told."""

    def __init__(self, behaviour: Callable[[int], None] = lambda tries: None) -> None:
        self.behaviour = behaviour
        self.runs: list[int] = []
        self.failures: list[tuple[str, bool]] = []

    def run(self, ctx: JobContext, job: Any) -> dict[str, Any]:
        self.runs.append(ctx.tries)
        self.behaviour(ctx.tries)
        return {"outcome": "done"}

    def failed(self, ctx: JobContext, job: Any, error: ErrorDetail, final: bool) -> None:
        self.failures.append((error.code, final))


@pytest.fixture
def client(any_redis: str):
    c = redis.Redis.from_url(any_redis, decode_responses=True)
    ensure_group(c, KEYS)
    yield c
    c.close()


def _consumer(client: Any, handler: Recorder, name: str = "c1", **settings: Any):
    s = make_settings("redis://unused", max_tries=3, **settings)
    return Consumer(
        name, client, client, s, LeaseBook(), threading.Event(), handlers={"layout": handler}
    )


def _enqueue(client: Any) -> LayoutJob:
    job = LayoutJob(site_id="s", fragment_id="f", sha256="x")
    client.xadd(KEYS.jobs, {"job": encode_job(job)})
    return job


def _drain(consumer: Consumer, steps: int = 10) -> None:
    for _ in range(steps):
        consumer.step()


def _dead(client: Any) -> list[DeadLetter]:
    return [DeadLetter.model_validate_json(f["dead"]) for _, f in client.xrange(KEYS.dead)]


def _empty(client: Any) -> bool:
    return bool(client.xlen(KEYS.jobs) == 0 and client.xpending(KEYS.jobs, GROUP)["pending"] == 0)


def test_success_is_acknowledged_and_counted(client: Any) -> None:
    handler = Recorder()
    job = _enqueue(client)
    assert _consumer(client, handler).step()
    assert handler.runs == [1] and handler.failures == []
    assert _empty(client)
    assert client.get(KEYS.tries(job.job_id)) is None
    stats = parse_stats(client.hgetall(KEYS.stats))
    assert stats.counts[("layout", "done")] == 1
    assert stats.durations["layout"].buckets[-1][1] == 1
    assert stats.latencies["layout"].buckets[-1][1] == 1


def test_transient_failure_is_retried(client: Any) -> None:
    def flaky(tries: int) -> None:
        if tries == 1:
            raise RuntimeError("boom")

    handler = Recorder(flaky)
    _enqueue(client)
    _drain(_consumer(client, handler), 3)
    assert handler.runs == [1, 2]
    assert handler.failures == [("internal_error", False)]
    assert _empty(client) and _dead(client) == []


def test_exhausted_tries_go_to_the_dead_letter(client: Any) -> None:
    def broken(tries: int) -> None:
        raise RuntimeError("always")

    handler = Recorder(broken)
    _enqueue(client)
    _drain(_consumer(client, handler), 5)
    assert handler.runs == [1, 2, 3]
    assert handler.failures[-1] == ("internal_error", True)
    (letter,) = _dead(client)
    assert letter.tries == 3 and "always" in letter.message
    assert _empty(client)


def test_bad_input_fails_at_once(client: Any) -> None:
    def invalid(tries: int) -> None:
        raise InvalidFragmentError("truncated")

    handler = Recorder(invalid)
    _enqueue(client)
    _drain(_consumer(client, handler), 3)
    assert handler.runs == [1]
    assert handler.failures == [("invalid_fragment", True)]
    assert _dead(client)[0].code == "invalid_fragment"


def test_unreadable_job_is_dead_lettered(client: Any) -> None:
    client.xadd(KEYS.jobs, {"job": '{"version": 99, "kind": "layout"}'})
    handler = Recorder()
    _consumer(client, handler).step()
    assert handler.runs == []
    assert _dead(client)[0].code == "bad_job"
    assert _empty(client)


def test_job_of_a_crashed_consumer_is_reclaimed(client: Any) -> None:
    _enqueue(client)
    # "crashed" reads the job and dies without acknowledging it.
    client.xreadgroup(GROUP, "crashed", {KEYS.jobs: ">"}, count=1)
    client.incr(
        KEYS.tries(LayoutJob.model_validate_json(client.xrange(KEYS.jobs)[0][1]["job"]).job_id)
    )
    handler = Recorder()
    rescuer = _consumer(client, handler, "rescuer", visibility_timeout_s=0.3)
    assert not rescuer.step()  # not silent long enough yet
    time.sleep(0.4)
    rescuer._next_claim = 0.0
    assert rescuer.step()
    assert handler.runs == [2]  # the crashed delivery counted as a try
    assert _empty(client)


def test_deleted_pending_entry_is_dropped(client: Any) -> None:
    # Redis 6.2 still hands out ids of deleted entries from XAUTOCLAIM; 7.x drops them.
    _enqueue(client)
    ((message_id, _),) = client.xreadgroup(GROUP, "crashed", {KEYS.jobs: ">"}, count=1)[0][1]
    client.xdel(KEYS.jobs, message_id)
    handler = Recorder()
    rescuer = _consumer(client, handler, "rescuer", visibility_timeout_s=0.1)
    time.sleep(0.2)
    rescuer.step()
    assert handler.runs == []
    assert client.xpending(KEYS.jobs, GROUP)["pending"] == 0


def test_too_many_deliveries_give_up(client: Any) -> None:
    job = _enqueue(client)
    client.set(KEYS.tries(job.job_id), 3)  # three workers died running it
    handler = Recorder()
    _consumer(client, handler).step()
    assert handler.runs == []
    assert handler.failures == [("too_many_tries", True)]
    assert _dead(client)[0].code == "too_many_tries"


def test_running_job_is_kept_from_others_by_the_keeper(client: Any) -> None:
    settings = make_settings("redis://unused", visibility_timeout_s=0.6, heartbeat_interval_s=0.1)
    stop, leases = threading.Event(), LeaseBook()
    slow = Recorder(lambda tries: time.sleep(2.0))
    owner = Consumer("owner", client, client, settings, leases, stop, handlers={"layout": slow})
    keeper = Keeper("w1", client, settings, leases, stop)
    _enqueue(client)
    beating = threading.Thread(target=keeper.run, daemon=True)
    beating.start()
    runner = threading.Thread(target=owner.step)
    runner.start()
    # The owner must hold the job before the other consumer looks, or the other one may
    # simply read the new job first (a race of the test, not of the keeper).
    taken_by = time.monotonic() + 1.0
    while not leases.snapshot() and time.monotonic() < taken_by:
        time.sleep(0.005)
    assert leases.snapshot(), "the owner never took the job"
    other_handler = Recorder()
    other = Consumer(
        "other", client, client, settings, LeaseBook(), stop, handlers={"layout": other_handler}
    )
    deadline = time.monotonic() + 1.8
    while time.monotonic() < deadline:
        other._next_claim = 0.0
        other.step()
    runner.join()
    stop.set()
    # The keeper may be mid-beat: the fixture closes the client only after it is done.
    beating.join(timeout=5.0)
    assert other_handler.runs == [] and slow.runs == [1]
    assert _empty(client)
    assert client.zscore(KEYS.workers, "w1") is not None


def test_consumers_of_dead_workers_are_pruned(client: Any) -> None:
    settings = make_settings("redis://unused")
    for _ in range(3):
        _enqueue(client)
    client.xreadgroup(GROUP, "dead-1-0", {KEYS.jobs: ">"}, count=1)  # dies holding a job
    client.xreadgroup(GROUP, "gone-2-0", {KEYS.jobs: ">"}, count=1)
    client.xack(KEYS.jobs, GROUP, client.xrange(KEYS.jobs)[1][0])  # ...this one finished
    client.xreadgroup(GROUP, "live-3-0", {KEYS.jobs: ">"}, count=1)  # alive
    client.xack(KEYS.jobs, GROUP, client.xrange(KEYS.jobs)[2][0])
    keeper = Keeper("live-3", client, settings, LeaseBook(), threading.Event())
    keeper.beat()
    assert keeper.prune_consumers() == 1
    names = {c["name"] for c in client.xinfo_consumers(KEYS.jobs, GROUP)}
    assert names == {"dead-1-0", "live-3-0"}  # the dead one still holds a job to reclaim
