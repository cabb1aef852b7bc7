"""``jigsaw align --hints`` and the checks of its options before anything runs, as a real
subprocess: one line and exit code 2 for a bad hints file or output path, and a summary on
stderr after a run."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from schemas.result import ResultModel
from services.synthetic import SyntheticScene
from tests.cli.conftest import RunJigsaw

pytestmark = pytest.mark.timeout(120)

IDENTITY = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
SUMMARY = re.compile(
    r"^3 fragment\(s\) used, 1 skipped, \d placed; "
    r"status (closed|ambiguous|open|failed), confidence [01]\.\d\d, \d+ alternative\(s\)$"
)


def test_align_with_hints_writes_the_result_and_a_summary(
    run_jigsaw: RunJigsaw, scene_dir: Path, small_scene: SyntheticScene, tmp_path: Path
) -> None:
    ids = [f.id for f in small_scene.fragments]
    first = small_scene.fragments[0]
    hints = {
        "fragments": {first.id: {"pose": first.pose.tolist(), "sigma_xy": 1.5}},
        "neighbours": [[ids[0], ids[1]]],
        "order": ids,
    }
    (tmp_path / "hints.json").write_text(json.dumps(hints))
    out = tmp_path / "new" / "out.json"  # missing folders are created
    process = run_jigsaw(
        "align",
        scene_dir,
        tmp_path / "missing.ply",
        "-o",
        out,
        "--hints",
        tmp_path / "hints.json",
    )
    assert process.returncode == 0, process.stderr
    result = ResultModel.model_validate_json(out.read_text())
    assert [f.id for f in result.fragments] == ids
    lines = process.stderr.strip().splitlines()
    assert "missing.ply" in lines[0]  # the skipped path, reported as before
    assert SUMMARY.match(lines[-2]), process.stderr
    assert lines[-1] == f"written: result {out}", process.stderr
    assert process.stdout == ""


@pytest.mark.parametrize(
    ("content", "words"),
    [
        (None, "cannot read"),
        ("{not json", "json"),
        (json.dumps({"order": ["a"], "colour": "red"}), "colour: extra inputs"),
        (json.dumps({"fragments": {"a": {"pose": [[2.0] * 4] * 4}}}), "fragments.a.pose"),
    ],
)
def test_bad_hints_exit_2_before_anything_runs(
    run_jigsaw: RunJigsaw, tmp_path: Path, content: str | None, words: str
) -> None:
    hints = tmp_path / "hints.json"
    if content is not None:
        hints.write_text(content)
    # The fragment path does not exist either: only the hints are reported, as nothing ran.
    process = run_jigsaw("align", tmp_path / "nothing.ply", "--hints", hints)
    assert process.returncode == 2
    assert process.stdout == ""
    (line,) = process.stderr.strip().splitlines()
    assert line.startswith(f"{hints}: ") and words in line.lower(), line


def test_unwritable_outputs_exit_2_before_anything_runs(
    run_jigsaw: RunJigsaw, scene_dir: Path, tmp_path: Path
) -> None:
    (tmp_path / "plain.txt").write_text("a file, not a folder")
    process = run_jigsaw(
        "align",
        scene_dir,
        "-o",
        tmp_path,
        "--picture",
        tmp_path / "plain.txt" / "plan.svg",
    )
    assert process.returncode == 2
    assert process.stderr.strip().splitlines() == [
        f"error: -o {tmp_path}: is a directory",
        f"error: --picture {tmp_path / 'plain.txt' / 'plan.svg'}: "
        f"{tmp_path / 'plain.txt'} is not a directory",
    ]
    assert process.stdout == ""


def test_an_output_the_checks_cannot_foresee_failing_exits_2(
    run_jigsaw: RunJigsaw, scene_dir: Path
) -> None:
    # /proc exists and root may write to it as far as os.access tells, but no file can be
    # made there: the write fails after the run, and that is the output's fault (exit 2).
    out = Path("/proc") / "fpj-no-such-output.json"
    process = run_jigsaw("align", scene_dir, "-o", out)
    assert process.returncode == 2, process.stderr
    assert process.stderr.strip().splitlines()[-1].startswith(f"{out}: cannot write: ")
    layout = run_jigsaw("layout", scene_dir, "-o", out)
    assert layout.returncode == 2, layout.stderr
    assert layout.stderr.strip().splitlines()[-1].startswith(f"{out}: cannot write: ")
