"""Load benchmark of the service (not a test): simulated robots uploading over HTTP.

For each worker count it starts a private Redis, `jigsaw serve` (no local workers) and N
`jigsaw worker` processes, then measures

- latency: R robots upload the F fragments of one site at the same moment; the time from the
  end of the last upload to the site's settled result (closed or not) is the headline number
  (target: under 3 s for 8 fragments of 100k points on 2 cores);
- throughput: S sites of F fragments uploaded by R concurrent robots: uploads/s, MB/s, and the
  time until every site is settled;
- queue latency and job run times, from the service's own /metrics.

The fleet benchmark (robots over HTTP and zenoh across many sites, several API processes)
is ``bench/fleet_load.py``, on the same :class:`Service`.

    .venv/bin/python bench/service_load.py --workers 1 2 --fragments 8 --points 100000

Everything runs on this machine; the numbers include HTTP, Redis and the real pipeline.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import dataclasses
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path
from typing import Any

import httpx
import redis

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from api.processes import free_tcp_port  # noqa: E402
from services.point_io import encode_ply  # noqa: E402
from services.synthetic import SceneSpec, generate_scene  # noqa: E402


def make_fragments(count: int, points: int, seed: int) -> tuple[int, dict[str, bytes]]:
    """PLY bytes of a synthetic site with exactly ``count`` fragments of ``points`` points."""
    spec = dataclasses.replace(
        SceneSpec.easy(),
        n_fragments_range=(count, count),
        points_per_fragment=(points, points),
        n_corners_range=(max(4, count), max(4, count) + 4),
        size_range=((6.0, 8.0), (12.0, 16.0)),
    )
    for candidate in range(seed, seed + 50):
        scene = generate_scene(spec, candidate)
        if len(scene.fragments) == count:
            return candidate, {f.id: encode_ply(f.points) for f in scene.fragments}
    raise SystemExit(f"no scene with {count} fragments near seed {seed}")


class Service:
    """Private Redis + ``apis`` x `jigsaw serve` + N `jigsaw worker`, as real processes.

    Every API process has its own HTTP port and, with ``zenoh``, its own zenoh listen
    endpoint on loopback (none otherwise). The upload rate limit is off: every simulated
    robot comes from 127.0.0.1, which a per-address limit would count as one client.
    """

    def __init__(self, workers: int, concurrency: int, apis: int = 1, zenoh: bool = False) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix="fpj-bench-"))
        self.redis_port = free_tcp_port()
        self.http_ports = [free_tcp_port() for _ in range(apis)]
        self.zenoh_ports = [free_tcp_port() for _ in range(apis)] if zenoh else []
        self.redis_url = f"redis://127.0.0.1:{self.redis_port}/0"
        self.urls = [f"http://127.0.0.1:{port}" for port in self.http_ports]
        self.url = self.urls[0]
        self.workers, self.concurrency = workers, concurrency
        self.processes: list[subprocess.Popen[bytes]] = []
        self.roles: list[str] = []  # "redis", "api" or "worker", one per process

    @property
    def zenoh_endpoints(self) -> list[str]:
        """The API processes' zenoh listen endpoints (empty without zenoh)."""
        return [f"tcp/127.0.0.1:{port}" for port in self.zenoh_ports]

    def _env(self, zenoh_listen: str = "none") -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if not k.startswith("FPJ_")}
        env.update(
            FPJ_REDIS_URL=self.redis_url,
            FPJ_LOCAL_WORKERS="0",
            FPJ_LOG_LEVEL="warning",
            FPJ_WORKER_CONCURRENCY=str(self.concurrency),
            FPJ_PLACEMENT_TIMEOUT_S="900",
            FPJ_UPLOAD_RATE_LIMIT="0",
            FPJ_ZENOH_LISTEN=zenoh_listen,
            PYTHONPATH=str(ROOT),
        )
        return env

    def _spawn(self, role: str, command: list[str], env: dict[str, str] | None = None) -> None:
        stdout = subprocess.DEVNULL if role == "redis" else None
        self.processes.append(subprocess.Popen(command, env=env, cwd=ROOT, stdout=stdout))
        self.roles.append(role)

    def start(self) -> None:
        """Start Redis, the APIs and the workers; return once all workers are ready."""
        self._spawn(
            "redis",
            [
                *("redis-server", "--port", str(self.redis_port), "--bind", "127.0.0.1"),
                *("--dir", str(self.dir), "--save", "", "--appendonly", "no"),
            ],
        )
        client = redis.Redis.from_url(self.redis_url)
        self._wait(lambda: _ping(client), "redis")
        cli = [sys.executable, "-m", "cli.main"]
        for k, port in enumerate(self.http_ports):
            listen = self.zenoh_endpoints[k] if self.zenoh_ports else "none"
            self._spawn("api", [*cli, "serve", "--port", str(port)], self._env(listen))
        for _ in range(self.workers):
            self._spawn("worker", [*cli, "worker"], self._env())
        self._wait(lambda: all(self._ready(url) for url in self.urls), "service")

    def _ready(self, url: str) -> bool:
        try:
            reply = httpx.get(f"{url}/readyz", timeout=1)
        except httpx.TransportError:
            return False
        return reply.status_code == 200 and reply.json()["workers"] == self.workers

    @staticmethod
    def _wait(check: Any, what: str, timeout: float = 60) -> None:
        deadline = time.monotonic() + timeout
        while not check():
            if time.monotonic() > deadline:
                raise SystemExit(f"{what} did not start")
            time.sleep(0.1)

    def stop(self) -> None:
        """Stop every process, newest first (killed after 30 s)."""
        for process in reversed(self.processes):
            process.terminate()
            try:
                process.wait(30)
            except subprocess.TimeoutExpired:
                process.kill()


