"""The web view and the docs over real HTTP (uvicorn, Redis 7): pages and every asset they
reference come from the service itself, tokens are honoured, the event stream works before a
site exists, the glTF download, ISO 8601 times."""

from __future__ import annotations

import json
import re
import threading
from collections.abc import Callable
from datetime import datetime
from typing import Any

import pytest

from api.colors import fragment_color, fragment_rgb
from schemas.result import ResultModel
from store.keys import Keys
from tests.service_fixtures import (
    ApiServer,
    SiteEvents,
    make_settings,
    ply_bytes,
    read_events,
    wait_until,
)

pytestmark = pytest.mark.timeout(60)

KEYS = Keys("fpj")
_ASSET = re.compile(r'(?:src|href)="([^"#]+)"')
_SVG_NS = "http://www.w3.org/2000/svg"


def _assets(html: str) -> list[str]:
    return [ref for ref in _ASSET.findall(html) if not ref.startswith("data:")]


def _square_result(placed: bool = True) -> dict[str, Any]:
    pose = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    return ResultModel.model_validate(
        {
            "status": "closed" if placed else "failed",
            "confidence": 0.9 if placed else 0.0,
            "fragments": [
                {
                    "id": "a",
                    "placed": placed,
                    "pose": pose if placed else None,
                    "loop_index": 0 if placed else None,
                    "local_layout": {"keypoints": [[0, 0, 0], [4, 0, 0], [4, 3, 0]]},
                }
            ],
            "floorplan": {
                "rooms": [{"id": "room_0", "polygon": [[0, 0], [4, 0], [4, 3], [0, 3]]}]
                if placed
                else []
            },
        }
    ).model_dump(mode="json")


def _store_result(redis_client: Any, site: str, result: dict[str, Any]) -> None:
    redis_client.zadd(KEYS.sites, {site: 1.0})
    redis_client.hset(KEYS.site(site), mapping={"created_at": "1.0", "updated_at": "1.0"})
    redis_client.set(KEYS.result(site), json.dumps(result))


@pytest.mark.parametrize("page", ["/", "/sites/lab"])
def test_pages_and_their_assets_come_from_the_service(api: ApiServer, page: str) -> None:
    with api.client() as http:
        reply = http.get(page)
        assert reply.status_code == 200 and reply.headers["content-type"].startswith("text/html")
        assets = _assets(reply.text)
        assert any(a.endswith(".js") for a in assets) and any(a.endswith(".css") for a in assets)
        for ref in assets:
            assert "//" not in ref, f"{page} loads {ref} from elsewhere"
            url = reply.url.join(ref)
            asset = http.get(url)
            assert asset.status_code == 200, (page, ref)
            if ref.endswith((".js", ".css")):
                links = re.findall(r"https?://[^\s\"'`)]+", asset.text)
                assert [link for link in links if link != _SVG_NS] == [], (ref, links)


def test_docs_work_offline(api: ApiServer) -> None:
    with api.client() as http:
        docs = http.get("/docs")
        assert docs.status_code == 200
        assets = _assets(docs.text) + re.findall(r'<script src="([^"]+)"', docs.text)
        assert "/static/swagger-ui/swagger-ui-bundle.js" in assets
        assert "/static/swagger-ui/swagger-ui.css" in assets
        for ref in assets:
            assert ref.startswith("/"), ref
            asset = http.get(ref)
            assert asset.status_code == 200, ref
            if ref.endswith((".js", ".css")):
                assert len(asset.content) > 10_000, ref  # the real bundle, not a stub
        assert "https://" not in docs.text and "http://" not in docs.text
        assert '"validatorUrl": null' in docs.text
        assert http.get("/openapi.json").json()["openapi"].startswith("3.1")
        assert http.get("/docs/oauth2-redirect").status_code == 200
        assert http.get("/redoc").status_code == 404


def test_invalid_site_id_page_is_400(api: ApiServer) -> None:
    with api.client() as http:
        assert http.get("/sites/no%20spaces").status_code == 400
        assert http.get("/sites/%2E%2E").status_code == 400


