"""The outside frame rooms' chains judged against their room's outline."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bench.outside import frames
from bench.outside.frame_chains import WRONG, FrameChain, chain_strays, chain_table, main
from bench.outside.run import frame_jobs

pytestmark = pytest.mark.timeout(180)

_SQUARE = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])


def test_a_chain_on_the_outline_strays_nowhere_and_one_past_a_corner_strays_beyond():
    assert chain_strays(np.array([[1.0, 0.0], [4.0, 0.0], [4.0, 3.0]]), _SQUARE) == (0.0, 0.0)
    beyond, within = chain_strays(np.array([[1.0, 0.0], [4.0, 0.0], [4.0, 5.0]]), _SQUARE)
    assert (beyond, within) == pytest.approx((1.0, 0.0))
    # A front taken for the wall, 0.5 m into the room.
    beyond, within = chain_strays(np.array([[1.0, 0.5], [3.0, 0.5]]), _SQUARE)
    assert (beyond, within) == pytest.approx((0.0, 0.5))


def test_the_table_counts_wrong_chains_and_the_wrong_rooms_they_are_in():
    rows = [
        FrameChain("a", "wide", "f0", 1.2, 0.0, False),
        FrameChain("a", "wide", "f1", 0.0, 0.05, False),
        FrameChain("b", "wide", "f0", 0.0, 0.6, True),
        FrameChain("c", "kinect", "f0", 0.1, 0.1, False),
    ]
    assert [r.wrong for r in rows] == [True, False, True, False]
    table = chain_table(rows).splitlines()
    assert table[2] == "| kinect | 1 | 0 | 0 | 0 | 0 of 1 | 0 of 1 |"
    assert table[3] == "| wide | 3 | 2 | 1 | 1 | 2 of 2 | 1 of 1 |"
    assert table[4] == "| all | 4 | 2 | 1 | 1 | 2 of 3 | 1 of 2 |"
    assert WRONG == 0.3


def test_a_draws_folder_is_judged_frame_by_frame(tmp_path: Path, capsys) -> None:
    # One wide room of the draw made beforehand and scored right; main makes the two others.
    job = next(j for j in frame_jobs(1) if j.camera == "wide")
    folder = tmp_path / job.name
    frames.make_scene(folder, job.seed, job.camera, job.kind)
    (folder / "score.json").write_text(json.dumps({"main": {"acc": True}}))
    assert main(["--out", str(tmp_path), "--per-camera", "1", "--workers", "1", "--list"]) == 0
    out = capsys.readouterr().out
    assert len(list(tmp_path.glob("*/truth.json"))) == 3
    rows = [line for line in out.splitlines() if line.startswith("| ")]
    assert rows[0].startswith("| camera |") and rows[-1].startswith("| all |")
    total = json.loads((folder / "truth.json").read_text())["n_frames"]
    assert f"| wide | {total} |" in out