def _ping(client: redis.Redis) -> bool:
    try:
        return bool(client.ping())
    except redis.exceptions.ConnectionError:
        return False


@contextmanager
def running(
    workers: int, concurrency: int, apis: int = 1, zenoh: bool = False
) -> Iterator[Service]:
    """A running service with ``workers`` workers and ``apis`` API processes, stopped after
    the block."""
    service = Service(workers, concurrency, apis, zenoh)
    try:
        service.start()
        yield service
    finally:
        service.stop()


def upload_all(url: str, uploads: list[tuple[str, str, bytes]], robots: int) -> list[float]:
    """Upload concurrently from ``robots`` threads (one client each); returns end times."""
    local = threading.local()
    barrier = threading.Barrier(min(robots, len(uploads)))

    def put(item: tuple[str, str, bytes]) -> float:
        if not hasattr(local, "client"):
            local.client = httpx.Client(base_url=url, timeout=300)
            barrier.wait()
        site, fid, data = item
        reply = local.client.put(f"/v1/sites/{site}/fragments/{fid}", content=data)
        if reply.status_code not in (200, 202):
            raise SystemExit(f"upload failed: {reply.status_code} {reply.text}")
        return time.perf_counter()

    with concurrent.futures.ThreadPoolExecutor(robots) as pool:
        return list(pool.map(put, uploads))


def settled(http: httpx.Client, site: str) -> dict[str, Any] | None:
    """The site's status once every layout ran and the newest placement covers them."""
    status: dict[str, Any] = http.get(f"/v1/sites/{site}").json()
    busy = any(f["state"] in ("queued", "running") for f in status["fragments"])
    placement = status["placement"]
    done = placement["state"] in ("done", "failed")
    if busy or not done or placement["result_generation"] != placement["generation"]:
        return None
    return status


def wait_settled(url: str, sites: list[str], timeout: float) -> tuple[float, dict[str, str]]:
    """Wait until every site's placement settled: (the time, result status per site)."""
    statuses: dict[str, str] = {}
    with httpx.Client(base_url=url, timeout=30) as http:
        deadline = time.monotonic() + timeout
        while len(statuses) < len(sites):
            for site in sites:
                if site not in statuses and (status := settled(http, site)):
                    statuses[site] = status["placement"]["result_status"]
            if time.monotonic() > deadline:
                raise SystemExit(f"sites not settled within {timeout}s: {statuses}")
            time.sleep(0.01)
    return time.perf_counter(), statuses


_METRIC = re.compile(r'^(fpj_job_[a-z_]+_seconds)_(sum|count)\{kind="(\w+)"\} ([0-9.e+]+)$')


def job_metrics(url: str) -> dict[str, float]:
    """Mean job run time and queue latency per kind, from /metrics."""
    values: dict[tuple[str, str, str], float] = {}
    for line in httpx.get(f"{url}/metrics", timeout=10).text.splitlines():
        if match := _METRIC.match(line):
            values[(match[1], match[3], match[2])] = float(match[4])
    means: dict[str, float] = {}
    for (name, kind, part), value in values.items():
        if part == "count" and name == "fpj_job_duration_seconds":
            means[f"{kind}_runs"] = value
        if part == "sum" and values.get((name, kind, "count")):
            short = name.removeprefix("fpj_job_").removesuffix("_seconds")
            means[f"{kind}_{short}_mean_s"] = value / values[(name, kind, "count")]
    return means


