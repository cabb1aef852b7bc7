"""Fleet load benchmark (not a test): many robots over HTTP and zenoh across many sites.

For each configuration (API processes x workers, e.g. ``1x2`` and ``2x4``) it starts a
private Redis, the API processes (each with its own HTTP port and zenoh endpoint) and the
workers (:class:`bench.service_load.Service`), then R robots (half over HTTP, half over
zenoh queries, spread over the API processes) upload the F fragments of S sites at once:
the uploads are dealt out to the robots round-robin, each robot sends its share one after
another. It reports

- uploads per second (acknowledged uploads / time from the first to the last reply);
- upload latency to acknowledgement, p50 and p99, over all uploads and per transport;
- time to result: from a site's last acknowledged upload to its settled result, p50 and max;
- peak memory: the largest sum of resident memory (VmRSS) of the service's processes (Redis,
  APIs, workers) sampled every 0.2 s, and Redis' own used_memory_peak;
- fragments lost: acknowledged uploads missing from their site's result or not processed
  (must be 0), and uploads refused;
- same results: each site's result (status, fragment ids, placed set, poses relative to
  the first placed fragment's within 1 cm) is compared with the first configuration's.

    .venv/bin/python bench/fleet_load.py --robots 50 --sites 20 --configs 1x2 2x4

Everything runs on this machine, robots included; on a small shared machine the robots'
threads and zenoh sessions compete with the service for the same cores.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import threading
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import redis
import zenoh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.service_load import Service, make_fragments, running, settled  # noqa: E402
from transport.config import ZenohOptions, build_config  # noqa: E402
from transport.keys import ZenohKeys  # noqa: E402

Upload = tuple[str, str, bytes]  # site id, fragment id, bytes


@dataclasses.dataclass(frozen=True)
class Sent:
    """One upload as a robot saw it."""

    site: str
    fragment: str
    transport: str
    start: float
    end: float
    ok: bool
    answer: str


def make_sites(
    sites: int, fragments: int, points: int, scenes: int, seed: int
) -> dict[str, dict[str, bytes]]:
    """``{site id: {fragment id: PLY bytes}}``: ``scenes`` distinct scenes dealt to the sites."""
    bases = [make_fragments(fragments, points, seed + 100 * k)[1] for k in range(scenes)]
    return {f"site-{n:02d}": bases[n % scenes] for n in range(sites)}


class MemorySampler(threading.Thread):
    """Peak of the summed resident memory of some processes, sampled every 0.2 s."""

    def __init__(self, pids: list[int]) -> None:
        super().__init__(daemon=True)
        self.pids, self.peak_bytes = pids, 0
        self.stop = threading.Event()

    def run(self) -> None:
        """Sample until stopped."""
        while not self.stop.wait(0.2):
            self.peak_bytes = max(self.peak_bytes, sum(map(_rss, self.pids)))


def _rss(pid: int) -> int:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


class Robots:
    """The robots' uploads, and when each site got its last reply."""

    def __init__(self, service: Service, sites: dict[str, dict[str, bytes]]) -> None:
        self.service, self.sites = service, sites
        self.sent: list[Sent] = []
        self.site_done: dict[str, float] = {}  # site -> its last reply (perf_counter)
        self._left = {site: len(fragments) for site, fragments in sites.items()}
        self._lock = threading.Lock()

    def record(self, sent: Sent) -> None:
        """Note one reply; a site whose every upload got its reply is done."""
        with self._lock:
            self.sent.append(sent)
            self._left[sent.site] -= 1
            if self._left[sent.site] == 0:
                self.site_done[sent.site] = sent.end

    def http_robot(self, index: int, uploads: list[Upload], ready: threading.Barrier) -> None:
        """Upload ``uploads`` over HTTP, one after another, to one of the API processes."""
        url = self.service.urls[index % len(self.service.urls)]
        with httpx.Client(base_url=url, timeout=600) as http:
            ready.wait()
            for site, fid, data in uploads:
                start = time.perf_counter()
                try:
                    reply = http.put(f"/v1/sites/{site}/fragments/{fid}", content=data)
                    ok, answer = reply.status_code in (200, 202), reply.text
                except httpx.HTTPError as exc:  # counted as refused, never lost track of
                    ok, answer = False, repr(exc)
                self.record(Sent(site, fid, "http", start, time.perf_counter(), ok, answer))

    def zenoh_robot(self, index: int, uploads: list[Upload], ready: threading.Barrier) -> None:
        """Upload ``uploads`` as zenoh queries (client mode) to one of the API processes."""
        endpoints = self.service.zenoh_endpoints
        options = ZenohOptions(mode="client", connect=[endpoints[index % len(endpoints)]])
        keys, tag = ZenohKeys(), json.dumps({"robot_id": f"robot{index}"}).encode()
        with zenoh.open(build_config(options)) as session:
            _wait_for_service(session, keys)
            ready.wait()
            for site, fid, data in uploads:
                start = time.perf_counter()
                try:
                    key = keys.fragment(site, fid)
                    replies = list(session.get(key, payload=data, attachment=tag, timeout=600))
                    ok, answer = bool(replies) and replies[0].ok is not None, _zenoh_text(replies)
                except zenoh.ZError as exc:
                    ok, answer = False, repr(exc)
                self.record(Sent(site, fid, "zenoh", start, time.perf_counter(), ok, answer))


