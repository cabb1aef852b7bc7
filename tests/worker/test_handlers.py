"""Layout and placement handlers with the real pipeline on real Redis (in-process consumer)."""

from __future__ import annotations

import asyncio
import json
import threading
import time
from collections.abc import Awaitable, Callable
from typing import Any

import pytest
import redis

from api.hints import replace_hints
from api.ingest import ingest_fragment
from api.site_data import delete_fragment, delete_site
from schemas.hints import HintsModel
from schemas.jobs import LayoutJob, PlacementJob, decode_job
from schemas.result import AlternativeModel, ResultModel
from services.point_io import encode_ply
from services.synthetic import SyntheticScene
from store.backend import Backend
from store.keys import Keys
from tests.service_fixtures import make_settings
from worker.consumer import Consumer, LeaseBook
from worker.handlers import HANDLERS
from worker.updates import JobContext, JobTimeoutError, store_result, update_fragment

pytestmark = pytest.mark.timeout(60)

KEYS = Keys("fpj")


@pytest.fixture
def setup(any_redis: str):
    settings = make_settings(any_redis)
    client = redis.Redis.from_url(any_redis, decode_responses=True)
    raw = redis.Redis.from_url(any_redis)
    yield settings, client, raw
    client.close()
    raw.close()


def _api(settings, call: Callable[[Backend], Awaitable[Any]]) -> Any:
    """Run one of the API's store functions, as the HTTP and zenoh front ends do."""

    async def run() -> Any:
        backend = await Backend.connect(settings)
        try:
            return await call(backend)
        finally:
            await backend.aclose()

    return asyncio.run(run())


def _upload(settings, site: str, fragments: dict[str, bytes]) -> None:
    async def upload(backend: Backend) -> None:
        for fid, data in fragments.items():
            await ingest_fragment(backend, site, fid, data)

    _api(settings, upload)


def _delete(settings, site: str, fid: str) -> None:
    _api(settings, lambda backend: delete_fragment(backend, site, fid))


def _consumer(settings, client, raw) -> Consumer:
    return Consumer("c", client, raw, settings, LeaseBook(), threading.Event())


def _run_all(consumer: Consumer, limit: int = 30) -> int:
    """Run jobs until the stream is empty; returns how many ran."""
    count = 0
    while consumer.client.xlen(KEYS.jobs) and count < limit:
        consumer.step()
        count += 1
    return count


def _ctx(settings, client, raw, **kwargs) -> JobContext:
    return JobContext(client, raw, KEYS, settings, settings.pipeline_params(), **kwargs)


def test_site_is_laid_out_then_placed_once(setup, easy_scene: SyntheticScene) -> None:
    settings, client, raw = setup
    _upload(settings, "site", {f.id: encode_ply(f.points) for f in easy_scene.fragments})
    consumer = _consumer(settings, client, raw)
    runs = _run_all(consumer)
    # One layout job per fragment, and the placements coalesced: the first placement request
    # enqueues one job; later requests only bump the generation; since every layout finished
    # before it ran, exactly one placement ran.
    assert runs == len(easy_scene.fragments) + 1
    site = client.hgetall(KEYS.site("site"))
    assert site["placement_state"] == "done"
    assert site["result_generation"] == site["generation"] == str(len(easy_scene.fragments))
    result = ResultModel.model_validate_json(client.get(KEYS.result("site")))
    assert result.status == "closed"
    assert [f.id for f in result.fragments] == [f.id for f in easy_scene.fragments]
    for fragment in easy_scene.fragments:
        record = client.hgetall(KEYS.fragment("site", fragment.id))
        assert record["state"] == "done" and record["progress"] == "1"
        assert client.exists(KEYS.fragment_layout("site", fragment.id))
    assert client.get(KEYS.placement_flag("site")) is None


