"""Robots as separate processes: two send and watch, both receive the poses once the loop
closes, a late joiner gets the result by query, the site status lists who is connected and
what each sent, and a robot that disconnects disappears from it."""

from __future__ import annotations

import json
import signal
import time
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any

import pytest

from services.point_io import encode_ply
from services.synthetic import SyntheticScene
from tests.service_fixtures import ply_bytes, wait_until
from tests.zenoh.conftest import Proc, ZenohService, robot_session

pytestmark = pytest.mark.timeout(90)

SITE = "fleet"


def _closed_poses(lines: list[str], ids: set[str]) -> dict[str, Any] | None:
    """The latest closed pose of each fragment, once every one in ``ids`` has one."""
    poses = {}
    for line in lines:
        update = json.loads(line)
        assert 0.0 <= update["confidence"] <= 1.0, update  # each update says how sure it is
        if update["status"] == "closed":
            poses[update["fragment_id"]] = update["pose"]
    return poses if set(poses) >= ids else None


def _robots(http: Any, site: str) -> dict[str, list[str]]:
    reply = http.get(f"/v1/sites/{site}")
    if reply.status_code != 200:
        return {}
    return {r["robot_id"]: r["fragments"] for r in reply.json()["robots"]}


def test_two_robots_send_and_receive_poses(
    zenoh_service: ZenohService,
    procs: Callable[[list[str]], Proc],
    tmp_path: Path,
    easy_scene: SyntheticScene,
) -> None:
    files = []
    for fragment in easy_scene.fragments:
        files.append(tmp_path / f"{fragment.id}.ply")
        files[-1].write_bytes(encode_ply(fragment.points))
    (tmp_path / "broken.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\n")
    command = zenoh_service.robot_command
    watchers = {
        robot: procs(command("watch", "--site", SITE, robot=robot)) for robot in ("ra", "rb")
    }
    for watcher in watchers.values():
        watcher.wait_err("watching")

    sent_a = procs(command("send", "--site", SITE, *map(str, files[:2]), robot="ra"))
    assert sent_a.finish() == 0, sent_a.describe()
    replies = [json.loads(line) for line in sent_a.out]
    assert [(r["fragment_id"], r["created"], r["status"]) for r in replies] == [
        ("frag_00", True, "queued"),
        ("frag_01", True, "queued"),
    ]
    sent_b = procs(
        command("send", "--site", SITE, str(files[2]), str(tmp_path / "broken.ply"), robot="rb")
    )
    assert sent_b.finish() == 1, sent_b.describe()  # one reply is an error
    ok, error = (json.loads(line) for line in sent_b.out)
    assert ok["fragment_id"] == "frag_02" and ok["created"] is True
    assert error["error"]["code"] == "invalid_fragment"

    ids = {f.id for f in easy_scene.fragments}
    received = {
        r: w.wait_for(lambda lines: _closed_poses(lines, ids), 60) for r, w in watchers.items()
    }
    with zenoh_service.http() as http:
        result = http.get(f"/v1/sites/{SITE}/result").json()
        assert result["status"] == "closed"
        expected = {f["id"]: f["pose"] for f in result["fragments"]}
        for poses in received.values():
            assert poses == expected
        status = http.get(f"/v1/sites/{SITE}").json()
        assert sorted(f["fragment_id"] for f in status["fragments"]) == sorted(ids)  # no broken
        assert _robots(http, SITE) == {"ra": ["frag_00", "frag_01"], "rb": ["frag_02"]}

        # A late joiner: the result by query, and `watch` prints the latest poses first.
        with robot_session(zenoh_service) as session:
            replies = list(session.get(zenoh_service.keys.result(SITE), timeout=20))
            assert len(replies) == 1 and replies[0].ok is not None
            assert json.loads(replies[0].ok.payload.to_bytes()) == result
            every = list(session.get(zenoh_service.keys.all_results, timeout=20))
            assert SITE in {str(r.ok.key_expr).split("/")[2] for r in every if r.ok}
        late = procs(command("watch", "--site", SITE, "--count", "3"))
        assert late.finish() == 0, late.describe()
        assert _closed_poses(late.out, ids) == expected

        # Robot rb goes away (SIGTERM: its session closes), rb leaves the status; then ra is
        # killed outright (SIGKILL: zenoh notices the dead link) and leaves too.
        assert watchers["rb"].stop(signal.SIGTERM) == 0
        wait_until(lambda: set(_robots(http, SITE)) == {"ra"}, 15)
        watchers["ra"].stop(signal.SIGKILL)
        wait_until(lambda: _robots(http, SITE) == {}, 15)


def test_robot_presence_follows_its_session(zenoh_service: ZenohService) -> None:
    keys = zenoh_service.keys
    with zenoh_service.http() as http:
        with robot_session(zenoh_service) as session:
            with session.liveliness().declare_token(keys.robot("solo")):
                tag = b'{"robot_id": "solo"}'
                replies = list(
                    session.get(
                        keys.fragment("pres", "s1"), payload=ply_bytes(), attachment=tag, timeout=20
                    )
                )
                assert replies[0].ok is not None
                wait_until(lambda: _robots(http, "pres") == {"solo": ["s1"]}, 15)
                status = http.get("/v1/sites/pres").json()["robots"][0]
                since = datetime.fromisoformat(status["connected_since"])  # ISO 8601, UTC
                assert since.tzinfo is not None and since.timestamp() > time.time() - 60
            wait_until(lambda: _robots(http, "pres") == {}, 15)  # token undeclared
            with session.liveliness().declare_token(keys.robot("solo")):
                wait_until(lambda: _robots(http, "pres") == {"solo": ["s1"]}, 15)
        wait_until(lambda: _robots(http, "pres") == {}, 15)  # session closed
