"""File exports of an alignment: aligned point cloud, 3D layout model, pictures.

Used by ``jigsaw align --cloud/--model/--picture`` and ``jigsaw demo``. The encoders return
bytes or text (pure); :func:`write_exports` writes the requested files. The 3D layout model
and its PLY and glTF encodings are :mod:`services.model_export` (the web API serves them too).

Frames: fragment points are fragment-local; poses (result JSON, contract section 3) map them
to the site frame (z up, floor at z = 0).
"""

from __future__ import annotations

import html
import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from api.colors import fragment_rgb
from cli.pictures import Canvas, palette
from schemas.result import ResultModel
from services.layout_model import LayoutMesh
from services.model_export import layout_model, mesh_gltf, mesh_ply, site_chains, to_site
from services.point_io import encode_ply
from services.types import FloatArray, LocalLayout

__all__ = [
    "ExportTargets",
    "aligned_cloud_ply",
    "floorplan_canvas",
    "layout_canvas",
    "placed_poses",
    "save_picture",
    "write_exports",
    "write_model",
]

_MODEL_SUFFIXES = (".ply", ".gltf")
_PICTURE_SUFFIXES = (".svg", ".png")
_WALL_BAND = (0.2, 2.0)  # m above the floor: the slice drawn in top views (no floor/ceiling)
_MAX_PIXELS = 1200  # longest picture side, px (before margins)


@dataclass(frozen=True)
class ExportTargets:
    """Optional output files of ``jigsaw align``.

    cloud: ``.ply`` of all placed fragments' points in the site frame, coloured per fragment.
    model: ``.ply`` (mesh) or ``.gltf`` of the 3D layout (walls, floor, ceiling).
    picture: ``.svg`` or ``.png`` top view of the floorplan with the placed points.
    """

    cloud: Path | None = None
    model: Path | None = None
    picture: Path | None = None

    def requested(self) -> dict[str, Path | None]:
        """Option name -> path (None when not asked for)."""
        return {"--cloud": self.cloud, "--model": self.model, "--picture": self.picture}

    def problems(self) -> list[str]:
        """Options whose file suffix is not supported (empty when all are fine)."""
        suffixes = {
            "--cloud": (".ply",),
            "--model": _MODEL_SUFFIXES,
            "--picture": _PICTURE_SUFFIXES,
        }
        return [
            f"{option} {path}: must end in {' or '.join(suffixes[option])}"
            for option, path in self.requested().items()
            if path is not None and path.suffix.lower() not in suffixes[option]
        ]


# --------------------------------------------------------------------------------------------
# Point clouds
# --------------------------------------------------------------------------------------------


def placed_poses(result: ResultModel) -> dict[str, FloatArray]:
    """(4, 4) local -> site pose of every placed fragment, in result order."""
    return {
        f.id: np.asarray(f.pose, dtype=np.float64)
        for f in result.fragments
        if f.placed and f.pose is not None
    }


