"""End to end over real HTTP with real worker processes on Redis 7: concurrent uploaders,
closed loops with correct poses, sites that do not mix, events, pictures, deletion."""

from __future__ import annotations

import concurrent.futures
import threading
from typing import Any

import numpy as np
import pytest

from schemas.params import PipelineParams
from services.pipeline import estimate_layout, place_site
from services.point_io import encode_ply
from services.synthetic import SceneSpec, SyntheticScene, generate_scene
from tests.service_fixtures import (
    ApiServer,
    SiteEvents,
    make_settings,
    read_events,
    wait_result,
    wait_until,
)

pytestmark = pytest.mark.timeout(120)


@pytest.fixture(scope="module")
def scenes(easy_scene: SyntheticScene) -> dict[int, SyntheticScene]:
    return {0: easy_scene, 2: generate_scene(SceneSpec.easy(), 2)}


def _upload_all(server: ApiServer, uploads: list[tuple[str, str, bytes]]) -> list[int]:
    """Each upload from its own client and thread, all at once."""
    barrier = threading.Barrier(len(uploads))

    def put(item: tuple[str, str, bytes]) -> int:
        site, fid, data = item
        with server.client() as http:
            barrier.wait()
            return http.put(f"/v1/sites/{site}/fragments/{fid}", content=data).status_code

    with concurrent.futures.ThreadPoolExecutor(len(uploads)) as pool:
        return list(pool.map(put, uploads))


def _pose_errors(result: dict[str, Any], scene: SyntheticScene) -> tuple[float, float]:
    """Largest translation (m) and rotation (deg) error of the poses relative to the first."""
    truth = {f.id: f.pose for f in scene.fragments}
    poses = {f["id"]: np.asarray(f["pose"]) for f in result["fragments"]}
    ids = list(poses)
    worst_t, worst_r = 0.0, 0.0
    for fid in ids[1:]:
        est = np.linalg.inv(poses[ids[0]]) @ poses[fid]
        gt = np.linalg.inv(truth[ids[0]]) @ truth[fid]
        delta = np.linalg.inv(gt) @ est
        angle = np.degrees(np.arccos(np.clip((np.trace(delta[:3, :3]) - 1) / 2, -1, 1)))
        worst_t = max(worst_t, float(np.linalg.norm(delta[:3, 3])))
        worst_r = max(worst_r, float(angle))
    return worst_t, worst_r


def _in_process(scene: SyntheticScene, order: list[str]) -> dict[str, Any]:
    """The pipeline run in this process on the same (float32-rounded) points, same order."""
    params = PipelineParams(parser=make_settings(None).parser_limits())
    fragments = sorted(scene.fragments, key=lambda f: order.index(f.id))
    layouts = {
        f.id: estimate_layout(f.points.astype(np.float32).astype(float), params) for f in fragments
    }
    return place_site(layouts, params).model_dump(mode="json")


def _events(server: ApiServer, site: str, out: SiteEvents, done: threading.Event) -> None:
    read_events(server.url, site, out, lambda kind, e: kind == "result" and _closed(e))
    done.set()


def _closed(event: dict[str, Any]) -> bool:
    return bool(event["data"]["status"] == "closed")


