"""Job statistics: the stats hash read back as counters and cumulative histograms."""

from __future__ import annotations

import pytest

from store.stats import BUCKETS, parse_stats

pytestmark = pytest.mark.timeout(10)


def test_stats_histograms_are_cumulative() -> None:
    raw = {
        "jobs:layout:done": "3",
        f"duration:layout:le:{BUCKETS[0]!r}": "1",
        "duration:layout:le:1.0": "2",
        "duration:layout:le:inf": "1",
        "duration:layout:sum": "12.5",
    }
    stats = parse_stats(raw)
    assert stats.counts[("layout", "done")] == 3
    buckets = dict(stats.durations["layout"].buckets)
    assert buckets[BUCKETS[0]] == 1 and buckets[1.0] == 3 and buckets[float("inf")] == 4
    assert stats.durations["layout"].total == 12.5
