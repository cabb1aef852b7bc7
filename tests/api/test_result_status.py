"""Status and confidence out over real HTTP on real Redis: the site status, the result, the
picture and the server-sent events after a placement stores an ambiguous result (written by
the worker's own store_result, as a placement job would)."""

from __future__ import annotations

import threading
from typing import Any

import pytest

from schemas.result import ResultModel
from store.connection import sync_client
from store.keys import Keys
from tests.service_fixtures import (
    ApiServer,
    SiteEvents,
    make_settings,
    ply_bytes,
    read_events,
    wait_until,
)
from worker.updates import JobContext, store_result

pytestmark = pytest.mark.timeout(30)

POSE = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
AMBIGUOUS = ResultModel.model_validate(
    {
        "status": "ambiguous",
        "confidence": 0.62,
        "fragments": [{"id": "a", "placed": True, "pose": POSE, "loop_index": 0}],
        "floorplan": {"rooms": [{"id": "room_0", "polygon": [[0, 0], [4, 0], [4, 3], [0, 3]]}]},
        "alternatives": [
            {
                "probability": 0.3,
                "fragments": [{"id": "a", "pose": POSE, "loop_index": 0}],
                "floorplan": {"rooms": [{"id": "room_0", "polygon": [[0, 0], [3, 0], [3, 4]]}]},
            }
        ],
    }
)


def _store(redis_url: str, site: str, result: ResultModel) -> None:
    settings = make_settings(redis_url)
    client = sync_client(redis_url, timeout=5)
    try:
        ctx = JobContext(client, client, Keys(), settings, settings.pipeline_params())
        assert store_result(ctx, site, 1, result)
    finally:
        client.close()


def _done(kind: str, event: dict[str, Any]) -> bool:
    return kind == "placement" and event["data"].get("result_status") is not None


def test_status_result_picture_and_events_show_status_and_confidence(
    api: ApiServer, redis_url: str
) -> None:
    events: SiteEvents = []
    with api.client() as http:
        assert http.put("/v1/sites/s1/fragments/a", content=ply_bytes(300)).status_code == 202
        listener = threading.Thread(
            target=read_events, args=(api.url, "s1", events, _done, 20), daemon=True
        )
        listener.start()
        wait_until(lambda: events, 10)  # subscribed (the status snapshot came)
        _store(redis_url, "s1", AMBIGUOUS)
        listener.join(10)
        assert not listener.is_alive(), events

        placement = http.get("/v1/sites/s1").json()["placement"]
        assert placement["state"] == "done" and placement["result_status"] == "ambiguous"
        assert placement["confidence"] == pytest.approx(0.62) and placement["alternatives"] == 1
        assert placement["loop_closed"] is True
        listed = http.get("/v1/sites").json()["sites"][0]["placement"]
        assert listed["confidence"] == pytest.approx(0.62)

        result = http.get("/v1/sites/s1/result")
        assert result.status_code == 200
        assert ResultModel.model_validate(result.json()) == AMBIGUOUS
        svg = http.get("/v1/sites/s1/floorplan.svg")
        assert svg.status_code == 200 and "confidence 0.62" in svg.text
        assert "stroke-dasharray" in svg.text

    kinds = {kind: data for kind, data in events}
    assert kinds["result"]["data"]["status"] == "ambiguous"
    assert kinds["result"]["data"]["confidence"] == pytest.approx(0.62)
    assert kinds["placement"]["data"]["confidence"] == pytest.approx(0.62)


@pytest.mark.parametrize("status", ["closed", "open"])
def test_result_is_200_for_closed_and_open(api: ApiServer, redis_url: str, status: str) -> None:
    with api.client() as http:
        assert http.put("/v1/sites/s1/fragments/a", content=ply_bytes(300)).status_code == 202
        _store(redis_url, "s1", ResultModel(status=status, confidence=0.9))
        reply = http.get("/v1/sites/s1/result")
        assert reply.status_code == 200 and reply.json()["status"] == status
        placement = http.get("/v1/sites/s1").json()["placement"]
        assert placement["loop_closed"] is (status == "closed")
