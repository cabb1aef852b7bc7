"""Benchmark (not a test): fragment ingest over zenoh (query) vs HTTP (PUT), same service.

Starts `jigsaw serve` (embedded Redis, no workers: only ingest is measured) listening for HTTP
and zenoh on loopback, then uploads fragments of several sizes one after another, each under
a new id, from one HTTP client (keep-alive) and from one zenoh session, alternating the two
so both see the same machine state. For each size and transport: latency to acknowledgement
(the reply: HTTP 202 / zenoh reply with the same JSON) median and p90, and MB/s (payload
bytes / median latency). ``new``: a new id each time, so both paths run the same validation
(parse), hashing, compression and Redis transaction; ``duplicate``: the same bytes under the
same id again, answered after hashing and one Redis read, which leaves mostly the transport.

    .venv/bin/python bench/zenoh_vs_http.py --sizes 10000 100000 1000000 --repeat 10
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import zenoh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from api.processes import free_tcp_port  # noqa: E402
from services.point_io import encode_ply  # noqa: E402
from transport.config import ZenohOptions, build_config  # noqa: E402
from transport.keys import ZenohKeys  # noqa: E402


@contextmanager
def service(zenoh_port: int, http_port: int) -> Iterator[None]:
    """`jigsaw serve` with an embedded Redis and no workers, stopped with SIGTERM."""
    data = Path(tempfile.mkdtemp(prefix="fpj-bench-zenoh-"))
    env = {k: v for k, v in os.environ.items() if not k.startswith("FPJ_")}
    env.update(
        FPJ_DATA_DIR=str(data),
        FPJ_LOCAL_WORKERS="0",
        FPJ_LOG_LEVEL="warning",
        FPJ_ZENOH_LISTEN=f"tcp/127.0.0.1:{zenoh_port}",
        PYTHONPATH=str(ROOT),
    )
    command = [sys.executable, "-m", "cli.main", "serve", "--port", str(http_port)]
    process = subprocess.Popen(command, env=env, cwd=ROOT)
    try:
        deadline = time.monotonic() + 30
        while True:
            try:
                if httpx.get(f"http://127.0.0.1:{http_port}/healthz", timeout=1).is_success:
                    break
            except httpx.TransportError:
                if time.monotonic() > deadline or process.poll() is not None:
                    raise SystemExit("the service did not start") from None
                time.sleep(0.1)
        yield
    finally:
        process.send_signal(signal.SIGTERM)
        process.wait(30)


def fragment(points: int, seed: int) -> bytes:
    """A binary float32 PLY of ``points`` random points (16 bytes of header aside, 12 B/pt)."""
    cloud = np.random.default_rng(seed).uniform(-5.0, 5.0, size=(points, 3))
    return encode_ply(cloud)


def timed(send: Callable[[str], None], ids: list[str]) -> list[float]:
    """Seconds each ``send`` of an id took."""
    latencies = []
    for fid in ids:
        start = time.perf_counter()
        send(fid)
        latencies.append(time.perf_counter() - start)
    return latencies


def _row(name: str, kind: str, data: bytes, size: int, values: list[float]) -> dict[str, Any]:
    median = statistics.median(values)
    return {
        "transport": name,
        "upload": kind,
        "points": size,
        "bytes": len(data),
        "median_ms": 1000 * median,
        "p90_ms": 1000 * float(np.quantile(values, 0.9)),
        "mb_per_s": len(data) / median / 1e6,
    }


def run(sizes: list[int], repeat: int) -> list[dict[str, Any]]:
    """Upload latency over zenoh and HTTP per cloud size: one table row each."""
    zenoh_port, http_port = free_tcp_port(), free_tcp_port()
    keys = ZenohKeys()
    rows = []
    options = ZenohOptions(connect=[f"tcp/127.0.0.1:{zenoh_port}"])
    with (
        service(zenoh_port, http_port),
        httpx.Client(base_url=f"http://127.0.0.1:{http_port}", timeout=120) as http,
        zenoh.open(build_config(options)) as session,
    ):

        def over_http(size: int, data: bytes) -> Callable[[str], None]:
            def send(fid: str) -> None:
                reply = http.put(f"/v1/sites/h{size}/fragments/{fid}", content=data)
                assert reply.status_code in (200, 202), reply.text

            return send

        def over_zenoh(size: int, data: bytes) -> Callable[[str], None]:
            def send(fid: str) -> None:
                replies = list(
                    session.get(keys.fragment(f"z{size}", fid), payload=data, timeout=120)
                )
                assert replies and replies[0].ok is not None, replies

            return send

        wait_zenoh = list(session.get(keys.service, timeout=10))
        assert wait_zenoh, "no zenoh front end"
        for size in sizes:
            data = fragment(size, seed=size)
            senders = {"http": over_http(size, data), "zenoh": over_zenoh(size, data)}
            for send in senders.values():
                timed(send, [f"warm{i}" for i in range(2)])
            for kind in ("new", "duplicate"):
                latencies: dict[str, list[float]] = {name: [] for name in senders}
                for i in range(repeat):  # alternate, so both see the same conditions
                    for name, send in senders.items():
                        latencies[name] += timed(send, [f"f{i}" if kind == "new" else "f0"])
                rows += [_row(name, kind, data, size, v) for name, v in latencies.items()]
    return rows


def main() -> None:
    """Run the benchmark (command-line options: see ``--help``) and print its table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    parser.add_argument("--repeat", type=int, default=10)
    parser.add_argument("--json", type=Path, help="also write the rows as JSON")
    args = parser.parse_args()
    rows = run(args.sizes, args.repeat)
    lines = [
        "| upload | transport | points | MB | median ms | p90 ms | MB/s |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['upload']} | {r['transport']} | {r['points']} | {r['bytes'] / 1e6:.2f} | "
            f"{r['median_ms']:.1f} | {r['p90_ms']:.1f} | {r['mb_per_s']:.1f} |"
        )
    sys.stdout.write("\n".join(lines) + "\n")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