def test_tokens_guard_data_not_pages(redis_url: str, api_factory: Callable[..., ApiServer]) -> None:
    server = api_factory(make_settings(redis_url, tokens=["s3cret"]))
    with server.client() as http:
        for page in ("/", "/sites/lab", "/docs", "/static/web/site.js", "/openapi.json"):
            assert http.get(page).status_code == 200, page
        assert http.get("/v1/sites").status_code == 401
        auth = {"Authorization": "Bearer s3cret"}
        assert http.get("/v1/sites", headers=auth).status_code == 200
        # ?access_token= is taken by the event stream only (browsers' EventSource).
        assert http.get("/v1/sites", params={"access_token": "s3cret"}).status_code == 401
        assert http.get("/v1/sites/lab/events", params={"access_token": "no"}).status_code == 403
        assert http.get("/v1/sites/lab/events").status_code == 401
        with http.stream("GET", "/v1/sites/lab/events?access_token=s3cret") as stream:
            assert stream.status_code == 200
            assert stream.headers["content-type"].startswith("text/event-stream")


def test_events_before_the_first_upload(api: ApiServer) -> None:
    events: SiteEvents = []
    done = threading.Event()

    def listen() -> None:
        read_events(api.url, "early", events, lambda kind, _: kind == "fragment", timeout=30)
        done.set()

    threading.Thread(target=listen, daemon=True).start()
    wait_until(lambda: events, 10)
    kind, status = events[0]
    assert kind == "status"
    assert status["site_id"] == "early" and status["fragments"] == []
    assert status["created_at"] is None
    with api.client() as http:
        assert http.get("/v1/sites/early").status_code == 404  # still not a site
        assert http.put("/v1/sites/early/fragments/f1", content=ply_bytes()).status_code == 202
    assert done.wait(15)
    kind, event = events[-1]
    assert kind == "fragment" and event["fragment_id"] == "f1"
    assert event["data"]["state"] == "queued"
    datetime.fromisoformat(event["time"])


def test_times_are_iso_8601(api: ApiServer) -> None:
    with api.client() as http:
        http.put("/v1/sites/t/fragments/f1", content=ply_bytes())
        status = http.get("/v1/sites/t").json()
        listed = http.get("/v1/sites").json()["sites"][0]
    stamps = [status["created_at"], status["updated_at"], listed["updated_at"]]
    stamps += [status["fragments"][0]["created_at"], status["fragments"][0]["updated_at"]]
    for stamp in stamps:
        assert isinstance(stamp, str) and stamp.endswith("Z"), stamp
        moment = datetime.fromisoformat(stamp)
        assert moment.tzinfo is not None and moment.year >= 2024


def test_layout_gltf_download(api: ApiServer, redis_client: Any) -> None:
    with api.client() as http:
        assert http.get("/v1/sites/none/layout.gltf").status_code == 404
        http.put("/v1/sites/g/fragments/f1", content=ply_bytes())
        assert http.get("/v1/sites/g/layout.gltf").status_code == 202  # nothing placed yet
        _store_result(redis_client, "g", _square_result())
        reply = http.get("/v1/sites/g/layout.gltf")
        assert reply.status_code == 200
        assert reply.headers["content-type"].startswith("model/gltf+json")
        assert "attachment" in reply.headers["content-disposition"]
        gltf = reply.json()
        assert gltf["asset"]["version"] == "2.0"
        assert gltf["accessors"][0]["count"] > 0 and gltf["accessors"][1]["count"] % 3 == 0
        _store_result(redis_client, "g", _square_result(placed=False))
        missing = http.get("/v1/sites/g/layout.gltf")
        assert missing.status_code == 404
        assert missing.json()["error"]["code"] == "layout_not_found"


def test_fragment_colours_depend_on_the_id_only() -> None:
    assert fragment_color("frag_00") == fragment_color("frag_00")
    colours = {fragment_color(f"frag_{i:02d}") for i in range(12)}
    assert len(colours) >= 10  # neighbouring ids get different colours
    for i in range(12):
        r, g, b = fragment_rgb(f"frag_{i:02d}")
        assert max(r, g, b) <= 220  # dark enough to read on white