def _wait_for_service(session: zenoh.Session, keys: ZenohKeys) -> None:
    deadline = time.monotonic() + 30
    while not list(session.get(keys.service, timeout=2)):
        if time.monotonic() > deadline:
            raise SystemExit("no zenoh front end answered")


def _zenoh_text(replies: list[Any]) -> str:
    if not replies:
        return "no reply"
    sample = replies[0].ok if replies[0].ok is not None else replies[0].err
    return str(sample.payload.to_string())


def deal(sites: dict[str, dict[str, bytes]], robots: int) -> list[list[Upload]]:
    """Every upload, interleaved across sites, dealt to the robots round-robin."""
    ordered = [
        (site, fid, fragments[fid])
        for k in range(max(map(len, sites.values())))
        for site, fragments in sites.items()
        for fid in sorted(fragments)[k : k + 1]
    ]
    return [ordered[r::robots] for r in range(robots)]


def watch_results(
    url: str, robots: Robots, stop: threading.Event, settled_at: dict[str, float]
) -> None:
    """Note when each site whose uploads are all answered has a settled result (until every
    site has one, at most an hour after ``stop``)."""
    deadline = float("inf")
    with httpx.Client(base_url=url, timeout=60) as http:
        while len(settled_at) < len(robots.sites) and time.monotonic() < deadline:
            for site in list(robots.site_done):
                if site not in settled_at and settled(http, site):
                    settled_at[site] = time.perf_counter()
            if stop.is_set() and deadline == float("inf"):
                deadline = time.monotonic() + 3600
            time.sleep(0.25)


def _relative_poses(result: dict[str, Any]) -> dict[str, np.ndarray]:
    """Placed fragments' poses relative to the first placed id's: the site frame follows
    the first fragment placed, which depends on upload order, so absolute poses may differ
    by one rigid motion while the assembly is the same."""
    poses = {f["id"]: np.array(f["pose"], float) for f in result["fragments"] if f["placed"]}
    if not poses:
        return {}
    reference = np.linalg.inv(poses[min(poses)])
    return {fid: reference @ pose for fid, pose in poses.items()}


