"""The frames' calibration refitted on outside draws: reading the draws, composing the maps."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from bench.outside.fit_frames import composed, draw_verdicts, main, remapped
from schemas.params import PlacementParams

pytestmark = pytest.mark.timeout(30)


def _draw(folder: Path, rooms: Sequence[tuple[float | None, bool]]) -> Path:
    """A draw's folder: one scene per (confidence, right), as ``bench.outside.run`` scores."""
    for k, (confidence, right) in enumerate(rooms):
        scene = folder / f"wide_{k:03d}"
        scene.mkdir(parents=True)
        score = {"status": "ambiguous", "confidence": confidence, "main": {"acc": right}}
        (scene / "score.json").write_text(json.dumps(score))
    (folder / "unscored").mkdir()  # a scene the draw has not run yet is left out
    return folder


def test_a_draws_rooms_are_read_with_no_result_counted_as_no_confidence(tmp_path: Path) -> None:
    folder = _draw(tmp_path / "d", [(0.8, True), (None, False), (0.3, False)])
    assert draw_verdicts([folder]) == ([0.8, 0.0, 0.3], [True, False, False])


def test_the_composed_map_gives_a_frames_room_the_logit_the_second_map_gives_it() -> None:
    params = PlacementParams(
        frame_calibration=(-0.7, 0.4),
        frame_view_slope=-0.1,
        frame_view_top_slope=-10.0,
        frame_station_slope=-1.3,
    )
    second = (0.5, 1.2)
    new = composed(params, second)
    z, wider, below, stations = 1.7, 0.3, 0.05, 2.0  # a room's logit and its slopes' terms

    def logit(p: PlacementParams) -> float:
        a, b = p.frame_calibration
        terms = p.frame_view_slope * wider + p.frame_view_top_slope * below
        return a + b * z + terms + p.frame_station_slope * stations

    old = logit(params)
    expected = 1.0 / (1.0 + np.exp(-(second[0] + second[1] * old)))
    mapped = logit(params.model_copy(update=new))
    assert 1.0 / (1.0 + np.exp(-mapped)) == pytest.approx(expected, abs=2e-3)
    assert remapped([1.0 / (1.0 + np.exp(-old))], second)[0] == pytest.approx(expected)


def test_the_fit_raises_confidence_where_rooms_were_right_more_often_than_it_said(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rooms = [(0.6, k % 10 != 0) for k in range(40)]  # said 60 %, right 90 %
    fit = _draw(tmp_path / "fit", rooms)
    check = _draw(tmp_path / "check", rooms[:20])
    assert main(["--fit", str(fit), "--check", str(check)]) == 0
    out = capsys.readouterr().out
    assert "--set placement.frame_calibration=[" in out
    before, after = (float(x) for x in out.split("check:")[1].split("Brier ")[1].split()[0:3:2])
    assert after < before
