"""The job wire format: versioned JSON, never pickle."""

from __future__ import annotations

import pytest

from schemas.jobs import LayoutJob, PlacementJob, decode_job, encode_job

pytestmark = pytest.mark.timeout(10)


def test_jobs_round_trip_and_reject_unknown_versions() -> None:
    layout = LayoutJob(site_id="s", fragment_id="f", sha256="x")
    assert decode_job(encode_job(layout)) == layout
    placement = PlacementJob(site_id="s")
    assert decode_job(encode_job(placement)) == placement
    with pytest.raises(ValueError):
        decode_job('{"version": 2, "kind": "layout", "site_id": "s"}')
    with pytest.raises(ValueError):
        decode_job('{"version": 1, "kind": "pickle", "site_id": "s"}')