def result_difference(a: dict[str, Any], b: dict[str, Any], tolerance: float = 0.01) -> str:
    """How two results of one site differ ("" when they agree): status, fragments, placed
    set, or a relative pose (rotation entries or translation) off by more than ``tolerance``
    (meters; about half a degree for rotation entries)."""
    if a["status"] != b["status"]:
        return f"status {a['status']} vs {b['status']}"
    ids = sorted(f["id"] for f in a["fragments"]), sorted(f["id"] for f in b["fragments"])
    if ids[0] != ids[1]:
        return "fragment ids"
    poses_a, poses_b = _relative_poses(a), _relative_poses(b)
    if sorted(poses_a) != sorted(poses_b):
        return "placed fragments"
    worst = max((float(np.abs(poses_a[f] - poses_b[f]).max()) for f in poses_a), default=0.0)
    return f"poses differ by {worst:.3f}" if worst > tolerance else ""


def lost_fragments(url: str, sent: list[Sent]) -> tuple[int, dict[str, Any]]:
    """Acknowledged uploads missing from their site's result or not processed; results."""
    results: dict[str, Any] = {}
    lost = 0
    with httpx.Client(base_url=url, timeout=60) as http:
        for site in sorted({s.site for s in sent}):
            results[site] = http.get(f"/v1/sites/{site}/result").json()
            status = http.get(f"/v1/sites/{site}").json()
            done = {f["fragment_id"] for f in status["fragments"] if f["state"] == "done"}
            in_result = {f["id"] for f in results[site].get("fragments", [])}
            acked = {s.fragment for s in sent if s.site == site and s.ok}
            lost += len(acked - (done & in_result))
    return lost, results


def _quantiles(values: list[float]) -> tuple[float, float]:
    if not values:
        return float("nan"), float("nan")
    return float(np.quantile(values, 0.5)), float(np.quantile(values, 0.99))


