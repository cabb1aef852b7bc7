"""The 3D layout model of a result (services.model_export): glTF and PLY encodings, walls of
an open result, the room of a closed one."""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest

from schemas.result import FragmentResultModel, ResultModel
from services.layout_model import layout_mesh
from services.model_export import layout_model, mesh_gltf, mesh_ply
from tests.result_fixtures import L_SHAPE, small_result

pytestmark = pytest.mark.timeout(60)


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
    mesh = layout_model(small_result(closed=False))
    assert mesh is not None
    assert len(mesh.triangles) == 2 * 2 + 2 * 1  # chain a: 2 walls, chain b: 1 wall
    assert mesh.vertices[:, 2].min() == 0.0 and mesh.vertices[:, 2].max() > 2.0


def test_layout_model_closed_uses_room_height() -> None:
    mesh = layout_model(small_result())
    assert mesh is not None
    assert mesh.vertices[:, 2].max() == pytest.approx(2.6)


def test_layout_model_none_when_nothing_placed() -> None:
    result = ResultModel(status="failed", fragments=[FragmentResultModel(id="x", placed=False)])
    assert layout_model(result) is None
