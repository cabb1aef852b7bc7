"""Prometheus metrics: upload counters of this process, job and queue numbers from Redis.

The job numbers are written by every worker into one Redis hash (:mod:`store.stats`) and
read at scrape time, so one scrape of any API replica covers all workers.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from prometheus_client import REGISTRY, CollectorRegistry, Counter, generate_latest
from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    Metric,
)
from prometheus_client.registry import Collector

from api.site_data import live_workers, queue_counts
from store.backend import Backend
from store.connection import record
from store.stats import Histogram, JobStats, parse_stats

__all__ = ["ROS_DEPTH_IMAGES", "UPLOADS", "UPLOAD_BYTES", "render_metrics"]

UPLOADS = Counter(
    "fpj_uploads", "Fragment uploads by outcome (accepted, duplicate or error code)", ["outcome"]
)
UPLOAD_BYTES = Counter("fpj_upload_bytes", "Bytes of accepted fragment uploads")
ROS_DEPTH_IMAGES = Counter(
    "fpj_ros_depth_images",
    "ROS 2 depth images by outcome (accepted, duplicate, unpaired or error code)",
    ["outcome"],
)


@dataclass(frozen=True)
class _Snapshot:
    stats: JobStats
    jobs: dict[str, int]
    workers: int
    sites: int


def _histogram(name: str, doc: str, per_kind: dict[str, Histogram]) -> HistogramMetricFamily:
    family = HistogramMetricFamily(name, doc, labels=["kind"])
    for kind, hist in per_kind.items():
        buckets = [("+Inf" if b == float("inf") else repr(b), c) for b, c in hist.buckets]
        family.add_metric([kind], buckets, hist.total)
    return family


class _RedisCollector(Collector):
    def __init__(self, snap: _Snapshot) -> None:
        self.snap = snap

    def collect(self) -> Iterable[Metric]:
        snap = self.snap
        jobs = CounterMetricFamily(
            "fpj_jobs", "Finished job runs by kind and outcome", labels=["kind", "outcome"]
        )
        for (kind, outcome), count in sorted(snap.stats.counts.items()):
            jobs.add_metric([kind, outcome], count)
        yield jobs
        by_state = GaugeMetricFamily("fpj_jobs_in_state", "Jobs now by state", labels=["state"])
        for state, count in snap.jobs.items():
            by_state.add_metric([state], count)
        yield by_state
        yield GaugeMetricFamily(
            "fpj_queue_depth", "Jobs waiting for a worker", value=snap.jobs["queued"]
        )
        yield GaugeMetricFamily(
            "fpj_workers_alive", "Workers with a recent heartbeat", snap.workers
        )
        yield GaugeMetricFamily(
            "fpj_sites", "Sites with at least one accepted fragment", snap.sites
        )
        yield _histogram("fpj_job_duration_seconds", "Job run time", snap.stats.durations)
        yield _histogram(
            "fpj_job_queue_latency_seconds", "Enqueue to start of a job", snap.stats.latencies
        )


async def render_metrics(backend: Backend) -> bytes:
    """The Prometheus text exposition: process metrics, then the Redis-wide job metrics."""
    raw = record(await backend.redis.hgetall(backend.keys.stats))
    snap = _Snapshot(
        stats=parse_stats(raw),
        jobs=await queue_counts(backend),
        workers=await live_workers(backend),
        sites=int(await backend.redis.zcard(backend.keys.sites)),
    )
    registry = CollectorRegistry(auto_describe=False)
    registry.register(_RedisCollector(snap))
    return generate_latest(REGISTRY) + generate_latest(registry)
