"""The 3D layout model of a result and its encodings: binary PLY mesh and glTF 2.0.

Used by ``jigsaw align --model``, ``jigsaw demo`` and ``GET /v1/sites/{site}/layout.gltf``.
The encoders return bytes or a JSON-ready dict (no I/O). The mesh keeps its vertices in the
site frame (z up, floor at z = 0, meters); the glTF model turns z-up into glTF's y-up with a
rotation on its one node.
"""

from __future__ import annotations

import base64
from typing import Any

import numpy as np

from schemas.result import ResultModel
from services.layout_model import LayoutMesh, layout_mesh
from services.types import FloatArray

__all__ = ["DEFAULT_ROOM_HEIGHT", "layout_model", "mesh_gltf", "mesh_ply", "site_chains", "to_site"]

DEFAULT_ROOM_HEIGHT = 2.5  # m, model height when no fragment saw the ceiling
_Y_UP = [-(0.5**0.5), 0.0, 0.0, 0.5**0.5]  # glTF node quaternion (x, y, z, w): z-up -> y-up
# one triangle list (mode 4) of accessor 0 (positions) indexed by accessor 1, material 0
_PRIMITIVE: dict[str, Any] = {"attributes": {"POSITION": 0}, "indices": 1, "mode": 4, "material": 0}


def to_site(points: FloatArray, pose: FloatArray) -> FloatArray:
    """(N, 3) fragment-local -> site frame, row-wise ``R p + t``."""
    return np.asarray(points @ pose[:3, :3].T + pose[:3, 3], dtype=np.float64)


def site_chains(result: ResultModel) -> dict[str, FloatArray]:
    """Each placed fragment's keypoint chain in the site frame, id -> (K, 2) float64."""
    chains = {}
    for f in result.fragments:
        if f.placed and f.pose is not None and len(f.local_layout.keypoints) >= 2:
            local = np.asarray(f.local_layout.keypoints, dtype=np.float64)
            chains[f.id] = to_site(local, np.asarray(f.pose, dtype=np.float64))[:, :2]
    return chains


def _wall_strips(chains: list[FloatArray], floor_z: float, ceiling_z: float) -> LayoutMesh:
    """Vertical wall quads (two triangles each) along open chains."""
    vertices, triangles, offset = [np.zeros((0, 3))], [np.zeros((0, 3), np.int64)], 0
    for chain in chains:
        k = len(chain)
        bottom = np.column_stack([chain, np.full(k, floor_z)])
        top = np.column_stack([chain, np.full(k, ceiling_z)])
        i = np.arange(k - 1)
        quads = [np.column_stack([i, i + 1, k + i + 1]), np.column_stack([i, k + i + 1, k + i])]
        vertices.append(np.vstack([bottom, top]))
        triangles.append(np.vstack(quads) + offset)
        offset += 2 * k
    return LayoutMesh(np.vstack(vertices), np.vstack(triangles).astype(np.int64))


def layout_model(result: ResultModel) -> LayoutMesh | None:
    """The 3D layout as a triangle mesh in the site frame, or None when nothing is placed.

    A result with a room (closed, ambiguous, or an open result's unconfirmed guess) gives
    walls, floor and ceiling (:func:`services.layout_model.layout_mesh`); one without a
    room gives the walls of the placed chains only.
    """
    rooms = [room for room in result.floorplan.rooms if len(room.polygon) >= 3]
    if rooms:
        room = rooms[0]
        ceiling = room.ceiling_z if room.ceiling_z is not None else DEFAULT_ROOM_HEIGHT
        polygon = np.asarray(room.polygon, dtype=np.float64)
        return layout_mesh(polygon, room.floor_z, ceiling)
    chains = site_chains(result)
    if not chains:
        return None
    return _wall_strips(list(chains.values()), 0.0, DEFAULT_ROOM_HEIGHT)


def mesh_ply(mesh: LayoutMesh) -> bytes:
    """Binary little-endian PLY with ``vertex`` (float x, y, z) and ``face`` elements."""
    header = "\n".join(
        [
            "ply",
            "format binary_little_endian 1.0",
            "comment floorplan-jigsaw layout model, site frame, meters",
            f"element vertex {len(mesh.vertices)}",
            "property float x",
            "property float y",
            "property float z",
            f"element face {len(mesh.triangles)}",
            "property list uchar int vertex_indices",
            "end_header",
            "",
        ]
    )
    faces = np.empty(len(mesh.triangles), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    faces["n"] = 3
    faces["v"] = mesh.triangles
    vertices = np.ascontiguousarray(mesh.vertices, dtype="<f4")
    return header.encode("ascii") + vertices.tobytes() + faces.tobytes()


def mesh_gltf(mesh: LayoutMesh, name: str = "layout") -> dict[str, Any]:
    """A glTF 2.0 asset (JSON) with the mesh in one embedded base64 buffer.

    Positions are float32 VEC3 (with min/max), indices uint32; the node rotates the site
    frame's z-up into glTF's y-up.

    Raises
    ------
    ValueError
        The mesh has no triangle (glTF accessors need at least one element).
    """
    if len(mesh.triangles) == 0:
        raise ValueError("the mesh has no triangle")
    positions = np.ascontiguousarray(mesh.vertices, dtype="<f4")
    indices = np.ascontiguousarray(mesh.triangles.ravel(), dtype="<u4")
    blob = positions.tobytes() + indices.tobytes()  # both parts are multiples of 4 bytes
    uri = "data:application/octet-stream;base64," + base64.b64encode(blob).decode("ascii")
    n_pos = positions.nbytes
    return {
        "asset": {"version": "2.0", "generator": "floorplan-jigsaw"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": name, "rotation": _Y_UP}],
        "meshes": [{"name": name, "primitives": [_PRIMITIVE]}],
        "materials": [
            {
                "name": "wall",
                "doubleSided": True,
                "pbrMetallicRoughness": {
                    "baseColorFactor": [0.85, 0.85, 0.82, 1.0],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 1.0,
                },
            }
        ],
        "buffers": [{"byteLength": len(blob), "uri": uri}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": n_pos, "target": 34962},
            {"buffer": 0, "byteOffset": n_pos, "byteLength": indices.nbytes, "target": 34963},
        ],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": len(positions),
                "type": "VEC3",
                "min": positions.min(axis=0).astype(float).tolist(),
                "max": positions.max(axis=0).astype(float).tolist(),
            },
            {
                "bufferView": 1,
                "componentType": 5125,
                "count": len(indices),
                "type": "SCALAR",
            },
        ],
    }
