"""Job counters and duration histograms, kept in one Redis hash shared by all workers.

Workers add to ``P:stats`` as they finish jobs; the API's ``/metrics`` reads it back, so the
numbers cover every worker process however many there are.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import redis

from store.keys import Keys

__all__ = ["BUCKETS", "Histogram", "JobStats", "parse_stats", "record_job"]

BUCKETS: tuple[float, ...] = (0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 300.0)
KINDS = ("layout", "placement")


def _bucket(seconds: float) -> str:
    for bound in BUCKETS:
        if seconds <= bound:
            return repr(bound)
    return "inf"


def _observe(pipe: redis.client.Pipeline, stats: str, name: str, seconds: float) -> None:
    pipe.hincrby(stats, f"{name}:le:{_bucket(seconds)}", 1)
    pipe.hincrbyfloat(stats, f"{name}:sum", max(0.0, seconds))


def record_job(
    pipe: redis.client.Pipeline,
    keys: Keys,
    kind: str,
    outcome: str,
    *,
    duration: float | None = None,
    latency: float | None = None,
) -> None:
    """Queue the updates for one finished (or given-up) job on ``pipe``."""
    pipe.hincrby(keys.stats, f"jobs:{kind}:{outcome}", 1)
    if duration is not None:
        _observe(pipe, keys.stats, f"duration:{kind}", duration)
    if latency is not None:
        _observe(pipe, keys.stats, f"latency:{kind}", latency)


@dataclass
class Histogram:
    """Cumulative bucket counts (upper bound -> count, ending with +inf) and the sum."""

    buckets: list[tuple[float, int]] = field(default_factory=list)
    total: float = 0.0


@dataclass
class JobStats:
    """The counters and histograms of the stats hash.

    counts: (kind, outcome) -> jobs; durations: kind -> run time; latencies: kind -> time
    from enqueue to the first try's start.
    """

    counts: dict[tuple[str, str], int] = field(default_factory=dict)
    durations: dict[str, Histogram] = field(default_factory=dict)
    latencies: dict[str, Histogram] = field(default_factory=dict)


def _histogram(raw: Mapping[str, str], name: str) -> Histogram:
    running = 0
    buckets = []
    for bound in (*BUCKETS, math.inf):
        label = "inf" if math.isinf(bound) else repr(bound)
        running += int(raw.get(f"{name}:le:{label}", 0))
        buckets.append((bound, running))
    return Histogram(buckets, float(raw.get(f"{name}:sum", 0.0)))


def parse_stats(raw: Mapping[str, str]) -> JobStats:
    """Read the stats hash back into counters and cumulative histograms."""
    stats = JobStats()
    for name, value in raw.items():
        parts = name.split(":")
        if parts[0] == "jobs" and len(parts) == 3:
            stats.counts[(parts[1], parts[2])] = int(value)
    for kind in KINDS:
        stats.durations[kind] = _histogram(raw, f"duration:{kind}")
        stats.latencies[kind] = _histogram(raw, f"latency:{kind}")
    return stats
