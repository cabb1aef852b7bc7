"""The outside benchmark's runner: a scene aligned in process is scored as the CLI's run is,
parameters can be tried that way, and bad options stop before any scene is made."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.outside.run import frame_jobs, main, run_job

pytestmark = pytest.mark.timeout(300)

_SCORED = ("status", "confidence", "top3", "placed")


def test_a_frame_scene_aligned_in_process_scores_as_the_clis_run_and_settings_apply(
    tmp_path: Path,
) -> None:
    job = next(j for j in frame_jobs(1) if j.camera == "wide")
    inside = run_job(job, tmp_path, settings=())
    assert inside["exit_code"] == 0 and (tmp_path / job.name / "result.json").exists()
    assert run_job(job, tmp_path, settings=("placement.frame_calibration=[9, 1]",)) == inside
    cli = run_job(job, tmp_path, rerun=True)  # the same scene, aligned by `jigsaw align`
    assert cli["exit_code"] == 0
    assert {k: cli[k] for k in _SCORED} == {k: inside[k] for k in _SCORED}
    assert cli["main"]["acc"] == inside["main"]["acc"]
    surer = run_job(job, tmp_path, settings=("placement.frame_calibration=[9, 1]",), rerun=True)
    assert surer["confidence"] > inside["confidence"]


@pytest.mark.parametrize(
    "options",
    [["--set", "placement.station_occam=1"], ["--in-process", "--set", "placement.nope=1"]],
)
def test_settings_need_the_in_process_run_and_must_name_a_parameter(
    tmp_path: Path, options: list[str]
) -> None:
    with pytest.raises(SystemExit) as stop:
        main(["frames", "--per-camera", "1", "--out", str(tmp_path), *options])
    assert stop.value.code == 2
    assert not any(tmp_path.iterdir())  # no scene made