def test_duplicate_delivery_changes_nothing(setup, easy_scene: SyntheticScene) -> None:
    settings, client, raw = setup
    fragment = easy_scene.fragments[0]
    _upload(settings, "site", {fragment.id: encode_ply(fragment.points)})
    job_json = client.xrange(KEYS.jobs)[0][1]["job"]
    consumer = _consumer(settings, client, raw)
    _run_all(consumer)
    layout = client.get(KEYS.fragment_layout("site", fragment.id))
    generation = client.hget(KEYS.site("site"), "generation")
    HANDLERS["layout"].run(_ctx(settings, client, raw), decode_job(job_json))
    assert client.get(KEYS.fragment_layout("site", fragment.id)) == layout
    # The layout and its placement request were written in one step: nothing to redo.
    assert client.hget(KEYS.site("site"), "generation") == generation


def test_stale_job_of_replaced_bytes_is_ignored(setup, easy_scene: SyntheticScene) -> None:
    settings, client, raw = setup
    fragment = easy_scene.fragments[0]
    _upload(settings, "site", {fragment.id: encode_ply(fragment.points)})
    stale = LayoutJob(site_id="site", fragment_id=fragment.id, sha256="0" * 64)
    HANDLERS["layout"].run(_ctx(settings, client, raw), stale)
    assert client.hget(KEYS.fragment("site", fragment.id), "state") == "queued"
    assert not client.exists(KEYS.fragment_layout("site", fragment.id))


def test_writes_never_resurrect_a_deleted_fragment(setup, easy_scene: SyntheticScene) -> None:
    settings, client, raw = setup
    fragment = easy_scene.fragments[0]
    _upload(settings, "site", {fragment.id: encode_ply(fragment.points)})
    sha = client.hget(KEYS.fragment("site", fragment.id), "sha256")
    _delete(settings, "site", fragment.id)
    ctx = _ctx(settings, client, raw)
    assert not update_fragment(ctx, "site", fragment.id, sha, {"state": "done"}, layout="{}")
    assert not client.exists(KEYS.fragment("site", fragment.id))
    assert not client.exists(KEYS.fragment_layout("site", fragment.id))


def test_layout_past_its_deadline_times_out(setup, easy_scene: SyntheticScene) -> None:
    settings, client, raw = setup
    fragment = easy_scene.fragments[0]
    _upload(settings, "site", {fragment.id: encode_ply(fragment.points)})
    job = decode_job(client.xrange(KEYS.jobs)[0][1]["job"])
    ctx = _ctx(settings, client, raw, deadline=time.monotonic() - 1)
    with pytest.raises(JobTimeoutError):
        HANDLERS["layout"].run(ctx, job)


def test_older_result_never_overwrites_a_newer_one(setup) -> None:
    settings, client, raw = setup
    ctx = _ctx(settings, client, raw)
    client.hset(KEYS.site("site"), "created_at", "1.0")
    assert store_result(ctx, "site", 5, ResultModel(status="closed"))
    assert not store_result(ctx, "site", 4, ResultModel(status="open"))
    assert ResultModel.model_validate_json(client.get(KEYS.result("site"))).status == "closed"
    assert client.hget(KEYS.site("site"), "result_generation") == "5"


def test_placement_waits_for_pending_layouts(setup, easy_scene: SyntheticScene) -> None:
    settings, client, raw = setup
    first, second = easy_scene.fragments[:2]
    _upload(settings, "site", {first.id: encode_ply(first.points)})
    consumer = _consumer(settings, client, raw)
    _run_all(consumer)
    generation = int(client.hget(KEYS.site("site"), "result_generation"))
    _upload(settings, "site", {second.id: encode_ply(second.points)})
    # A placement request arrives while the new fragment is still queued: it must wait.
    client.delete(KEYS.placement_flag("site"))
    job = PlacementJob(site_id="site")
    HANDLERS["placement"].run(_ctx(settings, client, raw), job)
    assert int(client.hget(KEYS.site("site"), "result_generation")) == generation
    assert client.get(KEYS.placement_flag("site")) is None
    _run_all(consumer)
    result = ResultModel.model_validate_json(client.get(KEYS.result("site")))
    assert [f.id for f in result.fragments] == [first.id, second.id]


