"""``jigsaw demo --service``: the real service end to end on a generated scene.

Starts ``jigsaw serve`` (embedded Redis and local workers, data in a temporary folder),
uploads the scene's fragments over HTTP from several concurrent "robots", waits for the
site's placement, prints each fragment's pose error against ground truth, saves the
floorplan picture, and stops the service with SIGTERM.
"""

from __future__ import annotations

import concurrent.futures
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
from rich.console import Console
from rich.table import Table

from api.processes import free_tcp_port
from services.evaluation import evaluate_result
from services.point_io import encode_ply
from services.synthetic import SceneSpec, generate_scene, ground_truth_json

__all__ = ["run_service_demo"]

_SITE = "demo-site"
_ROBOTS = 3


def _start_service(port: int, data_dir: Path) -> subprocess.Popen[bytes]:
    env = {
        **os.environ,
        "FPJ_DATA_DIR": str(data_dir),
        "FPJ_ZENOH_LISTEN": "none",
        "FPJ_LOG_LEVEL": "WARNING",
    }
    env.pop("FPJ_REDIS_URL", None)
    command = [
        sys.executable,
        "-m",
        "cli.main",
        "serve",
        "--host",
        "127.0.0.1",
        "--port",
        str(port),
    ]
    return subprocess.Popen(command, env=env, cwd=Path(__file__).resolve().parents[1])


def _wait_healthy(http: httpx.Client, process: subprocess.Popen[bytes], timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"jigsaw serve exited with code {process.returncode}")
        try:
            if http.get("/healthz").status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.2)
    raise RuntimeError("jigsaw serve did not become healthy in time")


def _upload(base_url: str, fragments: dict[str, bytes]) -> dict[str, int]:
    """PUT every fragment, ``_ROBOTS`` at a time, as independent robots would."""

    def put(item: tuple[str, bytes]) -> tuple[str, int]:
        fid, body = item
        with httpx.Client(base_url=base_url, timeout=120) as client:
            return fid, client.put(f"/v1/sites/{_SITE}/fragments/{fid}", content=body).status_code

    with concurrent.futures.ThreadPoolExecutor(_ROBOTS) as pool:
        return dict(pool.map(put, fragments.items()))


def _wait_result(http: httpx.Client, count: int, timeout: float) -> dict[str, Any]:
    """The site's result once every fragment is processed and a placement has run on all."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        response = http.get(f"/v1/sites/{_SITE}/result")
        if response.status_code == 200:
            result: dict[str, Any] = response.json()
            if len(result.get("fragments", [])) == count:
                return result
        time.sleep(0.3)
    raise RuntimeError("no result for the whole site in time")


def _report(result: dict[str, Any], truth: dict[str, Any], console: Console) -> None:
    report = evaluate_result(result, truth)
    table = Table(title=f"site {_SITE}: status {result['status']}")
    for column in ("fragment", "placed", "loop", "rotation err (deg)", "translation err (%)"):
        table.add_column(column)
    for fragment in result["fragments"]:
        error = report.pose_errors.get(fragment["id"])
        table.add_row(
            fragment["id"],
            str(fragment["placed"]),
            str(fragment.get("loop_index")),
            f"{error.rotation_deg:.2f}" if error else "-",
            f"{error.translation_pct:.2f}" if error else "-",
        )
    console.print(table)
    layout = report.layout_error_pct
    console.print(
        f"ACC_global: {'correct' if report.global_correct else 'wrong'}; "
        + (f"layout error {layout[0]:.2f}% mean / {layout[1]:.2f}% max; " if layout else "")
        + (f"room IoU {report.iou:.3f}" if report.iou is not None else "")
    )


def run_service_demo(out: Path, seed: int) -> int:
    """Run the service demo; returns the process exit code."""
    console = Console()
    scene = generate_scene(SceneSpec.paper(), seed)
    fragments = {f.id: encode_ply(f.points) for f in scene.fragments}
    out.mkdir(parents=True, exist_ok=True)
    port = free_tcp_port()
    base_url = f"http://127.0.0.1:{port}"
    with tempfile.TemporaryDirectory(prefix="fpj-demo-") as data_dir:
        process = _start_service(port, Path(data_dir))
        try:
            with httpx.Client(base_url=base_url, timeout=30) as http:
                _wait_healthy(http, process, timeout=60)
                console.print(f"service up on {base_url}; uploading {len(fragments)} fragments")
                started = time.monotonic()
                codes = _upload(base_url, fragments)
                uploaded = time.monotonic()
                statuses = sorted(set(codes.values()))
                console.print(f"uploads: HTTP {statuses} in {uploaded - started:.2f} s")
                result = _wait_result(http, len(fragments), timeout=300)
                console.print(f"result {time.monotonic() - uploaded:.2f} s after the last upload")
                picture = http.get(f"/v1/sites/{_SITE}/floorplan.svg")
                (out / "service_floorplan.svg").write_bytes(picture.content)
        except (RuntimeError, httpx.HTTPError) as exc:
            console.print(f"[red]service demo failed: {exc}[/red]")
            return 1
        finally:
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
    _report(result, ground_truth_json(scene), console)
    console.print(f"floorplan picture: {out / 'service_floorplan.svg'}")
    return 0