def run_fleet(
    service: Service, sites: dict[str, dict[str, bytes]], robots: int
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Run the fleet once against ``service``; returns the row and the sites' results."""
    fleet = Robots(service, sites)
    shares = deal(sites, robots)
    ready = threading.Barrier(robots + 1)
    threads = [
        threading.Thread(
            target=fleet.zenoh_robot if r % 2 else fleet.http_robot,
            args=(r // 2, shares[r], ready),  # each transport's robots spread over APIs
            daemon=True,
        )
        for r in range(robots)
    ]
    sampler = MemorySampler([p.pid for p in service.processes])
    settled_at: dict[str, float] = {}
    stop = threading.Event()
    watcher = threading.Thread(
        target=watch_results, args=(service.url, fleet, stop, settled_at), daemon=True
    )
    for thread in threads:
        thread.start()
    sampler.start()
    ready.wait()  # every robot connected: go
    start = time.perf_counter()
    watcher.start()
    for thread in threads:
        thread.join()
    uploads_end = max(s.end for s in fleet.sent)
    stop.set()
    watcher.join()
    sampler.stop.set()
    sampler.join()
    lost, results = lost_fragments(service.url, fleet.sent)
    return _row(service, fleet, start, uploads_end, settled_at, sampler, lost), results


def _row(
    service: Service,
    fleet: Robots,
    start: float,
    uploads_end: float,
    settled_at: dict[str, float],
    sampler: MemorySampler,
    lost: int,
) -> dict[str, Any]:
    ok = [s for s in fleet.sent if s.ok]
    latency = {"all": [s.end - s.start for s in ok]}
    for s in ok:
        latency.setdefault(s.transport, []).append(s.end - s.start)
    to_result = [settled_at[site] - fleet.site_done[site] for site in settled_at]
    info = redis.Redis.from_url(service.redis_url).info("memory")
    row: dict[str, Any] = {
        "apis": len(service.urls),
        "workers": service.workers,
        "uploads": len(fleet.sent),
        "refused": len(fleet.sent) - len(ok),
        "uploads_per_s": len(ok) / (uploads_end - start),
        "all_settled_s": max(settled_at.values()) - start,
        "to_result_p50_s": float(np.median(to_result)),
        "to_result_max_s": max(to_result),
        "peak_rss_mb": sampler.peak_bytes / 1e6,
        "redis_peak_mb": int(info["used_memory_peak"]) / 1e6,
        "lost": lost,
    }
    for name, values in latency.items():
        row[f"{name}_p50_ms"], row[f"{name}_p99_ms"] = (1000 * q for q in _quantiles(values))
    refusals: dict[str, int] = defaultdict(int)
    for s in fleet.sent:
        if not s.ok:
            refusals[s.answer[:120]] += 1
    row["refusals"] = dict(refusals)
    return row


def fleet_runs(
    sites: dict[str, dict[str, bytes]], robots: int, configs: list[tuple[int, int]]
) -> list[dict[str, Any]]:
    """One fleet run per ``(apis, workers)``; each row says how many sites' results match
    the first configuration's (:func:`result_difference`), and how the others differ."""
    rows: list[dict[str, Any]] = []
    first: dict[str, Any] = {}
    for apis, workers in configs:
        with running(workers, 1, apis=apis, zenoh=True) as service:
            row, results = run_fleet(service, sites, robots)
        first = first or results
        differences = {site: result_difference(first[site], r) for site, r in results.items()}
        row["same_results"] = sum(not d for d in differences.values())
        row["differences"] = {site: d for site, d in differences.items() if d}
        statuses = [r["status"] for r in results.values()]
        row["statuses"] = {status: statuses.count(status) for status in sorted(set(statuses))}
        rows.append(row)
        print(json.dumps(row, default=lambda v: round(v, 3)), flush=True)
    return rows


def table(rows: list[dict[str, Any]], sites: int) -> str:
    """The rows as a Markdown table."""
    lines = [
        "| APIs x workers | uploads | uploads/s | p50 / p99 ms (all) | p50 / p99 ms (HTTP) | "
        "p50 / p99 ms (zenoh) | to result p50 / max s | all settled s | peak RSS MB | "
        "Redis peak MB | lost | refused | same results |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        cells: list[str] = [f"{r['apis']} x {r['workers']}", str(r["uploads"])]
        cells.append(f"{r['uploads_per_s']:.1f}")
        for name in ("all", "http", "zenoh"):
            cells.append(f"{r.get(f'{name}_p50_ms', 0):.0f} / {r.get(f'{name}_p99_ms', 0):.0f}")
        cells.append(f"{r['to_result_p50_s']:.1f} / {r['to_result_max_s']:.1f}")
        cells.append(f"{r['all_settled_s']:.1f}")
        cells += [f"{r['peak_rss_mb']:.0f}", f"{r['redis_peak_mb']:.0f}"]
        cells += [str(r["lost"]), str(r["refused"]), f"{r['same_results']}/{sites}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _config(text: str) -> tuple[int, int]:
    apis, _, workers = text.partition("x")
    return int(apis), int(workers)


def main(argv: list[str] | None = None, out: Callable[[str], Any] = print) -> list[dict[str, Any]]:
    """Run the benchmark from the command line; returns the rows."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", type=int, default=50, help="half HTTP, half zenoh")
    parser.add_argument("--sites", type=int, default=20)
    parser.add_argument("--fragments", type=int, default=5, help="per site")
    parser.add_argument("--points", type=int, default=20_000, help="per fragment")
    parser.add_argument("--scenes", type=int, default=4, help="distinct scenes dealt to sites")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--configs", type=_config, nargs="+", default=[(1, 2), (2, 4)])
    parser.add_argument("--json", type=Path, help="also write the rows here")
    args = parser.parse_args(argv)
    sites = make_sites(args.sites, args.fragments, args.points, args.scenes, args.seed)
    size = sum(len(d) for fragments in sites.values() for d in fragments.values())
    out(
        f"{args.sites} sites x {args.fragments} fragments x {args.points} points "
        f"({size / 1e6:.1f} MB of PLY), {args.robots} robots, {os.cpu_count()} CPUs"
    )
    rows = fleet_runs(sites, args.robots, args.configs)
    out(table(rows, args.sites))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))
    return rows


if __name__ == "__main__":
    main()
