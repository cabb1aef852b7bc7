"""RGB-D frames over HTTP: a zip bomb and bad frames refused with their code and nothing
stored, and three frames that close a room end to end (real uvicorn, real workers, Redis).
The archive checks themselves: tests/services/test_uploads.py."""

from __future__ import annotations

import pytest

from services.evaluation import evaluate_result
from services.synthetic.render import frame_ground_truth_json
from tests.frame_fixtures import (
    ROOM_SEED,
    frame_files,
    frame_zip,
    raw_zip,
    three_frames,
    zip_bomb,
    zip_files,
)
from tests.service_fixtures import ApiServer, redis_snapshot, wait_result

pytestmark = pytest.mark.timeout(120)


@pytest.fixture(scope="module")
def files() -> dict[str, bytes]:
    return frame_files(three_frames(0).frames[0].frame)


def test_a_gigabyte_entry_over_http_is_413_and_nothing_is_stored(
    server: ApiServer, redis_client
) -> None:
    bomb = zip_bomb(1 << 30)
    assert len(bomb) < 8_000_000  # 1 GiB inflated
    before = redis_snapshot(redis_client)
    with server.client() as http:
        reply = http.put("/v1/sites/s/fragments/f", content=bomb)
    assert reply.status_code == 413
    assert reply.json()["error"]["code"] == "archive_too_large"
    assert redis_snapshot(redis_client) == before


def test_bad_frames_over_http_get_their_code_and_store_nothing(
    server: ApiServer, redis_client, files
) -> None:
    flat = dict(files, **{"color.png": files["color.png"][:100]})
    cases = [
        (zip_files({"depth.png": files["depth.png"]}), 422, "missing_frame_file"),
        (zip_files(flat), 422, "invalid_color"),
        (b"PK\x03\x04truncated", 422, "invalid_archive"),
        (raw_zip([("../x", b"1")]), 422, "invalid_archive"),
        (b"GIF89a", 415, "unsupported_format"),
    ]
    before = redis_snapshot(redis_client)
    with server.client() as http:
        for body, status, code in cases:
            reply = http.put("/v1/sites/s/fragments/f", content=body)
            assert (reply.status_code, reply.json()["error"]["code"]) == (status, code)
    assert redis_snapshot(redis_client) == before


def test_three_zipped_frames_make_the_sites_room(server: ApiServer) -> None:
    scene = three_frames(ROOM_SEED)
    with server.client() as http:
        for f in scene.frames:
            reply = http.put(
                f"/v1/sites/rgbd/fragments/{f.id}",
                content=frame_zip(f.frame),
                headers={"content-type": "application/zip"},
            )
            assert reply.status_code == 202, reply.text
            assert reply.json()["format"] == "rgbd"
        # A frame site is 'ambiguous' short of near-certainty (tests/frame_fixtures.py).
        result = wait_result(http, "rgbd", timeout=90, status=("closed", "ambiguous"))
    assert all(f["placed"] for f in result["fragments"])
    assert len(result["floorplan"]["rooms"]) == 1
    assert result["confidence"] > 0.75  # a wide camera's frames: its view angle doubts them
    report = evaluate_result(result, frame_ground_truth_json(scene))
    assert report.global_correct
