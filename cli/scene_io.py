"""Synthetic scenes on disk: one binary PLY per fragment plus ``ground_truth.json``.

The folder is a valid ``jigsaw align`` input: the PLYs are the fragments (id = file stem)
and the JSON file is ignored by the fragment reader.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from services.point_io import encode_ply
from services.synthetic import SyntheticScene, ground_truth_json

__all__ = ["TRUTH_FILE", "read_truth", "write_scene"]

TRUTH_FILE = "ground_truth.json"


def write_scene(scene: SyntheticScene, folder: Path) -> None:
    """Write every fragment as ``<id>.ply`` (binary little-endian, float) and the truth.

    Parameters
    ----------
    scene : SyntheticScene
        The generated scene; fragment points are in their local frames.
    folder : Path
        Created when missing; existing files of the same names are replaced.
    """
    folder.mkdir(parents=True, exist_ok=True)
    for fragment in scene.fragments:
        (folder / f"{fragment.id}.ply").write_bytes(encode_ply(fragment.points))
    text = json.dumps(ground_truth_json(scene), indent=2)
    (folder / TRUTH_FILE).write_text(text + "\n")


def read_truth(folder: Path) -> dict[str, Any]:
    """The ground truth written by :func:`write_scene` (``folder/ground_truth.json``).

    Raises
    ------
    OSError
        The file is missing or unreadable.
    ValueError
        The file is not a JSON object.
    """
    data = json.loads((folder / TRUTH_FILE).read_text())
    if not isinstance(data, dict):
        raise ValueError(f"{folder / TRUTH_FILE}: not a JSON object")
    return data
