"""Placement coalescing and stream bookkeeping on real Redis 7.0 and 6.2."""

from __future__ import annotations

from typing import Any

import pytest
import redis

from schemas.jobs import DeadLetter, PlacementJob, decode_job
from store.connection import ensure_group
from store.jobs import ack, dead_letter, finish_placement, request_placement, retry_later
from store.keys import GROUP, Keys
from tests.service_fixtures import make_settings

pytestmark = pytest.mark.timeout(30)

KEYS = Keys("fpj")


@pytest.fixture
def client(any_redis: str):
    c = redis.Redis.from_url(any_redis, decode_responses=True)
    ensure_group(c, KEYS)
    for site in ("s1", "a", "b"):  # a site exists from its first upload on
        c.hset(KEYS.site(site), "created_at", "1.0")
    yield c
    c.close()


def _jobs(client: Any) -> list[PlacementJob]:
    return [decode_job(fields["job"]) for _, fields in client.xrange(KEYS.jobs)]  # type: ignore[misc]


def test_requests_coalesce_into_one_job(client: Any) -> None:
    settings = make_settings(None)
    generations = [request_placement(client, KEYS, settings, "s1") for _ in range(5)]
    assert generations == [1, 2, 3, 4, 5]
    jobs = _jobs(client)
    assert len(jobs) == 1 and jobs[0].kind == "placement"
    assert client.get(KEYS.placement_flag("s1")) == jobs[0].job_id
    assert client.pttl(KEYS.placement_flag("s1")) > 0
    assert client.hget(KEYS.site("s1"), "placement_state") == "queued"


def test_finish_releases_when_nothing_changed(client: Any) -> None:
    settings = make_settings(None)
    generation = request_placement(client, KEYS, settings, "s1")
    job = _jobs(client)[0]
    assert finish_placement(client, KEYS, settings, job, generation) is False
    assert client.get(KEYS.placement_flag("s1")) is None
    # The next request enqueues a new job straight away.
    request_placement(client, KEYS, settings, "s1")
    assert len(_jobs(client)) == 2


def test_finish_requeues_exactly_once_when_dirty(client: Any) -> None:
    settings = make_settings(None)
    started = request_placement(client, KEYS, settings, "s1")
    job = _jobs(client)[0]
    for _ in range(3):  # fragments landing while the placement runs
        request_placement(client, KEYS, settings, "s1")
    assert len(_jobs(client)) == 1
    assert finish_placement(client, KEYS, settings, job, started) is True
    jobs = _jobs(client)
    assert len(jobs) == 2
    assert client.get(KEYS.placement_flag("s1")) == jobs[1].job_id


def test_finish_leaves_a_newer_owner_alone(client: Any) -> None:
    settings = make_settings(None)
    request_placement(client, KEYS, settings, "s1")
    client.set(KEYS.placement_flag("s1"), "someone-else")
    stale = PlacementJob(site_id="s1")
    assert finish_placement(client, KEYS, settings, stale, 0) is False
    assert client.get(KEYS.placement_flag("s1")) == "someone-else"


def test_no_placement_for_a_site_that_does_not_exist(client: Any) -> None:
    # E.g. deleted while a fragment delete or hints were on their way: nothing comes back.
    assert request_placement(client, KEYS, make_settings(None), "gone") == 0
    assert _jobs(client) == []
    assert client.keys("fpj:site:gone*") == []


def test_sites_are_coalesced_separately(client: Any) -> None:
    settings = make_settings(None)
    request_placement(client, KEYS, settings, "a")
    request_placement(client, KEYS, settings, "b")
    request_placement(client, KEYS, settings, "a")
    assert sorted(j.site_id for j in _jobs(client)) == ["a", "b"]


def test_ack_retry_and_dead_letter(client: Any) -> None:
    for n in range(3):
        client.xadd(KEYS.jobs, {"job": f"raw-{n}"})
    entries = client.xreadgroup(GROUP, "c1", {KEYS.jobs: ">"}, count=3)[0][1]
    (id0, _), (id1, _), (id2, _) = entries
    client.set(KEYS.tries("j0"), 1)
    ack(client, KEYS, id0, "j0")
    assert client.get(KEYS.tries("j0")) is None
    retry_later(client, KEYS, id1, "raw-1")
    letter = DeadLetter(job="raw-2", code="x", message="m", tries=3, consumer="c1")
    dead_letter(client, KEYS, id2, None, letter)
    remaining = client.xrange(KEYS.jobs)
    assert [f["job"] for _, f in remaining] == ["raw-1"]  # the retried copy, at the end
    assert client.xpending(KEYS.jobs, GROUP)["pending"] == 0
    dead = client.xrange(KEYS.dead)
    assert DeadLetter.model_validate_json(dead[0][1]["dead"]).code == "x"
