"""The outside frame rooms' chains judged against their room's outline."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bench.outside import frames
from bench.outside.frame_chains import (
    BIG_OVERLAP,
    BIG_UNSEEN,
    WRONG,
    FrameChain,
    chain_span,
    chain_strays,
    chain_table,
    junction_overlaps,
    main,
    overlap_table,
    stage_table,
    unseen_stretches,
    unseen_table,
)
from bench.outside.run import frame_jobs

pytestmark = pytest.mark.timeout(180)

_SQUARE = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])


def _frame(room: str, stations: int, span: tuple[float, float] | None, right: bool) -> FrameChain:
    """A right chain (or a strayed one, span None) of a wide room on a 16 m outline."""
    return FrameChain(room, "wide", "f", 0.0, 0.0, right, span, stations, 16.0)


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
    ends = [k for k, row in enumerate(rows) if row.startswith("| all |")]
    assert rows[0].startswith("| camera |") and len(ends) == 2
    # The chain table, then the wrong chains by the step that made them wrong: as many.
    assert rows[ends[0] + 1].startswith("| camera | wrong chains |")
    assert rows[ends[0]].split("|")[3] == rows[ends[1]].split("|")[2]
    assert rows[ends[1] + 1].startswith("| stations |")
    assert sum(row.startswith("| stations | rooms, every chain right |") for row in rows) == 1
    total = json.loads((folder / "truth.json").read_text())["n_frames"]
    assert f"| wide | {total} |" in out


def test_the_stage_table_counts_wrong_chains_by_the_step_that_made_them_wrong():
    rows = [
        FrameChain("a", "wide", "f0", 1.2, 0.0, False, stage="graph"),
        FrameChain("a", "wide", "f1", 0.0, 0.05, False),
        FrameChain("b", "kinect", "f0", 0.0, 0.6, True, stage="frustum edges"),
        FrameChain("c", "kinect", "f0", np.inf, np.inf, False, stage="no chain"),
    ]
    table = stage_table(rows).splitlines()
    assert table[0].startswith("| camera | wrong chains | graph | furniture | frustum edges |")
    assert table[2] == "| kinect | 2 | 0 | 0 | 1 | 0 | 0 | 0 | 1 |"
    assert table[3] == "| wide | 1 | 1 | 0 | 0 | 0 | 0 | 0 | 0 |"
    assert table[4] == "| all | 3 | 1 | 0 | 1 | 0 | 0 | 0 | 1 |"


def test_a_chains_span_runs_along_the_outline_across_its_first_vertex():
    assert chain_span(np.array([[1.0, 0.0], [4.0, 0.0], [4.0, 2.0]]), _SQUARE) == (1.0, 6.0)
    # Drawn against the outline's direction, it covers the same stretch.
    assert chain_span(np.array([[4.0, 2.0], [4.0, 0.0], [1.0, 0.0]]), _SQUARE) == (1.0, 6.0)
    assert chain_span(np.array([[0.0, 1.0], [0.0, 0.0], [2.0, 0.0]]), _SQUARE) == (15.0, 18.0)


def test_junction_overlaps_close_the_loop_and_count_a_span_inside_another_as_overlap():
    assert junction_overlaps([(9.3, 16.4), (0.0, 5.0), (4.5, 9.0)], 16.0) == pytest.approx(
        [0.5, -0.3, 0.4]
    )
    # The second lies inside the first: the first runs 3 m past its start.
    assert junction_overlaps([(0.0, 6.0), (3.0, 5.0), (6.2, 15.5)], 16.0) == pytest.approx(
        [3.0, -1.2, -0.5]
    )


def test_the_overlap_table_sets_rooms_overlapping_at_a_junction_apart_per_station_count():
    rows = [
        # one station, overlaps of 0.1 m: right
        _frame("a", 1, (0.0, 8.1), True), _frame("a", 1, (8.0, 16.1), True),
        # two stations, 2 m of overlap: wrong; a chain strayed (no span) is left out
        _frame("b", 2, (0.0, 10.0), False), _frame("b", 2, (8.0, 16.0), False),
        _frame("b", 2, None, False),
        # two stations, 0.5 m of overlap: right
        _frame("c", 2, (0.0, 8.5), True), _frame("c", 2, (8.0, 16.0), True),
    ]  # fmt: skip
    table = overlap_table(rows).splitlines()
    assert table[2] == "| 1 | 1 | 1 | 0 | 0 of 0 | 1 of 1 | 0.10 |"
    assert table[3] == "| 2 | 2 | 1 | 1 | 0 of 1 | 1 of 1 | 1.25 |"
    assert BIG_OVERLAP == 0.6


def test_unseen_stretches_are_the_outline_no_span_covers_round_the_loop():
    assert unseen_stretches([(9.3, 16.4), (0.0, 5.0), (4.5, 9.0)], 16.0) == pytest.approx([0.3])
    # A span inside another hides nothing; the hole before the last span and the one
    # closing the loop both count, largest first.
    assert unseen_stretches([(0.0, 6.0), (3.0, 5.0), (8.0, 15.0)], 16.0) == pytest.approx(
        [2.0, 1.0]
    )
    assert unseen_stretches([(0.0, 8.5), (8.0, 16.2)], 16.0) == []
    assert unseen_stretches([], 16.0) == [16.0]


def test_the_unseen_table_sets_rooms_with_wall_unseen_between_chains_apart():
    rows = [
        # one station, the whole loop seen: right
        _frame("a", 1, (0.0, 8.1), True), _frame("a", 1, (8.0, 16.1), True),
        # one station, 2 m unseen between the chains: wrong
        _frame("b", 1, (0.0, 8.0), False), _frame("b", 1, (10.0, 16.0), False),
        # a chain strayed (no span): left out, whatever it leaves unseen
        _frame("c", 2, (0.0, 4.0), False), _frame("c", 2, None, False),
    ]  # fmt: skip
    table = unseen_table(rows).splitlines()
    assert len(table) == 3
    assert table[2] == "| 1 | 2 | 1 | 1 | 0 of 1 | 1 of 1 | 1.00 |"
    assert BIG_UNSEEN == 0.6
