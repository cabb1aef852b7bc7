"""Priors over zenoh (contract 5): a fragment's attachment ``prior`` becomes its entry of the
site's hints; a bad prior is refused and nothing is stored; `jigsaw send --prior`; pose
updates carry the result's status and confidence."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import redis

from schemas.hints import FragmentPrior
from schemas.result import ResultModel
from schemas.zenoh import PoseUpdate
from tests.service_fixtures import ply_bytes, wait_until
from tests.zenoh.conftest import Proc, ZenohService, robot_session

pytestmark = pytest.mark.timeout(60)

IDENTITY = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
MOVED = [[0.0, -1.0, 0.0, 2.0], [1.0, 0.0, 0.0, 3.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]


def _reply(session: Any, key: str, payload: bytes, attachment: dict[str, Any]) -> dict[str, Any]:
    (reply,) = session.get(key, payload=payload, attachment=json.dumps(attachment), timeout=20)
    sample = reply.ok if reply.ok is not None else reply.err
    body: dict[str, Any] = json.loads(sample.payload.to_bytes())
    return body


def _hints(http: Any, site: str) -> dict[str, Any] | None:
    reply = http.get(f"/v1/sites/{site}/hints")
    return reply.json() if reply.status_code == 200 else None


def test_query_prior_is_merged_into_the_hints(zenoh_service: ZenohService) -> None:
    keys = zenoh_service.keys
    with robot_session(zenoh_service) as session, zenoh_service.http() as http:
        assert http.put("/v1/sites/zh/hints", json={"order": ["f1", "f2"]}).status_code == 200
        prior = {"pose": MOVED, "sigma_xy": 0.5, "sigma_yaw_deg": 5}
        body = _reply(session, keys.fragment("zh", "f1"), ply_bytes(300), {"prior": prior})
        assert body["fragment_id"] == "f1" and body["created"] is True, body
        # The same bytes with a new prior: still a duplicate, but the prior is replaced.
        again = {"robot_id": "r1", "prior": {"pose": IDENTITY}}
        body = _reply(session, keys.fragment("zh", "f1"), ply_bytes(300), again)
        assert body["created"] is False, body
        _reply(session, keys.fragment("zh", "f2"), ply_bytes(300, seed=2), {"prior": prior})
        hints = _hints(http, "zh")
        assert hints is not None and hints["order"] == ["f1", "f2"]  # the rest is kept
        assert FragmentPrior.model_validate(hints["fragments"]["f1"]) == FragmentPrior(
            pose=IDENTITY
        )
        assert FragmentPrior.model_validate(hints["fragments"]["f2"]) == FragmentPrior(**prior)
        assert http.get("/v1/sites/zh").json()["hints"] is True


@pytest.mark.parametrize(
    "prior",
    [
        {"pose": [[2.0] * 4] * 4},  # not a rigid motion
        {"pose": IDENTITY, "sigma_xy": -1},
        {"pose": IDENTITY, "colour": "red"},  # unknown field
        "north-east",
    ],
)
def test_bad_prior_is_refused_and_nothing_is_stored(
    zenoh_service: ZenohService, prior: Any
) -> None:
    keys = zenoh_service.keys
    with robot_session(zenoh_service) as session, zenoh_service.http() as http:
        body = _reply(session, keys.fragment("zbadprior", "f1"), ply_bytes(300), {"prior": prior})
        assert set(body) == {"error"} and body["error"]["code"] == "invalid_prior", body
        assert http.get("/v1/sites/zbadprior").status_code == 404


def test_put_prior_is_merged_into_the_hints(zenoh_service: ZenohService) -> None:
    keys = zenoh_service.keys
    with robot_session(zenoh_service) as session, zenoh_service.http() as http:
        attachment = json.dumps({"prior": {"pose": MOVED}})
        session.put(keys.fragment("zputprior", "p1"), ply_bytes(300), attachment=attachment)
        hints = wait_until(lambda: _hints(http, "zputprior"), 15)
        assert hints["fragments"]["p1"]["pose"] == MOVED


def test_send_with_prior(
    zenoh_service: ZenohService, procs: Callable[[list[str]], Proc], tmp_path: Path
) -> None:
    scan, other = tmp_path / "s1.ply", tmp_path / "s2.ply"
    scan.write_bytes(ply_bytes(300, seed=5))
    other.write_bytes(ply_bytes(300, seed=6))
    (tmp_path / "prior.json").write_text(json.dumps({"pose": MOVED, "sigma_xy": 2.0}))
    (tmp_path / "bad.json").write_text(json.dumps({"pose": MOVED, "sigma": 2.0}))
    command = zenoh_service.robot_command("send", "--site", "zsend", str(scan))
    sent = procs([*command, "--prior", str(tmp_path / "prior.json")])
    assert sent.finish() == 0, sent.describe()
    assert json.loads(sent.out[0])["fragment_id"] == "s1"
    with zenoh_service.http() as http:
        hints = _hints(http, "zsend")
        assert hints is not None and hints["fragments"]["s1"]["sigma_xy"] == 2.0
    bad = procs([*command, "--prior", str(tmp_path / "bad.json")])
    assert bad.finish() == 2 and bad.out == []
    assert bad.err == [f"{tmp_path / 'bad.json'}: sigma: Extra inputs are not permitted"]
    two = procs([*command, str(other), "--prior", str(tmp_path / "prior.json")])
    assert two.finish() == 2 and any("one file" in line for line in two.err), two.describe()


def test_pose_updates_carry_status_and_confidence(zenoh_service: ZenohService) -> None:
    """A worker's result message on Redis comes out as pose updates over zenoh."""
    result = ResultModel.model_validate(
        {
            "status": "ambiguous",
            "confidence": 0.58,
            "fragments": [
                {"id": "a", "placed": True, "pose": MOVED, "loop_index": 0, "confidence": 0.97},
                {"id": "b", "placed": False},
            ],
            "alternatives": [{"probability": 0.4}],
        }
    )
    envelope = {"version": 1, "site_id": "zconf", "generation": 1, "result": result.model_dump()}
    updates: list[PoseUpdate] = []
    client = redis.Redis.from_url(str(zenoh_service.settings.redis_url))
    with (
        robot_session(zenoh_service) as session,
        session.declare_subscriber(
            zenoh_service.keys.site_poses("zconf"),
            lambda s: updates.append(PoseUpdate.model_validate_json(s.payload.to_bytes())),
        ),
    ):

        def received() -> bool:
            if not updates:  # again, until the new subscriber is matched
                client.publish(f"{zenoh_service.settings.key_prefix}:results", json.dumps(envelope))
            return bool(updates)

        wait_until(received, 15, interval=0.5)
    client.close()
    update = updates[0]
    assert (update.fragment_id, update.status, update.pose) == ("a", "ambiguous", MOVED)
    assert update.confidence == pytest.approx(0.58)
    assert update.fragment_confidence == pytest.approx(0.97)
