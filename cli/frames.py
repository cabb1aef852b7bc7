"""RGB-D frames on disk for the CLI: frame folders, frame zips and dataset sequences.

- a frame folder holds ``depth.png``, ``intrinsics.json`` and optionally ``color.png`` /
  ``color.jpg`` (contract section 1); a ``.zip`` of those files is the same frame;
- a TUM RGB-D sequence folder holds ``depth/`` and ``rgb/`` (depth scale 5000), with
  ``depth.txt`` / ``rgb.txt`` listing ``timestamp file``; depth and colour are paired by the
  nearest timestamp (at most 20 ms apart); intrinsics from ``intrinsics.json`` in the folder,
  else TUM's defaults (fx = fy = 525, cx = 319.5, cy = 239.5);
- a Redwood / Open3D sequence folder holds ``depth/`` and ``color/`` (depth scale 1000),
  paired by sorted order; intrinsics from ``intrinsics.json`` (this project's form, or
  Open3D's ``{"width", "height", "intrinsic_matrix": [9 values, column-major]}``), else
  PrimeSense defaults (as TUM's).

A sequence gives one fragment per chosen frame: ``max_frames`` evenly spaced ones, the
fragment id ``{folder}_{depth file stem}``.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from schemas.frames import IntrinsicsModel
from schemas.params import PipelineParams
from services.errors import InvalidIntrinsicsError
from services.rgbd import COLOR_NAMES, DEPTH_NAME, INTRINSICS_NAME, RgbdFrame, decode_frame
from services.uploads import read_frame_archive

__all__ = [
    "FrameSource",
    "dataset_frames",
    "is_dataset",
    "is_frame_dir",
    "read_frame_dir",
    "read_frame_zip",
]

_TUM_DEFAULT = {"fx": 525.0, "fy": 525.0, "cx": 319.5, "cy": 239.5}
_MAX_PAIR_SECONDS = 0.02
_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


@dataclass(frozen=True)
class FrameSource:
    """One frame of a dataset sequence: its fragment id and files."""

    fragment_id: str
    depth: Path
    color: Path | None


def is_frame_dir(path: Path) -> bool:
    """True for a folder holding a frame's ``depth.png`` or ``intrinsics.json``."""
    return path.is_dir() and ((path / DEPTH_NAME).exists() or (path / INTRINSICS_NAME).exists())


def is_dataset(path: Path) -> bool:
    """True for a TUM (``depth/`` + ``rgb/``) or Redwood (``depth/`` + ``color/``) folder."""
    return (path / "depth").is_dir() and ((path / "rgb").is_dir() or (path / "color").is_dir())


def read_frame_dir(path: Path, params: PipelineParams) -> RgbdFrame:
    """Decode a frame folder (OSError when a file cannot be read; FragmentError subclasses
    for what is wrong with the frame)."""
    names = (DEPTH_NAME, INTRINSICS_NAME, *COLOR_NAMES)
    files = {name: (path / name).read_bytes() for name in names if (path / name).is_file()}
    return decode_frame(files, params.layout.frame, params.parser)


def read_frame_zip(path: Path, params: PipelineParams) -> RgbdFrame:
    """Decode a frame's zip archive (the same checks as an upload)."""
    files = read_frame_archive(path.read_bytes())
    return decode_frame(files, params.layout.frame, params.parser)


def _listing(folder: Path, listing: Path) -> list[tuple[float, Path]]:
    """(timestamp, file) of a TUM list file, or of the images named by timestamps."""
    if listing.is_file():
        rows = []
        for line in listing.read_text().splitlines():
            parts = line.split()
            if len(parts) >= 2 and not line.startswith("#"):
                rows.append((float(parts[0]), folder.parent / parts[1]))
        return rows
    found = []
    for image in sorted(folder.iterdir()):
        if image.suffix.lower() in _IMAGE_SUFFIXES:
            try:
                found.append((float(image.stem), image))
            except ValueError:
                continue
    return found


def _tum_pairs(root: Path) -> list[tuple[Path, Path | None]]:
    depth = _listing(root / "depth", root / "depth.txt")
    colour = _listing(root / "rgb", root / "rgb.txt")
    if not colour:
        return [(d, None) for _, d in depth]
    stamps = np.array([t for t, _ in colour])
    pairs: list[tuple[Path, Path | None]] = []
    for t, d in depth:
        k = int(np.argmin(np.abs(stamps - t)))
        pairs.append((d, colour[k][1] if abs(stamps[k] - t) <= _MAX_PAIR_SECONDS else None))
    return pairs


def _redwood_pairs(root: Path) -> list[tuple[Path, Path | None]]:
    depth = sorted(p for p in (root / "depth").iterdir() if p.suffix.lower() == ".png")
    colour = sorted(p for p in (root / "color").iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES)
    if len(colour) != len(depth):
        return [(d, None) for d in depth]
    return list(zip(depth, colour, strict=True))


def _dataset_intrinsics(root: Path, width: int, height: int, scale: float) -> IntrinsicsModel:
    """The sequence's intrinsics file (ours or Open3D's), else the TUM/PrimeSense defaults."""
    path = root / INTRINSICS_NAME
    if not path.is_file():
        path = root / "camera_intrinsic.json"
    if not path.is_file():
        return IntrinsicsModel(width=width, height=height, depth_scale=scale, **_TUM_DEFAULT)
    try:
        values = json.loads(path.read_text())
        if "intrinsic_matrix" in values:
            m = values["intrinsic_matrix"]  # column-major 3x3
            values = {
                "width": values["width"],
                "height": values["height"],
                "fx": m[0],
                "fy": m[4],
                "cx": m[6],
                "cy": m[7],
            }
        values.setdefault("depth_scale", scale)
        return IntrinsicsModel.model_validate(values)
    except (ValueError, KeyError, IndexError, TypeError) as exc:
        raise InvalidIntrinsicsError(f"{path.name}: {exc}") from exc


def dataset_frames(
    root: Path, params: PipelineParams, max_frames: int = 12
) -> Iterator[tuple[str, RgbdFrame | Exception]]:
    """The chosen frames of a TUM or Redwood sequence, as (fragment id, frame or the error
    that made it unusable)."""
    tum = (root / "rgb").is_dir()
    pairs = _tum_pairs(root) if tum else _redwood_pairs(root)
    if not pairs:
        return
    chosen = np.unique(np.linspace(0, len(pairs) - 1, min(max_frames, len(pairs))).astype(int))
    scale = 5000.0 if tum else 1000.0
    intrinsics: IntrinsicsModel | None = None
    for index in chosen:
        depth, colour = pairs[int(index)]
        fragment_id = f"{root.name}_{depth.stem}"[:64]
        try:
            data = depth.read_bytes()
            if intrinsics is None:
                width, height = (
                    int.from_bytes(data[16:20], "big"),
                    int.from_bytes(data[20:24], "big"),
                )
                intrinsics = _dataset_intrinsics(root, width, height, scale)
            files = {DEPTH_NAME: data, INTRINSICS_NAME: intrinsics.model_dump_json().encode()}
            if colour is not None:
                name = "color.jpg" if colour.suffix.lower() in (".jpg", ".jpeg") else "color.png"
                files[name] = colour.read_bytes()
            yield fragment_id, decode_frame(files, params.layout.frame, params.parser)
        except Exception as exc:  # reported per frame by the caller
            yield fragment_id, exc
