"""``PUT``/``GET /v1/sites/{site}/hints`` over real HTTP on real Redis (no workers): stored,
replaced, refused with ``invalid_hints`` when invalid, and each change requests a placement."""

from __future__ import annotations

import json
from typing import Any

import httpx
import pytest

from schemas.hints import HintsModel
from schemas.jobs import decode_job
from tests.service_fixtures import ApiServer, ply_bytes, redis_snapshot

pytestmark = pytest.mark.timeout(30)

IDENTITY = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
HINTS: dict[str, Any] = {
    "schema_version": 1,
    "frame": "map",
    "fragments": {"a": {"pose": IDENTITY, "sigma_xy": 1.5, "sigma_yaw_deg": 20}},
    "neighbours": [["a", "ghost"]],  # "ghost" has not arrived (yet): kept all the same
    "order": ["a", "ghost"],
}


def _placement_jobs(redis_client: Any) -> int:
    jobs = [decode_job(fields["job"]) for _, fields in redis_client.xrange("fpj:jobs")]
    return sum(job.kind == "placement" for job in jobs)


def _assert_error(reply: httpx.Response, status: int, code: str) -> None:
    assert reply.status_code == status, reply.text
    body = reply.json()
    assert set(body) == {"error"} and body["error"]["code"] == code, body
    assert body["error"]["message"] and "\n" not in body["error"]["message"]


def test_put_stores_the_hints_and_requests_a_placement(api: ApiServer, redis_client) -> None:
    with api.client() as http:
        assert http.put("/v1/sites/s1/fragments/a", content=ply_bytes(300)).status_code == 202
        assert _placement_jobs(redis_client) == 0  # the layout job comes first
        generation = int(redis_client.hget("fpj:site:s1", "generation") or 0)
        reply = http.put("/v1/sites/s1/hints", content=json.dumps(HINTS))
        assert reply.status_code == 200, reply.text
        assert HintsModel.model_validate(reply.json()) == HintsModel.model_validate(HINTS)
        got = http.get("/v1/sites/s1/hints")
        assert got.status_code == 200 and got.json() == reply.json()
        stored = HintsModel.model_validate_json(redis_client.get("fpj:site:s1:hints"))
        assert stored == HintsModel.model_validate(HINTS)
        # The site is placed again: its generation moves and one placement job is queued.
        assert int(redis_client.hget("fpj:site:s1", "generation")) == generation + 1
        assert _placement_jobs(redis_client) == 1
        status = http.get("/v1/sites/s1").json()
        assert status["hints"] is True and status["placement"]["state"] == "queued"


def test_put_replaces_earlier_hints(api: ApiServer) -> None:
    with api.client() as http:
        assert http.put("/v1/sites/s1/hints", content=json.dumps(HINTS)).status_code == 200
        second = {"order": ["b", "c"]}
        assert http.put("/v1/sites/s1/hints", json=second).status_code == 200
        got = http.get("/v1/sites/s1/hints").json()
        assert got["order"] == ["b", "c"] and got["fragments"] == {} and got["neighbours"] == []


def test_hints_may_come_before_the_first_fragment(api: ApiServer) -> None:
    with api.client() as http:
        assert http.get("/v1/sites/early").status_code == 404
        assert http.put("/v1/sites/early/hints", json=HINTS).status_code == 200
        status = http.get("/v1/sites/early").json()
        assert status["fragments"] == [] and status["hints"] is True
        assert http.get("/v1/sites/early/result").status_code == 202  # nothing placed yet
        assert [s["site_id"] for s in http.get("/v1/sites").json()["sites"]] == ["early"]


@pytest.mark.parametrize(
    ("body", "words"),
    [
        (b"{not json", "json"),
        (b"[]", "object"),
        (json.dumps({**HINTS, "colour": "red"}).encode(), "colour"),  # unknown field
        (json.dumps({"fragments": {"a": {"pose": IDENTITY, "sigma": 1}}}).encode(), "sigma"),
        (json.dumps({"fragments": {"a": {"pose": [[2.0] * 4] * 4}}}).encode(), "pose"),
        (json.dumps({"order": ["a", "a"]}).encode(), "twice"),
        (json.dumps({"fragments": {"..": {"pose": IDENTITY}}}).encode(), "ids"),
        (json.dumps({"schema_version": 2}).encode(), "schema_version"),
    ],
)
def test_invalid_hints_are_refused_and_change_nothing(
    api: ApiServer, redis_client, body: bytes, words: str
) -> None:
    with api.client() as http:
        assert http.put("/v1/sites/s1/hints", json={"order": ["x"]}).status_code == 200
        before = redis_snapshot(redis_client)
        reply = http.put("/v1/sites/s1/hints", content=body)
        _assert_error(reply, 422, "invalid_hints")
        assert words in reply.json()["error"]["message"].lower()
        assert redis_snapshot(redis_client) == before
        assert http.get("/v1/sites/s1/hints").json()["order"] == ["x"]


def test_hints_errors(api: ApiServer) -> None:
    with api.client() as http:
        _assert_error(http.get("/v1/sites/nowhere/hints"), 404, "site_not_found")
        assert http.put("/v1/sites/s1/fragments/a", content=ply_bytes(300)).status_code == 202
        _assert_error(http.get("/v1/sites/s1/hints"), 404, "hints_not_found")
        _assert_error(http.put("/v1/sites/%2E%2E/hints", json=HINTS), 400, "invalid_id")
        big = json.dumps({"order": [f"f{i}" for i in range(200_000)]})
        _assert_error(http.put("/v1/sites/s1/hints", content=big), 413, "hints_too_large")
        assert http.get("/v1/sites/s1").json()["hints"] is False


def test_openapi_documents_the_hints_body(api: ApiServer) -> None:
    with api.client() as http:
        spec = http.get("/openapi.json").json()
    body = spec["paths"]["/v1/sites/{site_id}/hints"]["put"]["requestBody"]
    ref = body["content"]["application/json"]["schema"]["$ref"]
    assert ref.rsplit("/", 1)[-1] in spec["components"]["schemas"]
