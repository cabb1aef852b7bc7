"""Uploads, status, listing, deletion, docs, health and metrics over real HTTP (no workers)."""

from __future__ import annotations

import hashlib
import time
from typing import Any

import httpx
import pytest
import redis

from schemas.jobs import decode_job
from schemas.service import SiteList, SiteStatus, UploadReply
from tests.service_fixtures import ApiServer, ply_bytes, wait_until

pytestmark = pytest.mark.timeout(60)


def test_upload_is_accepted_then_idempotent(api: ApiServer, redis_client: Any) -> None:
    data = ply_bytes(400)
    with api.client() as http:
        first = http.put("/v1/sites/s1/fragments/f1", content=data)
        assert first.status_code == 202
        reply = UploadReply.model_validate(first.json())
        assert reply.fragment_id == "f1" and reply.status == "queued" and reply.created
        assert reply.sha256 == hashlib.sha256(data).hexdigest()
        assert (reply.n_points, reply.format, reply.size_bytes) == (400, "ply", len(data))
        again = http.put("/v1/sites/s1/fragments/f1", content=data)
        assert again.status_code == 200
        assert again.json()["created"] is False and again.json()["status"] == "queued"
    jobs = [decode_job(f["job"]) for _, f in redis_client.xrange("fpj:jobs")]
    assert len(jobs) == 1 and jobs[0].kind == "layout"  # the duplicate queued nothing


def test_concurrent_identical_uploads_store_once(api: ApiServer, redis_client) -> None:
    import concurrent.futures

    data = ply_bytes(400)

    def put(_: int) -> int:
        with api.client() as http:
            return http.put("/v1/sites/s1/fragments/f1", content=data).status_code

    with concurrent.futures.ThreadPoolExecutor(8) as pool:
        codes = sorted(pool.map(put, range(8)))
    assert codes == [200] * 7 + [202]
    assert redis_client.xlen("fpj:jobs") == 1


def test_site_status_and_list(api: ApiServer) -> None:
    with api.client() as http:
        for fid in ("b", "a", "c"):
            http.put(f"/v1/sites/s1/fragments/{fid}", content=ply_bytes(300, seed=ord(fid)))
        http.put("/v1/sites/s2/fragments/x", content=ply_bytes(300))
        status = SiteStatus.model_validate(http.get("/v1/sites/s1").json())
        assert [f.fragment_id for f in status.fragments] == ["b", "a", "c"]  # upload order
        assert all(f.state == "queued" and f.progress == 0 for f in status.fragments)
        assert status.placement.state == "idle" and status.placement.last_placement_at is None
        assert not status.placement.loop_closed
        one = http.get("/v1/sites/s1/fragments/a").json()
        assert one["fragment_id"] == "a" and one["n_points"] == 300
        sites = SiteList.model_validate(http.get("/v1/sites").json())
        assert [(s.site_id, s.n_fragments) for s in sites.sites] == [("s1", 3), ("s2", 1)]
        page = http.get("/v1/sites", params={"offset": 1, "limit": 1}).json()
        assert page["total"] == 2 and [s["site_id"] for s in page["sites"]] == ["s2"]
        # Nothing placed yet: 202 from the result and the picture.
        assert http.get("/v1/sites/s1/result").status_code == 202
        assert http.get("/v1/sites/s1/floorplan.svg").json()["status"] == "processing"


def test_delete_fragment(api: ApiServer, redis_client: Any) -> None:
    with api.client() as http:
        http.put("/v1/sites/s1/fragments/a", content=ply_bytes(300))
        http.put("/v1/sites/s1/fragments/b", content=ply_bytes(300, seed=1))
        assert http.delete("/v1/sites/s1/fragments/a").status_code == 204
        assert http.delete("/v1/sites/s1/fragments/a").status_code == 404
        status = http.get("/v1/sites/s1").json()
        assert [f["fragment_id"] for f in status["fragments"]] == ["b"]
        assert status["placement"]["state"] == "queued"  # the site is re-placed
        assert not redis_client.exists("fpj:site:s1:frag:a:data")
        # The id is free again, for other bytes.
        assert http.put("/v1/sites/s1/fragments/a", content=ply_bytes(300, 5)).status_code == 202


