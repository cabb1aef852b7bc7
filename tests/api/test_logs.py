"""``jigsaw serve`` with FPJ_LOG_JSON=1: the API, its access lines and its workers log one JSON
object a line, and each job says what it did (a layout done, a placement's status and
confidence)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import httpx
import pytest

from services.point_io import encode_ply
from tests.conftest import small_scene
from tests.service_fixtures import ROOT, free_port, wait_result, wait_until

pytestmark = pytest.mark.timeout(120)


def _serve(redis_url: str, port: int, log: Path) -> subprocess.Popen[bytes]:
    env = {
        "PATH": "/usr/bin:/bin",
        "PYTHONPATH": str(ROOT),
        "FPJ_REDIS_URL": redis_url,
        "FPJ_LOCAL_WORKERS": "1",
        "FPJ_LOG_JSON": "1",
        "FPJ_LOG_LEVEL": "info",
        "FPJ_ZENOH_LISTEN": "none",
        "FPJ_MIN_POINTS": "100",
    }
    command = [sys.executable, "-m", "cli.main", "serve", "--host", "127.0.0.1"]
    with log.open("wb") as out:
        return subprocess.Popen(
            [*command, "--port", str(port)], env=env, cwd=ROOT, stdout=out, stderr=out
        )


def _healthy(url: str) -> bool:
    try:
        return httpx.get(f"{url}/healthz", timeout=1).status_code == 200
    except httpx.HTTPError:
        return False


def test_every_line_is_json_and_jobs_say_what_they_did(redis_url: str, tmp_path: Path) -> None:
    port, log = free_port(), tmp_path / "serve.log"
    process = _serve(redis_url, port, log)
    url = f"http://127.0.0.1:{port}"
    try:
        wait_until(lambda: _healthy(url) or process.poll() is not None, 30)
        assert process.poll() is None, log.read_text()
        scene = small_scene("easy", 0)
        with httpx.Client(base_url=url, timeout=30) as http:
            for fragment in scene.fragments:
                body = encode_ply(fragment.points)
                http.put(f"/v1/sites/logs/fragments/{fragment.id}", content=body)
            result = wait_result(http, "logs", timeout=60)
        wait_until(lambda: "placement done" in log.read_text(), 10)
    finally:
        process.send_signal(signal.SIGTERM)
        process.wait(30)
    lines = [line for line in log.read_text().splitlines() if line.strip()]
    entries: list[dict[str, Any]] = []
    for line in lines:
        entry = json.loads(line)  # every line, whoever wrote it
        assert {"time", "level", "logger", "pid", "message"} <= set(entry), entry
        entries.append(entry)
    puts = [e for e in entries if e["logger"] == "uvicorn.access" and e.get("method") == "PUT"]
    assert len(puts) == len(scene.fragments) and {e["status"] for e in puts} == {202}
    layouts = [e for e in entries if e["message"] == "layout done"]
    assert sorted(e["fragment"] for e in layouts) == sorted(f.id for f in scene.fragments)
    assert all(e["site"] == "logs" and e["seconds"] >= 0 and e["points"] > 0 for e in layouts)
    placed = [e for e in entries if e["message"] == "placement done"]
    assert placed and placed[-1]["status"] == result["status"]
    assert placed[-1]["confidence"] == pytest.approx(result["confidence"], abs=1e-4)
    assert placed[-1]["placed"] == len(scene.fragments)
    assert len({e["pid"] for e in entries}) >= 2  # the API and its worker
