"""The ``jigsaw`` console script, run as a real subprocess (contract section 2)."""

from __future__ import annotations

import base64
import json
import re
import shutil
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import open3d as o3d
import pytest

from schemas.export import SCHEMA_DIR
from schemas.layout_file import LayoutFileModel
from schemas.result import ResultModel
from services.parsing import parse_fragment
from services.point_io import encode_ply
from services.synthetic import SyntheticScene
from tests.cli.conftest import RunJigsaw

pytestmark = pytest.mark.timeout(180)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def aligned(run_jigsaw: RunJigsaw, scene_dir: Path, tmp_path_factory: pytest.TempPathFactory):
    """One ``jigsaw align`` run with every export option; returns (process, output folder)."""
    out = tmp_path_factory.mktemp("align")
    process = run_jigsaw(
        "align",
        scene_dir,
        "-o",
        out / "out.json",
        "--cloud",
        out / "cloud.ply",
        "--model",
        out / "model.gltf",
        "--picture",
        out / "plan.png",
    )
    return process, out


def _rotation_ok(pose: np.ndarray) -> bool:
    rotation = pose[:3, :3]
    return bool(
        np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-6)
        and np.isclose(np.linalg.det(rotation), 1.0, atol=1e-6)
        and np.allclose(pose[3], [0.0, 0.0, 0.0, 1.0])
    )


def test_align_writes_contract_result(aligned: Any, small_scene: SyntheticScene) -> None:
    process, out = aligned
    assert process.returncode == 0, process.stderr
    result = ResultModel.model_validate_json((out / "out.json").read_text())
    assert result.status in ("closed", "open")
    assert {f.id for f in result.fragments} == {f.id for f in small_scene.fragments}
    for fragment in result.fragments:
        assert fragment.placed, fragment.id
        assert fragment.pose is not None
        pose = np.asarray(fragment.pose)
        assert pose.shape == (4, 4)
        assert _rotation_ok(pose), fragment.id
        keypoints = np.asarray(fragment.local_layout.keypoints)
        assert keypoints.ndim == 2 and keypoints.shape[1] == 3 and len(keypoints) >= 2


