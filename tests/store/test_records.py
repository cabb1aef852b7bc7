"""Settings, key names, hash records and statistics (no Redis needed)."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from schemas.access import Scope
from schemas.jobs import LayoutJob, PlacementJob, decode_job, encode_job
from schemas.settings import Settings
from store.keys import Keys
from store.records import fragment_status, new_fragment_record, placement_status
from store.stats import BUCKETS, parse_stats

pytestmark = pytest.mark.timeout(10)


def test_settings_from_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FPJ_TOKENS", "a, b,,c")
    monkeypatch.setenv("FPJ_MAX_UPLOAD_BYTES", "1000")
    monkeypatch.setenv("FPJ_MIN_POINTS", "7")
    settings = Settings()
    assert list(settings.tokens) == ["a", "b", "c"]
    assert all(scope == Scope() for scope in settings.tokens.values())  # every right, every site
    assert settings.max_upload_bytes == 1000
    assert settings.parser_limits().min_points == 7
    assert settings.pipeline_params().parser.min_points == 7
    monkeypatch.setenv("FPJ_TOKENS", '["x"]')
    assert list(Settings().tokens) == ["x"]
    monkeypatch.setenv("FPJ_TOKENS", "bot:lab+hall:upload, view:*:read,admin")
    assert Settings().tokens == {
        "bot": Scope(sites=("lab", "hall"), rights=("upload",)),
        "view": Scope(rights=("read",)),
        "admin": Scope(),
    }
    monkeypatch.setenv("FPJ_TOKENS", '{"a:b,c": {"sites": ["lab"], "rights": ["read"]}}')
    assert Settings().tokens == {"a:b,c": Scope(sites=("lab",), rights=("read",))}
    for bad in ("bot:lab:write", "bot:../x", ":lab", '{"t": {"site": ["lab"]}}'):
        monkeypatch.setenv("FPJ_TOKENS", bad)
        with pytest.raises(ValidationError):
            Settings()


def test_local_workers_default_to_embedded_mode_only() -> None:
    assert Settings(redis_url=None).embedded
    assert Settings(redis_url=None).local_worker_count() >= 1
    assert Settings(redis_url="redis://r:6379/0").local_worker_count() == 0
    assert Settings(redis_url="redis://r:6379/0", local_workers=3).local_worker_count() == 3


def test_jobs_round_trip_and_reject_unknown_versions() -> None:
    layout = LayoutJob(site_id="s", fragment_id="f", sha256="x")
    assert decode_job(encode_job(layout)) == layout
    placement = PlacementJob(site_id="s")
    assert decode_job(encode_job(placement)) == placement
    with pytest.raises(ValueError):
        decode_job('{"version": 2, "kind": "layout", "site_id": "s"}')
    with pytest.raises(ValueError):
        decode_job('{"version": 1, "kind": "pickle", "site_id": "s"}')


def test_keys_are_namespaced() -> None:
    keys = Keys("pfx")
    names = [
        keys.jobs,
        keys.dead,
        keys.workers,
        keys.sites,
        keys.site("s"),
        keys.fragment("s", "f"),
        keys.fragment_data("s", "f"),
        keys.result("s"),
        keys.placement_flag("s"),
    ]
    assert all(name.startswith("pfx:") for name in names)
    assert len(set(names)) == len(names)


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
