"""Scoped tokens over HTTP: each token does what its sites and rights allow, and nothing else
(401 without a token, 403 ``forbidden`` for an unknown one, 403 ``insufficient_scope`` for a
known one without the right on the site), alike on routes and the event stream."""

from __future__ import annotations

from collections.abc import Iterator

import httpx
import pytest

from tests.service_fixtures import ApiServer, make_settings, ply_bytes

pytestmark = pytest.mark.timeout(60)

TOKENS = "admin,robot:lab:upload,viewer:lab+hall:read,ops:*:read,cleaner:lab:delete"
HINTS = {"schema_version": 1, "neighbours": [["a", "b"]]}


def _as(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def _error(reply: httpx.Response, status: int, code: str) -> None:
    assert reply.status_code == status, reply.text
    assert reply.json()["error"]["code"] == code


@pytest.fixture
def http(redis_url: str, api_factory) -> Iterator[httpx.Client]:
    server: ApiServer = api_factory(make_settings(redis_url, tokens=TOKENS))
    with server.client() as client:
        for site in ("lab", "hall", "yard"):
            put = client.put(
                f"/v1/sites/{site}/fragments/a", content=ply_bytes(300), headers=_as("admin")
            )
            assert put.status_code == 202, put.text
        yield client


def test_upload_token_uploads_to_its_site_only(http: httpx.Client) -> None:
    robot = _as("robot")
    assert (
        http.put("/v1/sites/lab/fragments/b", content=ply_bytes(300), headers=robot).status_code
        == 202
    )
    assert http.put("/v1/sites/lab/hints", json=HINTS, headers=robot).status_code == 200
    _error(
        http.put("/v1/sites/hall/fragments/b", content=ply_bytes(300), headers=robot),
        403,
        "insufficient_scope",
    )
    _error(
        http.put("/v1/sites/new/fragments/b", content=ply_bytes(300), headers=robot),
        403,
        "insufficient_scope",
    )
    for path in (
        "/v1/sites/lab",
        "/v1/sites/lab/result",
        "/v1/sites/lab/hints",
        "/v1/sites",
        "/metrics",
    ):
        _error(http.get(path, headers=robot), 403, "insufficient_scope")
    _error(http.delete("/v1/sites/lab/fragments/b", headers=robot), 403, "insufficient_scope")
    # Another site's answer is the same whether it exists or not: a token learns nothing there.
    _error(http.get("/v1/sites/nowhere", headers=_as("viewer")), 403, "insufficient_scope")


def test_read_token_reads_its_sites_and_lists_only_them(http: httpx.Client) -> None:
    viewer = _as("viewer")
    assert http.get("/v1/sites/lab", headers=viewer).status_code == 200
    assert http.get("/v1/sites/hall/fragments/a", headers=viewer).status_code == 200
    _error(http.get("/v1/sites/yard", headers=viewer), 403, "insufficient_scope")
    listed = http.get("/v1/sites", headers=viewer).json()
    assert [s["site_id"] for s in listed["sites"]] == ["lab", "hall"] and listed["total"] == 2
    page = http.get("/v1/sites", params={"offset": 1, "limit": 1}, headers=viewer).json()
    assert [s["site_id"] for s in page["sites"]] == ["hall"]
    _error(
        http.put("/v1/sites/lab/fragments/c", content=ply_bytes(300), headers=viewer),
        403,
        "insufficient_scope",
    )
    _error(http.get("/metrics", headers=viewer), 403, "insufficient_scope")  # every site's figures
    ops = http.get("/v1/sites", headers=_as("ops")).json()
    assert [s["site_id"] for s in ops["sites"]] == ["lab", "hall", "yard"]
    assert http.get("/metrics", headers=_as("ops")).status_code == 200


def test_event_stream_takes_the_scope_too(http: httpx.Client) -> None:
    with http.stream("GET", "/v1/sites/hall/events?access_token=viewer") as stream:
        assert stream.status_code == 200
    _error(
        http.get("/v1/sites/yard/events", params={"access_token": "viewer"}),
        403,
        "insufficient_scope",
    )
    _error(
        http.get("/v1/sites/lab/events", params={"access_token": "robot"}),
        403,
        "insufficient_scope",
    )
    _error(http.get("/v1/sites/lab/events", params={"access_token": "nope"}), 403, "forbidden")
    _error(http.get("/v1/sites/lab/events"), 401, "unauthorized")


def test_delete_needs_the_delete_right(http: httpx.Client) -> None:
    _error(http.delete("/v1/sites/lab", headers=_as("ops")), 403, "insufficient_scope")
    _error(http.delete("/v1/sites/hall", headers=_as("cleaner")), 403, "insufficient_scope")
    assert http.delete("/v1/sites/lab", headers=_as("cleaner")).status_code == 204
    assert http.delete("/v1/sites/hall", headers=_as("admin")).status_code == 204
    listed = http.get("/v1/sites", headers=_as("admin")).json()
    assert [s["site_id"] for s in listed["sites"]] == ["yard"]
