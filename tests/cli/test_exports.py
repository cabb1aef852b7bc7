"""File exports (cli.exports) and scene files (cli.scene_io), in-process."""

from __future__ import annotations

import base64
import json
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
from schemas.result import (
    FloorplanModel,
    FragmentResultModel,
    LocalLayoutModel,
    ResultModel,
    RoomModel,
)
from services.layout_model import layout_mesh
from services.model_export import layout_model, mesh_gltf, mesh_ply
from services.parsing import parse_fragment
from services.synthetic import SyntheticScene
from services.types import LocalLayout, ManhattanFrame

pytestmark = pytest.mark.timeout(60)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
L_SHAPE = np.array([[0, 0], [4, 0], [4, 2], [2, 2], [2, 3], [0, 3]], dtype=np.float64)


def _pose(yaw_deg: float, shift: tuple[float, float, float]) -> np.ndarray:
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    pose = np.eye(4)
    pose[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    pose[:3, 3] = shift
    return pose


def _result(closed: bool = True) -> ResultModel:
    """Two placed fragments (a and b) and one unplaced (c)."""
    chain = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.0]]
    fragments = [
        FragmentResultModel(
            id="a",
            placed=True,
            pose=_pose(0.0, (0.0, 0.0, 0.0)).tolist(),
            loop_index=0,
            local_layout=LocalLayoutModel(keypoints=chain),
        ),
        FragmentResultModel(
            id="b",
            placed=True,
            pose=_pose(90.0, (1.0, 2.0, 0.5)).tolist(),
            loop_index=1,
            local_layout=LocalLayoutModel(keypoints=chain[:2]),
        ),
        FragmentResultModel(id="c", placed=False, local_layout=LocalLayoutModel(keypoints=[])),
    ]
    rooms = [RoomModel(id="room_0", polygon=L_SHAPE.tolist(), ceiling_z=2.6)] if closed else []
    return ResultModel(
        status="closed" if closed else "open",
        fragments=fragments,
        floorplan=FloorplanModel(rooms=rooms),
    )


def _clouds() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    return {k: rng.uniform([0, 0, 0], [3, 2, 2.5], (500 + 100 * i, 3)) for i, k in enumerate("abc")}


def test_gltf_is_valid_and_buffer_matches_accessors() -> None:
    mesh = layout_mesh(L_SHAPE, 0.0, 2.5)
    gltf = json.loads(json.dumps(mesh_gltf(mesh)))
    assert gltf["asset"]["version"] == "2.0"
    data = base64.b64decode(gltf["buffers"][0]["uri"].split(",", 1)[1])
    assert len(data) == gltf["buffers"][0]["byteLength"]
    position, index = gltf["accessors"]
    pos_view, idx_view = (gltf["bufferViews"][a["bufferView"]] for a in (position, index))
    assert pos_view["byteLength"] == position["count"] * 12
    assert idx_view["byteLength"] == index["count"] * 4
    assert pos_view["byteLength"] + idx_view["byteLength"] == len(data)
    vertices = np.frombuffer(data[: pos_view["byteLength"]], dtype="<f4").reshape(-1, 3)
    indices = np.frombuffer(data[idx_view["byteOffset"] :], dtype="<u4")
    np.testing.assert_allclose(vertices, mesh.vertices, atol=1e-6)
    np.testing.assert_array_equal(indices, mesh.triangles.ravel())
    np.testing.assert_allclose(position["min"], vertices.min(axis=0))
    np.testing.assert_allclose(position["max"], vertices.max(axis=0))
    assert indices.max() < position["count"]


def test_gltf_rejects_empty_mesh() -> None:
    with pytest.raises(ValueError, match="no triangle"):
        mesh_gltf(layout_mesh(np.zeros((0, 2)), 0.0, 2.5))


def test_ply_mesh_reads_back_with_open3d(tmp_path: Path) -> None:
    mesh = layout_mesh(L_SHAPE, 0.0, 2.5)
    path = tmp_path / "model.ply"
    path.write_bytes(mesh_ply(mesh))
    loaded = o3d.io.read_triangle_mesh(path)
    assert len(loaded.triangles) == 4 * len(L_SHAPE) - 4  # 2V walls + 2 (V - 2) fans
    np.testing.assert_array_equal(np.asarray(loaded.triangles), mesh.triangles)
    np.testing.assert_allclose(np.asarray(loaded.vertices), mesh.vertices, atol=1e-6)


def test_layout_model_of_open_result_is_wall_strips() -> None:
    mesh = layout_model(_result(closed=False))
    assert mesh is not None
    assert len(mesh.triangles) == 2 * 2 + 2 * 1  # chain a: 2 walls, chain b: 1 wall
    assert mesh.vertices[:, 2].min() == 0.0 and mesh.vertices[:, 2].max() > 2.0


def test_layout_model_closed_uses_room_height() -> None:
    mesh = layout_model(_result())
    assert mesh is not None
    assert mesh.vertices[:, 2].max() == pytest.approx(2.6)


def test_layout_model_none_when_nothing_placed() -> None:
    result = ResultModel(status="failed", fragments=[FragmentResultModel(id="x", placed=False)])
    assert layout_model(result) is None


def test_aligned_cloud_transforms_and_colours(tmp_path: Path) -> None:
    clouds = _clouds()
    data = aligned_cloud_ply(clouds, _result())
    points = parse_fragment(data, ParserLimits(min_points=1)).points
    expected = np.vstack(
        [clouds["a"], clouds["b"] @ _pose(90.0, (0, 0, 0))[:3, :3].T + [1, 2, 0.5]]
    )
    np.testing.assert_allclose(points, expected, atol=1e-5)  # c is unplaced: left out
    path = tmp_path / "cloud.ply"
    path.write_bytes(data)
    colours = np.asarray(o3d.io.read_point_cloud(path).colors)
    # one colour per fragment id, as in the service's pictures and the web view
    np.testing.assert_allclose(colours[0] * 255, fragment_rgb("a"), atol=0.5)
    np.testing.assert_allclose(colours[-1] * 255, fragment_rgb("b"), atol=0.5)


def test_pictures_png_and_svg() -> None:
    canvas = floorplan_canvas(_clouds(), _result())
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
    assert write_exports(targets, _clouds(), _result()) == []
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