def test_concurrent_uploads_close_one_site(server: ApiServer, scenes, redis_client) -> None:
    scene = scenes[0]
    data = {f.id: encode_ply(f.points) for f in scene.fragments}
    with server.client() as http:
        # Open the event stream once the site exists (first fragment), then upload the rest.
        first = scene.fragments[0].id
        assert http.put(f"/v1/sites/site/fragments/{first}", content=data[first]).status_code == 202
        events: list[tuple[str, dict[str, Any]]] = []
        done = threading.Event()
        listener = threading.Thread(
            target=_events, args=(server, "site", events, done), daemon=True
        )
        listener.start()
        wait_until(lambda: events, 10)
        codes = _upload_all(server, [("site", fid, d) for fid, d in data.items() if fid != first])
        assert codes == [202] * (len(data) - 1)
        result = wait_result(http, "site", status="closed")
        order = [f["fragment_id"] for f in http.get("/v1/sites/site").json()["fragments"]]
        assert [f["id"] for f in result["fragments"]] == order  # upload order
        assert sorted(order) == sorted(data)
        assert all(f["placed"] for f in result["fragments"])
        translation, rotation = _pose_errors(result, scene)
        assert translation < 0.2 and rotation < 1.0, (translation, rotation)
        # The service computes what the pipeline computes in-process.
        expected = _in_process(scene, order)
        assert expected["status"] == "closed"
        for got, want in zip(result["fragments"], expected["fragments"], strict=True):
            np.testing.assert_allclose(got["pose"], want["pose"], atol=1e-6)
        assert len(result["floorplan"]["rooms"]) == 1
        status = http.get("/v1/sites/site").json()
        assert all(f["state"] == "done" and f["progress"] == 1 for f in status["fragments"])
        placement = status["placement"]
        assert placement["state"] == "done" and placement["loop_closed"] is True
        assert placement["result_generation"] == placement["generation"]
        assert placement["last_placement_at"] is not None
        svg = http.get("/v1/sites/site/floorplan.svg")
        assert svg.headers["content-type"].startswith("image/svg+xml") and "<polygon" in svg.text
        assert http.get("/readyz").json()["workers"] == 2
        metrics = http.get("/metrics").text
        assert f'fpj_jobs_total{{kind="layout",outcome="done"}} {len(data)}.0' in metrics
    assert done.wait(15)
    kinds = [kind for kind, _ in events]
    assert kinds[0] == "status"
    assert {"fragment", "placement", "result"} <= set(kinds)
    fragment_events = [e for k, e in events if k == "fragment"]
    assert any(e["data"].get("state") == "running" for e in fragment_events)
    assert any(e["data"].get("state") == "done" for e in fragment_events)


def test_two_sites_at_once_do_not_mix(server: ApiServer, scenes) -> None:
    uploads = [
        (f"site-{seed}", f.id, encode_ply(f.points))
        for seed, scene in scenes.items()
        for f in scene.fragments
    ]
    assert _upload_all(server, uploads) == [202] * len(uploads)
    with server.client() as http:
        for seed, scene in scenes.items():
            result = wait_result(http, f"site-{seed}", status="closed")
            assert sorted(f["id"] for f in result["fragments"]) == [f.id for f in scene.fragments]
            translation, rotation = _pose_errors(result, scene)
            assert translation < 0.2 and rotation < 1.0, (seed, translation, rotation)
            sha = {
                f["fragment_id"]: f["sha256"]
                for f in http.get(f"/v1/sites/site-{seed}").json()["fragments"]
            }
            assert len(sha) == len(scene.fragments)


def test_duplicate_is_a_no_op_and_conflict_is_409_after_processing(
    server: ApiServer, scenes, redis_client: Any
) -> None:
    scene = scenes[0]
    data = {f.id: encode_ply(f.points) for f in scene.fragments}
    with server.client() as http:
        for fid, d in data.items():
            http.put(f"/v1/sites/s/fragments/{fid}", content=d)
        wait_result(http, "s", status="closed")
        generation = http.get("/v1/sites/s").json()["placement"]["generation"]
        fid = scene.fragments[1].id
        again = http.put(f"/v1/sites/s/fragments/{fid}", content=data[fid])
        assert again.status_code == 200 and again.json()["status"] == "done"
        conflict = http.put(f"/v1/sites/s/fragments/{fid}", content=data[scene.fragments[0].id])
        assert conflict.status_code == 409
        assert redis_client.xlen("fpj:jobs") == 0
        assert http.get("/v1/sites/s").json()["placement"]["generation"] == generation


def test_deleting_a_fragment_replaces_the_site(server: ApiServer, scenes) -> None:
    scene = scenes[0]
    with server.client() as http:
        for f in scene.fragments:
            http.put(f"/v1/sites/s/fragments/{f.id}", content=encode_ply(f.points))
        wait_result(http, "s", status="closed")
        gone = scene.fragments[-1].id
        assert http.delete(f"/v1/sites/s/fragments/{gone}").status_code == 204

        def replaced() -> dict[str, Any] | None:
            result = http.get("/v1/sites/s/result").json()
            return result if len(result["fragments"]) == len(scene.fragments) - 1 else None

        result = wait_until(replaced, 30)
        assert gone not in [f["id"] for f in result["fragments"]]
        assert result["status"] in ("open", "closed")