def test_stored_bytes_are_the_upload_compressed(api: ApiServer) -> None:
    import zlib

    data = ply_bytes(2000)
    with api.client() as http:
        http.put("/v1/sites/s1/fragments/a", content=data)
    raw = redis.Redis.from_url(api.settings.redis_url or "")
    assert zlib.decompress(raw.get("fpj:site:s1:frag:a:data")) == data  # type: ignore[arg-type]


def test_health_readiness_and_metrics(api: ApiServer, redis_client: Any) -> None:
    with api.client() as http:
        assert http.get("/healthz").json() == {"status": "ok"}
        ready = http.get("/readyz")
        assert ready.status_code == 503 and ready.json()["error"]["code"] == "unavailable"
        redis_client.zadd("fpj:workers", {"w-1": time.time()})
        assert http.get("/readyz").json() == {"status": "ready", "redis": "ok", "workers": 1}
        http.put("/v1/sites/s1/fragments/a", content=ply_bytes(300))
        http.put("/v1/sites/s1/fragments/a", content=b"junk")
        text = http.get("/metrics").text
    for name in (
        'fpj_uploads_total{outcome="accepted"}',
        'fpj_uploads_total{outcome="conflict"}',
        'fpj_jobs_in_state{state="queued"} 1.0',
        "fpj_queue_depth 1.0",
        "fpj_workers_alive 1.0",
        'fpj_job_duration_seconds_bucket{kind="layout",le="+Inf"}',
        "fpj_sites 1.0",
    ):
        assert name in text, name


def test_openapi_declares_error_responses(api: ApiServer) -> None:
    with api.client() as http:
        spec = http.get("/openapi.json").json()
        assert http.get("/docs").status_code == 200
    put = spec["paths"]["/v1/sites/{site_id}/fragments/{fragment_id}"]["put"]
    assert {"200", "202", "400", "409", "413", "415", "422", "503"} <= set(put["responses"])
    assert put["responses"]["409"]["content"]["application/json"]["schema"]["$ref"].endswith(
        "ErrorBody"
    )
    assert "application/octet-stream" in put["requestBody"]["content"]
    result = spec["paths"]["/v1/sites/{site_id}/result"]["get"]
    assert {"200", "202", "404"} <= set(result["responses"])
    assert "/v1/sites/{site_id}/events" in spec["paths"]
    assert "/v1/sites/{site_id}/floorplan.svg" in spec["paths"]


def test_large_body_over_the_limit_gets_a_clean_413(redis_url: str, api_factory) -> None:
    from tests.service_fixtures import make_settings

    server = api_factory(make_settings(redis_url, max_upload_bytes=64 * 1024))
    with httpx.Client(base_url=server.url, timeout=30) as http:
        reply = http.put("/v1/sites/s/fragments/a", content=bytes(8 * 1024 * 1024))
    assert reply.status_code == 413
    assert reply.json()["error"]["code"] == "fragment_too_large"


def test_event_stream_starts_with_status_and_cleans_up(api: ApiServer, redis_client: Any) -> None:
    with api.client() as http:
        http.put("/v1/sites/s1/fragments/a", content=ply_bytes(300))
        with http.stream("GET", "/v1/sites/s1/events") as stream:
            assert stream.headers["content-type"].startswith("text/event-stream")
            lines = stream.iter_lines()
            assert next(lines) == "retry: 2000"
            assert next(lines) == ""
            assert next(lines) == "event: status"
            status = SiteStatus.model_validate_json(next(lines).removeprefix("data: "))
            assert [f.fragment_id for f in status.fragments] == ["a"]
            assert redis_client.pubsub_numsub("fpj:site:s1:events") == [("fpj:site:s1:events", 1)]
            # A new upload shows up as a fragment event.
            with api.client() as other:
                other.put("/v1/sites/s1/fragments/b", content=ply_bytes(300, seed=3))
            for line in lines:
                if line.startswith("data: ") and '"fragment_id":"b"' in line:
                    break
    # The client is gone: the subscription is released.
    wait_until(
        lambda: redis_client.pubsub_numsub("fpj:site:s1:events") == [("fpj:site:s1:events", 0)],
        5,
    )
