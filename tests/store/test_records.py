"""Hash records and their wire status (no Redis needed)."""

from __future__ import annotations

import pytest

from store.records import fragment_status, new_fragment_record, placement_status

pytestmark = pytest.mark.timeout(10)


def test_records_to_wire() -> None:
    record = new_fragment_record(
        sha256="h", size_bytes=10, fmt="ply", n_points=5, dropped=1, now=2.0
    )
    status = fragment_status("f", record)
    assert (status.state, status.error, status.n_points, status.dropped_nonfinite) == (
        "queued",
        None,
        5,
        1,
    )
    failed = fragment_status(
        "f", {**record, "state": "failed", "error_code": "x", "error_message": "m"}
    )
    assert failed.error is not None and failed.error.code == "x"
    placement = placement_status(
        {"placement_state": "done", "result_status": "closed", "loop_closed": "1"}
    )
    assert placement.loop_closed and placement.result_status == "closed"
    assert placement_status({}).state == "idle"
