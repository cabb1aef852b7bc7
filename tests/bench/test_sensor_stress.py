"""The other-sensors benchmark and the fit of an evidence kind's map of the logit."""

from __future__ import annotations

import numpy as np
import pytest

from bench.scoring import fit_logit_map
from bench.sensor_stress import BUCKETS, main, run

pytestmark = pytest.mark.timeout(300)


def test_each_bucket_gets_its_scenes_with_status_confidence_and_verdict() -> None:
    records = run("vsparse", 1, 7000)
    assert [r["bucket"] for r in records] == [f"{lo}-{hi}" for lo, hi in BUCKETS]
    for record in records:
        assert record["status"] in ("closed", "ambiguous", "open", "failed")
        assert (record["confidence"] is None) == (record["status"] == "open")
        assert isinstance(record["right"], bool)


def test_an_overconfident_kind_gets_a_map_that_lowers_its_high_confidences() -> None:
    # Results said 0.99 that are right 70 % of the time, and 0.5 right half the time.
    rng = np.random.default_rng(0)
    confidences = [0.99] * 200 + [0.5] * 200
    right = list(rng.random(200) < 0.7) + list(rng.random(200) < 0.5)
    (bias, slope), summary = fit_logit_map(confidences, right, 0.95)
    mapped = 1.0 / (1.0 + np.exp(-(bias + slope * np.log(0.99 / 0.01))))
    assert 0.6 < mapped < 0.8
    assert "400 closed loops" in summary and "after 0 (0 right)" in summary


def test_the_table_has_a_row_per_variant_and_bucket(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--per-bucket", "1", "--variants", "vsparse"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| vsparse")]
    assert len(rows) == len(BUCKETS)