def _breakdown(url: str, site: str, last_upload: float, seen: float) -> dict[str, float]:
    """Where the time from the last upload to the result went (server clock = this clock)."""
    status = httpx.get(f"{url}/v1/sites/{site}", timeout=10).json()
    layouts_done = max(_epoch(f["updated_at"]) for f in status["fragments"])
    placement = status["placement"]
    started, placed = _epoch(placement["started_at"]), _epoch(placement["last_placement_at"])
    return {
        "layouts_s": layouts_done - last_upload,
        "wait_for_placement_s": started - layouts_done,
        "placement_s": placed - started,
        "result_to_client_s": seen - placed,
    }


def _epoch(stamp: str) -> float:
    """Unix seconds of the site status's ISO 8601 times."""
    return datetime.fromisoformat(stamp).timestamp()


def run_latency(service: Service, fragments: dict[str, bytes], robots: int) -> dict[str, Any]:
    """One site's fragments uploaded at once: time to the result and where it went."""
    site = "latency"
    uploads = [(site, fid, data) for fid, data in fragments.items()]
    start = time.perf_counter()
    ends = upload_all(service.url, uploads, robots)
    closed_at, statuses = wait_settled(service.url, [site], timeout=1800)
    # perf_counter -> wall clock, to compare with the server's timestamps.
    offset = time.time() - time.perf_counter()
    return {
        "uploads_s": max(ends) - start,
        "last_upload_to_result_s": closed_at - max(ends),
        "status": statuses[site],
        **_breakdown(service.url, site, max(ends) + offset, closed_at + offset),
    }


def run_throughput(
    service: Service, fragments: dict[str, bytes], sites: int, robots: int
) -> dict[str, Any]:
    """The fragments uploaded to ``sites`` sites at once: uploads per second, time to settle."""
    names = [f"load-{n}" for n in range(sites)]
    uploads = [(site, fid, data) for fid, data in fragments.items() for site in names]
    size = sum(len(data) for _, _, data in uploads)
    start = time.perf_counter()
    ends = upload_all(service.url, uploads, robots)
    upload_time = max(ends) - start
    done_at, statuses = wait_settled(service.url, names, timeout=3600)
    return {
        "uploads": len(uploads),
        "uploads_per_s": len(uploads) / upload_time,
        "upload_mb_per_s": size / upload_time / 1e6,
        "all_settled_after_s": done_at - start,
        "last_upload_to_all_settled_s": done_at - max(ends),
        "closed": sum(1 for s in statuses.values() if s == "closed"),
    }


def main() -> int:
    """Run the benchmark (command-line options: see ``--help``) and print its tables."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--concurrency", type=int, default=1, help="jobs per worker")
    parser.add_argument("--fragments", type=int, default=8)
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--robots", type=int, default=8, help="concurrent uploaders")
    parser.add_argument("--sites", type=int, default=2, help="sites in the throughput run")
    parser.add_argument("--json", type=Path, help="also write the results here")
    args = parser.parse_args()

    seed, fragments = make_fragments(args.fragments, args.points, args.seed)
    megabytes = sum(map(len, fragments.values())) / 1e6
    print(
        f"site: {len(fragments)} fragments x {args.points} points (seed {seed}), "
        f"{megabytes:.1f} MB of PLY; {os.cpu_count()} CPUs",
        flush=True,
    )
    rows = []
    for workers in args.workers:
        with running(workers, args.concurrency) as service:
            latency = run_latency(service, fragments, args.robots)
            throughput = run_throughput(service, fragments, args.sites, args.robots)
            row = {"workers": workers, **latency, **throughput, **job_metrics(service.url)}
        rows.append(row)
        print(json.dumps(row, indent=None, default=lambda v: round(v, 3)), flush=True)

    print(
        "\nworkers | last upload->result (layouts + wait + placement + notify) | status | "
        "uploads/s | MB/s | all sites settled | layout run | layout queue"
    )
    for r in rows:
        print(
            f"{r['workers']:>7} | {r['last_upload_to_result_s']:6.2f}s "
            f"({r['layouts_s']:.2f} + {r['wait_for_placement_s']:.2f} + "
            f"{r['placement_s']:.2f} + {r['result_to_client_s']:.2f}) | {r['status']} | "
            f"{r['uploads_per_s']:.1f} | {r['upload_mb_per_s']:.0f} | "
            f"{r['all_settled_after_s']:.1f}s | {r.get('layout_duration_mean_s', 0):.2f}s | "
            f"{r.get('layout_queue_latency_mean_s', 0):.2f}s"
        )
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
