"""The CLI on RGB-D frames: frame folders, frame zips, a TUM-style sequence, bad frames."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from cli.frames import dataset_frames, is_dataset
from schemas.params import PipelineParams
from services.rgbd import RgbdFrame
from tests.frame_fixtures import ROOM_SEED, frame_files, frame_zip, three_frames

pytestmark = pytest.mark.timeout(120)


def _write_folder(folder: Path, files: dict[str, bytes]) -> None:
    folder.mkdir(parents=True)
    for name, data in files.items():
        (folder / name).write_bytes(data)


def _align(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "cli.main", "align", *args],
        capture_output=True,
        text=True,
        timeout=110,
        check=False,
    )


def test_align_reads_frame_folders_and_zips_and_reports_bad_ones(tmp_path: Path) -> None:
    scene = three_frames(ROOM_SEED)
    first, second, third = scene.frames
    _write_folder(tmp_path / "in" / first.id, frame_files(first.frame))
    (tmp_path / "in" / f"{second.id}.zip").write_bytes(frame_zip(second.frame))
    _write_folder(tmp_path / "in" / third.id, frame_files(third.frame, "jpg"))
    bad = frame_files(first.frame)
    bad.pop("intrinsics.json")
    _write_folder(tmp_path / "in" / "broken", bad)
    out = tmp_path / "result.json"
    run = _align(str(tmp_path / "in"), "-o", str(out))
    assert run.returncode == 0, run.stderr
    assert f"{tmp_path / 'in' / 'broken'}: the frame has no intrinsics.json" in run.stderr
    result = json.loads(out.read_text())
    assert sorted(f["id"] for f in result["fragments"]) == sorted(f.id for f in scene.frames)
    assert result["status"] in ("closed", "ambiguous")  # see tests/frame_fixtures.py
    assert len(result["floorplan"]["rooms"]) == 1


def test_only_bad_frames_exit_2(tmp_path: Path) -> None:
    (tmp_path / "f.zip").write_bytes(b"PK\x03\x04 not really")
    run = _align(str(tmp_path / "f.zip"))
    assert run.returncode == 2
    assert f"{tmp_path / 'f.zip'}: not a readable zip archive" in run.stderr


def test_a_tum_sequence_gives_one_fragment_per_chosen_frame(tmp_path: Path) -> None:
    frame = three_frames(0).frames[0].frame
    root = tmp_path / "rgbd_dataset_test"
    (root / "depth").mkdir(parents=True)
    (root / "rgb").mkdir()
    tum = frame.intrinsics.model_copy(update={"depth_scale": 5000.0})
    files = frame_files(RgbdFrame(frame.depth, tum, frame.color))
    lines_d, lines_c = [], []
    for k in range(5):
        stamp = 1305031102.0 + k
        (root / "depth" / f"{stamp:.6f}.png").write_bytes(files["depth.png"])
        (root / "rgb" / f"{stamp + 0.01:.6f}.png").write_bytes(files["color.png"])
        lines_d.append(f"{stamp:.6f} depth/{stamp:.6f}.png")
        lines_c.append(f"{stamp + 0.01:.6f} rgb/{stamp + 0.01:.6f}.png")
    (root / "depth.txt").write_text("# depth\n" + "\n".join(lines_d) + "\n")
    (root / "rgb.txt").write_text("\n".join(lines_c) + "\n")
    (root / "intrinsics.json").write_text(tum.model_dump_json())
    assert is_dataset(root)
    found = dict(dataset_frames(root, PipelineParams(), max_frames=3))
    assert len(found) == 3
    decoded = next(iter(found.values()))
    assert isinstance(decoded, RgbdFrame) and decoded.color is not None
    assert float(decoded.depth.max()) == pytest.approx(float(frame.depth.max()), abs=1e-3)