def test_align_gltf_buffer_matches_accessors(aligned: Any) -> None:
    process, out = aligned
    assert process.returncode == 0, process.stderr
    gltf = json.loads((out / "model.gltf").read_text())
    assert gltf["asset"]["version"] == "2.0"
    (buffer,) = gltf["buffers"]
    data = base64.b64decode(buffer["uri"].split(",", 1)[1])
    assert len(data) == buffer["byteLength"]
    sizes = {5126: 4, 5125: 4}
    components = {"VEC3": 3, "SCALAR": 1}
    for accessor in gltf["accessors"]:
        view = gltf["bufferViews"][accessor["bufferView"]]
        expected = accessor["count"] * sizes[accessor["componentType"]]
        assert view["byteLength"] == expected * components[accessor["type"]]
        assert view["byteOffset"] + view["byteLength"] <= len(data)
    position = gltf["accessors"][gltf["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    assert len(position["min"]) == len(position["max"]) == 3


def test_align_cloud_and_picture(aligned: Any, small_scene: SyntheticScene) -> None:
    process, out = aligned
    assert process.returncode == 0, process.stderr
    cloud = o3d.io.read_point_cloud(out / "cloud.ply")
    assert len(cloud.points) == sum(len(f.points) for f in small_scene.fragments)
    assert cloud.has_colors()
    assert (out / "plan.png").read_bytes().startswith(PNG_SIGNATURE)


def test_align_model_ply_reads_back(run_jigsaw: RunJigsaw, scene_dir: Path, tmp_path: Path) -> None:
    # A second run writes the PLY mesh; its triangles follow from the result's polygon.
    process = run_jigsaw(
        "align", scene_dir, "-o", tmp_path / "r.json", "--model", tmp_path / "m.ply"
    )
    assert process.returncode == 0, process.stderr
    result = ResultModel.model_validate_json((tmp_path / "r.json").read_text())
    mesh = o3d.io.read_triangle_mesh(tmp_path / "m.ply")
    if result.floorplan.rooms:
        corners = len(result.floorplan.rooms[0].polygon)
        expected = 2 * corners + 2 * (corners - 2)  # walls, floor and ceiling fans
    else:
        chains = [f.local_layout.keypoints for f in result.fragments if f.placed]
        expected = sum(2 * (len(c) - 1) for c in chains)
    assert len(mesh.triangles) == expected
    assert np.asarray(mesh.vertices)[:, 2].min() == pytest.approx(0.0, abs=1e-6)


def test_layout_writes_keypoints(
    run_jigsaw: RunJigsaw, scene_dir: Path, tmp_path: Path, small_scene: SyntheticScene
) -> None:
    process = run_jigsaw("layout", scene_dir, "-o", tmp_path / "layout.json")
    assert process.returncode == 0, process.stderr
    data = json.loads((tmp_path / "layout.json").read_text())
    schema = json.loads((SCHEMA_DIR / "layout_file.schema.json").read_text(encoding="utf-8"))
    jsonschema.validate(data, schema)
    assert LayoutFileModel.model_validate(data).model_dump(mode="json") == data
    assert {f["id"] for f in data["fragments"]} == {f.id for f in small_scene.fragments}
    for fragment in data["fragments"]:
        keypoints = np.asarray(fragment["local_layout"]["keypoints"])
        assert keypoints.shape[1] == 3 and len(keypoints) >= 2


def test_garbage_file_is_reported_and_skipped(
    run_jigsaw: RunJigsaw, scene_dir: Path, tmp_path: Path
) -> None:
    for ply in sorted(scene_dir.glob("*.ply"))[:2]:
        shutil.copy(ply, tmp_path / ply.name)
    (tmp_path / "garbage.ply").write_bytes(b"this is not a point cloud\n" * 10)
    process = run_jigsaw("align", tmp_path, "-o", tmp_path / "out.json")
    assert process.returncode == 0, process.stderr
    assert re.search(r"garbage\.ply: \S+", process.stderr), process.stderr
    result = ResultModel.model_validate_json((tmp_path / "out.json").read_text())
    assert "garbage" not in {f.id for f in result.fragments}
    assert len(result.fragments) == 2


def test_only_garbage_exits_2(run_jigsaw: RunJigsaw, tmp_path: Path) -> None:
    (tmp_path / "garbage.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 5\n")
    process = run_jigsaw("align", tmp_path)
    assert process.returncode == 2
    assert re.search(r"garbage\.ply: \S+", process.stderr), process.stderr
    assert process.stdout == ""


def test_missing_path_exits_2(run_jigsaw: RunJigsaw, tmp_path: Path) -> None:
    process = run_jigsaw("align", tmp_path / "nothing-here.ply")
    assert process.returncode == 2
    assert "nothing-here.ply" in process.stderr


def test_bad_export_suffix_exits_2(run_jigsaw: RunJigsaw, scene_dir: Path, tmp_path: Path) -> None:
    process = run_jigsaw("align", scene_dir, "--model", tmp_path / "model.obj")
    assert process.returncode == 2
    assert "--model" in process.stderr and "model.obj" in process.stderr


def test_demo_writes_pictures(run_jigsaw: RunJigsaw, tmp_path: Path) -> None:
    process = run_jigsaw("demo", "--out", tmp_path / "demo", "--seed", "3")
    assert process.returncode == 0, process.stderr + process.stdout
    out = tmp_path / "demo"
    result = ResultModel.model_validate_json((out / "result.json").read_text())
    for fragment in result.fragments:
        assert (out / "layouts" / f"{fragment.id}.png").read_bytes().startswith(PNG_SIGNATURE)
        assert (out / "layouts" / f"{fragment.id}.svg").read_text().startswith("<svg")
    assert (out / "floorplan.png").read_bytes().startswith(PNG_SIGNATURE)
    assert "<svg" in (out / "floorplan.svg").read_text()
    assert (out / "scene" / "ground_truth.json").exists()
    for word in ("ACC_global", "layout error", "IoU", "energy margin"):
        assert word in process.stdout


def test_premerge_keeps_a_pose_for_every_input_file(
    run_jigsaw: RunJigsaw, scene_dir: Path, tmp_path: Path
) -> None:
    # A second copy of one scan, moved to another frame: the pre-merge registers it onto
    # the original, and both still get their own pose.
    first = sorted(scene_dir.glob("*.ply"))[0]
    for ply in sorted(scene_dir.glob("*.ply")):
        shutil.copy(ply, tmp_path / ply.name)
    points = parse_fragment(first.read_bytes()).points
    moved = points @ np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]).T + 2.0
    (tmp_path / "copy.ply").write_bytes(encode_ply(moved))
    process = run_jigsaw("align", tmp_path, "--premerge", "-o", tmp_path / "out.json", timeout=300)
    assert process.returncode == 0, process.stderr
    result = ResultModel.model_validate_json((tmp_path / "out.json").read_text())
    by_id = {f.id: f for f in result.fragments}
    assert set(by_id) == {p.stem for p in tmp_path.glob("*.ply")}
    assert by_id["copy"].pose is not None and by_id[first.stem].pose is not None
    # copy-local = R original-local + 2: the two poses differ by exactly that motion.
    motion = np.eye(4)
    motion[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    motion[:3, 3] = 2.0
    expected = np.array(by_id[first.stem].pose) @ np.linalg.inv(motion)
    assert np.allclose(np.array(by_id["copy"].pose), expected, atol=0.05)