def _stride(n: int, limit: int | None) -> int:
    return 1 if limit is None or n <= limit else -(-n // limit)


def aligned_cloud_ply(
    clouds: Mapping[str, FloatArray],
    result: ResultModel,
    *,
    colour: bool = True,
    max_points_per_fragment: int | None = None,
) -> bytes:
    """Binary PLY of all placed fragments in the site frame.

    Parameters
    ----------
    clouds : id -> (N, 3) float64, fragment-local, meters.
    result : the alignment result; unplaced fragments are left out.
    colour : add uchar ``red``/``green``/``blue`` per point, one colour per fragment id
        (:func:`api.colors.fragment_rgb`, as in the pictures and the web view).
    max_points_per_fragment : keep every k-th point so each fragment has at most this many.
    """
    poses = placed_poses(result)
    parts, colours = [np.zeros((0, 3))], [np.zeros((0, 3), np.uint8)]
    for fid, pose in poses.items():
        if fid not in clouds:
            continue
        points = clouds[fid][:: _stride(len(clouds[fid]), max_points_per_fragment)]
        parts.append(to_site(points, pose))
        colours.append(np.tile(np.array(fragment_rgb(fid), np.uint8), (len(points), 1)))
    points = np.vstack(parts)
    extra = None
    if colour:
        rgb = np.vstack(colours)
        extra = {"red": rgb[:, 0], "green": rgb[:, 1], "blue": rgb[:, 2]}
    return encode_ply(points, extra_properties=extra)


# --------------------------------------------------------------------------------------------
# 3D layout model
# --------------------------------------------------------------------------------------------


def write_model(mesh: LayoutMesh, path: Path) -> None:
    """Write the mesh as ``.ply`` or ``.gltf`` (by suffix)."""
    if path.suffix.lower() == ".gltf":
        _write(path, json.dumps(mesh_gltf(mesh, path.stem)).encode("utf-8"))
    else:
        _write(path, mesh_ply(mesh))


# --------------------------------------------------------------------------------------------
# Pictures
# --------------------------------------------------------------------------------------------


def _wall_slice(points: FloatArray, floor_z: float) -> FloatArray:
    """Points between the floor and ceiling bands (all points when that leaves none)."""
    height = points[:, 2] - floor_z
    keep = (height > _WALL_BAND[0]) & (height < _WALL_BAND[1])
    return points[keep] if keep.any() else points


def _bounds(
    xy: FloatArray, fixed: FloatArray, pad: float = 0.5
) -> tuple[float, float, float, float]:
    """Robust extent of the points (0.5 to 99.5 percentile) joined with ``fixed`` points."""
    parts = [fixed.reshape(-1, 2)]
    if len(xy):
        parts.append(np.percentile(xy, [0.5, 99.5], axis=0))
    both = np.vstack(parts) if sum(len(p) for p in parts) else np.zeros((1, 2))
    lo, hi = both.min(axis=0) - pad, both.max(axis=0) + pad
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def _canvas(bounds: tuple[float, float, float, float]) -> Canvas:
    extent = max(bounds[2] - bounds[0], bounds[3] - bounds[1], 1e-3)
    return Canvas(bounds, scale=min(60.0, _MAX_PIXELS / extent))


def _scale_bar(canvas: Canvas) -> None:
    extent = max(canvas.bounds[2] - canvas.bounds[0], canvas.bounds[3] - canvas.bounds[1])
    length = next((m for m in (0.5, 1.0, 2.0, 5.0, 10.0) if m >= extent / 8), 20.0)
    canvas.scale_bar(length)


def _darker(colour: tuple[int, int, int]) -> tuple[int, int, int]:
    r, g, b = (int(c * 0.6) for c in colour)
    return r, g, b


def floorplan_canvas(
    clouds: Mapping[str, FloatArray], result: ResultModel, max_points: int = 40_000
) -> Canvas:
    """Top view of the site: placed points per fragment, the room walls, ids, a scale bar.

    Points are the wall slice (0.2 to 2 m above the floor) of each placed fragment, at most
    ``max_points`` per fragment, in the fragment's colour (by id), over the room polygon drawn
    thick black; without a closed room each placed chain is drawn in its fragment's colour.
    """
    poses = placed_poses(result)
    slices = {
        fid: _wall_slice(to_site(clouds[fid][:: _stride(len(clouds[fid]), max_points)], p), 0.0)
        for fid, p in poses.items()
        if fid in clouds
    }
    rooms = [np.asarray(r.polygon, np.float64) for r in result.floorplan.rooms if r.polygon]
    chains = site_chains(result)
    fixed = np.vstack([np.zeros((0, 2)), *rooms, *chains.values()])
    xy = np.vstack([np.zeros((0, 2)), *(s[:, :2] for s in slices.values())])
    canvas = _canvas(_bounds(xy, fixed))
    for polygon in rooms:  # under the points, so misplaced wall points stay visible
        canvas.polyline(polygon, (0, 0, 0), width=5, closed=True)
    for fid, points in slices.items():
        canvas.points(points[:, :2], fragment_rgb(fid))
    if not rooms:
        for fid, chain in chains.items():
            canvas.polyline(chain, _darker(fragment_rgb(fid)), width=3)
    for fid, points in slices.items():
        if len(points):
            canvas.label(np.median(points[:, :2], axis=0).tolist(), html.escape(fid))
    _scale_bar(canvas)
    return canvas


def layout_canvas(
    points: FloatArray, layout: LocalLayout, colour_index: int = 0, max_points: int = 60_000
) -> Canvas:
    """Top view of one fragment in its aligned (Manhattan) frame with its keypoint chain.

    points: (N, 3) float64, fragment-local. The chain is drawn black over the wall slice of
    the points; the source is marked green, the target red, other keypoints grey.
    """
    frame = layout.frame
    thinned = points[:: _stride(len(points), max_points)]
    aligned = _wall_slice(thinned @ frame.rotation.T, frame.floor_z)
    keypoints = np.asarray(layout.keypoints, dtype=np.float64).reshape(-1, 2)
    canvas = _canvas(_bounds(aligned[:, :2], keypoints))
    canvas.points(aligned[:, :2], palette(colour_index))
    if len(keypoints) == 0:
        canvas.label(aligned[:, :2].mean(axis=0).tolist() if len(aligned) else [0, 0], "no wall")
    else:
        canvas.polyline(keypoints, (0, 0, 0), width=1)
        canvas.marks(keypoints[1:-1], (90, 90, 90), size=3)
        canvas.marks(keypoints[:1], (0, 160, 0), size=6)
        canvas.marks(keypoints[-1:], (200, 0, 0), size=6)
        canvas.label(keypoints[0].tolist(), "source")
        canvas.label(keypoints[-1].tolist(), "target")
    _scale_bar(canvas)
    return canvas


def save_picture(canvas: Canvas, path: Path) -> None:
    """Write the canvas as ``.png`` or ``.svg`` (by suffix)."""
    if path.suffix.lower() == ".png":
        _write(path, canvas.png())
    else:
        _write(path, canvas.svg().encode("utf-8"))


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------


def _write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)


def write_exports(
    targets: ExportTargets, clouds: Mapping[str, FloatArray], result: ResultModel
) -> list[str]:
    """Write the requested files; return notes for stderr (what could not be written, why).

    Raises
    ------
    OSError
        A file could not be written.
    """
    notes = []
    if targets.cloud is not None:
        if placed_poses(result):
            _write(targets.cloud, aligned_cloud_ply(clouds, result))
        else:
            notes.append(f"{targets.cloud}: not written, no fragment was placed")
    if targets.model is not None:
        mesh = layout_model(result)
        if mesh is None or len(mesh.triangles) == 0:
            notes.append(f"{targets.model}: not written, no wall was placed")
        else:
            write_model(mesh, targets.model)
    if targets.picture is not None:
        save_picture(floorplan_canvas(clouds, result), targets.picture)
    return notes
