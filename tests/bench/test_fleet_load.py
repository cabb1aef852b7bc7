"""Smoke test of the fleet load benchmark: a tiny fleet over HTTP and zenoh on real
processes (Redis, two API processes, a worker), nothing lost, the table printed."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.fleet_load import main

pytestmark = pytest.mark.timeout(180)


def test_a_tiny_fleet_loses_nothing(tmp_path: Path) -> None:
    lines: list[str] = []
    argv = ["--robots", "4", "--sites", "2", "--fragments", "3", "--points", "3000"]
    argv += ["--scenes", "1", "--configs", "2x1", "--json", str(tmp_path / "rows.json")]
    (row,) = main(argv, out=lines.append)
    assert row["uploads"] == 6 and row["refused"] == 0 and row["lost"] == 0
    assert row["same_results"] == 2 and sum(row["statuses"].values()) == 2
    assert row["http_p50_ms"] > 0 and row["zenoh_p50_ms"] > 0 and row["peak_rss_mb"] > 0
    assert "| 2 x 1 | 6 |" in lines[-1]
    assert (tmp_path / "rows.json").exists()
