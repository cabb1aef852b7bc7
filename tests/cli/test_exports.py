"""File exports (cli.exports) and scene files (cli.scene_io), in-process. The 3D layout model
they write: tests/services/test_model_export.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d
import pytest

from api.colors import fragment_rgb
from cli.exports import (
    ExportTargets,
    aligned_cloud_ply,
    floorplan_canvas,
    layout_canvas,
    write_exports,
)
from cli.scene_io import TRUTH_FILE, read_truth, write_scene
from schemas.params import ParserLimits
from schemas.result import FragmentResultModel, ResultModel
from services.parsing import parse_fragment
from services.synthetic import SyntheticScene
from services.types import LocalLayout, ManhattanFrame
from tests.result_fixtures import small_result, yaw_pose

pytestmark = pytest.mark.timeout(60)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _clouds() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    return {k: rng.uniform([0, 0, 0], [3, 2, 2.5], (500 + 100 * i, 3)) for i, k in enumerate("abc")}


def test_aligned_cloud_transforms_and_colours(tmp_path: Path) -> None:
    clouds = _clouds()
    data = aligned_cloud_ply(clouds, small_result())
    points = parse_fragment(data, ParserLimits(min_points=1)).points
    expected = np.vstack(
        [clouds["a"], clouds["b"] @ yaw_pose(90.0, (0, 0, 0))[:3, :3].T + [1, 2, 0.5]]
    )
    np.testing.assert_allclose(points, expected, atol=1e-5)  # c is unplaced: left out
    path = tmp_path / "cloud.ply"
    path.write_bytes(data)
    colours = np.asarray(o3d.io.read_point_cloud(path).colors)
    # one colour per fragment id, as in the service's pictures and the web view
    np.testing.assert_allclose(colours[0] * 255, fragment_rgb("a"), atol=0.5)
    np.testing.assert_allclose(colours[-1] * 255, fragment_rgb("b"), atol=0.5)


def test_pictures_png_and_svg() -> None:
    canvas = floorplan_canvas(_clouds(), small_result())
    assert canvas.png().startswith(PNG_SIGNATURE)
    svg = canvas.svg()
    assert svg.startswith("<svg") and ">a</text>" in svg and ">b</text>" in svg
    assert " m</text>" in svg  # scale bar label
    frame = ManhattanFrame(rotation=np.eye(3), floor_z=0.0, ceiling_z=2.5)
    layout = LocalLayout(keypoints=np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0]]), frame=frame)
    local = layout_canvas(_clouds()["a"], layout)
    assert local.png().startswith(PNG_SIGNATURE)
    assert "source" in local.svg() and "target" in local.svg()
    empty = LocalLayout(keypoints=np.zeros((0, 2)), frame=frame)
    assert "no wall" in layout_canvas(_clouds()["a"], empty).svg()


def test_write_exports_and_targets(tmp_path: Path) -> None:
    targets = ExportTargets(tmp_path / "c.ply", tmp_path / "m.gltf", tmp_path / "p.svg")
    assert targets.problems() == []
    assert write_exports(targets, _clouds(), small_result()) == []
    assert all(p.exists() for p in (targets.cloud, targets.model, targets.picture) if p)
    failed = ResultModel(status="failed", fragments=[FragmentResultModel(id="a", placed=False)])
    nothing = ExportTargets(tmp_path / "x.ply", tmp_path / "x.gltf", tmp_path / "x.png")
    notes = write_exports(nothing, {}, failed)
    assert len(notes) == 2 and not (tmp_path / "x.ply").exists()
    assert (tmp_path / "x.png").read_bytes().startswith(PNG_SIGNATURE)  # an empty plan
    bad = ExportTargets(tmp_path / "c.xyz", tmp_path / "m.obj", tmp_path / "p.jpg")
    assert len(bad.problems()) == 3


def test_write_scene_round_trip(small_scene: SyntheticScene, tmp_path: Path) -> None:
    write_scene(small_scene, tmp_path)
    assert sorted(p.stem for p in tmp_path.glob("*.ply")) == [f.id for f in small_scene.fragments]
    for fragment in small_scene.fragments:
        parsed = parse_fragment((tmp_path / f"{fragment.id}.ply").read_bytes())
        np.testing.assert_allclose(parsed.points, fragment.points, atol=1e-4, rtol=1e-6)
    truth = read_truth(tmp_path)
    assert (tmp_path / TRUTH_FILE).exists()
    assert [f["id"] for f in truth["fragments"]] == [f.id for f in small_scene.fragments]
    assert truth["seed"] == small_scene.seed
