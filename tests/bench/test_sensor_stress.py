"""The other-scanners benchmark: per bucket, each scene's status and its main room."""

from __future__ import annotations

import pytest

from bench.sensor_stress import BUCKETS, main, run

pytestmark = pytest.mark.timeout(300)


def test_each_bucket_gets_its_scenes_with_status_confidence_and_verdict() -> None:
    records = run("vsparse", 1, 7000)
    assert [r["bucket"] for r in records] == [f"{lo}-{hi}" for lo, hi in BUCKETS]
    for record in records:
        assert record["status"] in ("closed", "ambiguous", "open", "failed")
        assert isinstance(record["right"], bool)
        if record["status"] in ("closed", "ambiguous"):  # a main room, judged as reported
            confidence, right = record["main"]
            assert 0.0 <= confidence <= 1.0 and right == record["right"]


def test_the_table_has_a_row_per_variant_and_bucket(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--per-bucket", "1", "--variants", "vsparse"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| vsparse")]
    assert len(rows) == len(BUCKETS)