def test_deleting_every_fragment_clears_the_result(setup, easy_scene: SyntheticScene) -> None:
    settings, client, raw = setup
    fragment = easy_scene.fragments[0]
    _upload(settings, "site", {fragment.id: encode_ply(fragment.points)})
    consumer = _consumer(settings, client, raw)
    _run_all(consumer)
    assert client.exists(KEYS.result("site"))
    _delete(settings, "site", fragment.id)
    _run_all(consumer)
    assert not client.exists(KEYS.result("site"))
    assert client.hget(KEYS.site("site"), "placement_state") == "idle"


def _loop_order(result: ResultModel) -> list[str]:
    placed = [f for f in result.fragments if f.placed and f.loop_index is not None]
    return [f.id for f in sorted(placed, key=lambda f: f.loop_index or 0)]


def test_placement_reads_the_sites_hints(setup, easy_scene: SyntheticScene) -> None:
    settings, client, raw = setup
    _upload(settings, "site", {f.id: encode_ply(f.points) for f in easy_scene.fragments})
    consumer = _consumer(settings, client, raw)
    _run_all(consumer)
    plain = ResultModel.model_validate_json(client.get(KEYS.result("site")))
    truth = _loop_order(plain)
    assert plain.status == "closed" and len(truth) == 3
    # Hints that turn the loop the other way round: new hints place the site again, and the
    # placement either follows them or reports them as contradicted by the scans.
    wrong = [truth[0], truth[2], truth[1]]
    _api(settings, lambda backend: replace_hints(backend, "site", HintsModel(order=wrong)))
    assert _run_all(consumer) == 1
    hinted = ResultModel.model_validate_json(client.get(KEYS.result("site")))
    assert int(client.hget(KEYS.site("site"), "result_generation")) == len(truth) + 1
    followed = _loop_order(hinted) == wrong
    reported = "hint" in json.dumps(hinted.diagnostics)
    assert followed or reported, (hinted.status, _loop_order(hinted), hinted.diagnostics)


def test_queued_jobs_of_a_deleted_site_do_not_bring_it_back(
    setup, easy_scene: SyntheticScene
) -> None:
    settings, client, raw = setup
    _upload(settings, "site", {f.id: encode_ply(f.points) for f in easy_scene.fragments[:2]})
    hints = HintsModel(order=[f.id for f in easy_scene.fragments[:2]])
    _api(settings, lambda backend: replace_hints(backend, "site", hints))
    kinds = sorted(decode_job(fields["job"]).kind for _, fields in client.xrange(KEYS.jobs))
    assert kinds == ["layout", "layout", "placement"]
    _api(settings, lambda backend: delete_site(backend, "site"))
    assert _run_all(_consumer(settings, client, raw)) == 3
    assert client.keys("fpj:site:site*") == []
    assert client.zscore(KEYS.sites, "site") is None


def test_results_go_only_to_the_site_the_job_started_on(setup) -> None:
    settings, client, raw = setup
    ctx = _ctx(settings, client, raw)
    ambiguous = ResultModel(
        status="ambiguous", confidence=0.55, alternatives=[AlternativeModel(probability=0.4)]
    )
    assert not store_result(ctx, "site", 1, ambiguous)  # deleted: nothing comes back
    assert client.keys("fpj:site:site*") == []
    client.hset(KEYS.site("site"), "created_at", "2.0")  # deleted and created again since
    assert not store_result(ctx, "site", 1, ambiguous, site_created="1.0")
    assert not client.exists(KEYS.result("site"))
    assert store_result(ctx, "site", 1, ambiguous, site_created="2.0")
    site = client.hgetall(KEYS.site("site"))
    assert (site["result_status"], site["loop_closed"]) == ("ambiguous", "1")
    assert (float(site["result_confidence"]), site["result_alternatives"]) == (0.55, "1")
