"""Real room shapes for benchmarks: MatterportLayout outlines, cleaned, split by house.

The outlines (``../shared/data/room_shapes_mp3d.json`` next to the repository, see that
folder's README) may be used for testing and benchmarks only, never shipped inside the
product: they stay outside the project and are read here, never from ``services/``.
Each usable outline is cleaned by :func:`services.synthetic.shapes.clean_outline` and can be
given to :func:`services.synthetic.generate_scene` as ``outline``.

Houses are split once and for all into a "tune" and a "test" set (by the parity of the first
byte of the SHA-256 of the house id, so the split does not move when houses are added): tune
a method on one, report on the other.

Run ``python bench/room_shapes.py`` for the statistics of the cleaned shapes.
"""

from __future__ import annotations

import hashlib
import json
from collections import Counter
from collections.abc import Iterable
from pathlib import Path
from typing import Any, Literal

import numpy as np
from rich.console import Console
from rich.table import Table

from services.synthetic.shapes import OutlineLimits, clean_outline
from services.types import FloatArray

__all__ = ["DEFAULT_PATH", "house_split", "load_room_shapes", "raw_outlines", "split_houses"]

DEFAULT_PATH = Path(__file__).resolve().parents[2] / "shared" / "data" / "room_shapes_mp3d.json"
Split = Literal["tune", "test"]


def load_room_shapes(
    path: Path = DEFAULT_PATH,
    houses: Iterable[str] | None = None,
    limits: OutlineLimits | None = None,
) -> list[tuple[str, FloatArray]]:
    """The usable room outlines of a shapes file, cleaned, in file order.

    Parameters
    ----------
    path : Path
        A JSON list of ``{"house": id, "polygon": [[x, y], ...]}`` (meters, either winding).
    houses : iterable of str, optional
        Keep only these houses (e.g. one side of :func:`split_houses`); all when None.
    limits : OutlineLimits, optional
        Passed to :func:`~services.synthetic.shapes.clean_outline`.

    Returns
    -------
    list of (house id, (K, 2) float64 polygon)
        Counter-clockwise, axis-aligned, bounding-box minimum at the origin, meters; entries
        that are malformed or that the cleaning rejects are skipped.
    """
    keep = None if houses is None else set(houses)
    shapes = []
    for entry in json.loads(Path(path).read_text()):
        house, polygon = _parse(entry)
        if house is None or polygon is None or (keep is not None and house not in keep):
            continue
        cleaned = clean_outline(polygon, limits)
        if cleaned is not None:
            shapes.append((house, cleaned))
    return shapes


def house_split(house: str) -> Split:
    """The set a house belongs to: "tune" or "test", fixed by its id alone."""
    return "tune" if hashlib.sha256(house.encode()).digest()[0] % 2 == 0 else "test"


def raw_outlines(path: Path = DEFAULT_PATH, split: Split = "test") -> list[tuple[int, str, Any]]:
    """(index in the file, house, polygon as the file has it) of one split's entries, in
    file order, uncleaned: for generators that clean the outlines their own way.

    Raises
    ------
    FileNotFoundError
        When the shapes file is missing.
    """
    if not Path(path).exists():
        raise FileNotFoundError(f"no real room shapes: {path} is missing")
    return [
        (index, str(entry["house"]), entry["polygon"])
        for index, entry in enumerate(json.loads(Path(path).read_text()))
        if house_split(str(entry["house"])) == split
    ]


def split_houses(houses: Iterable[str]) -> tuple[frozenset[str], frozenset[str]]:
    """(tune, test): the distinct house ids split by :func:`house_split`; disjoint."""
    distinct = set(houses)
    tune = frozenset(h for h in distinct if house_split(h) == "tune")
    return tune, frozenset(distinct - tune)


def _parse(entry: Any) -> tuple[str | None, FloatArray | None]:
    """(house, (V, 2) polygon) of one file entry; None for what is missing or malformed."""
    try:
        house = str(entry["house"])
        polygon = np.asarray(entry["polygon"], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        return None, None
    if polygon.ndim != 2 or polygon.shape[1] != 2:
        return house, None
    return house, polygon


def main() -> None:
    """Print how many outlines survive cleaning and their corner counts, per split."""
    raw = json.loads(DEFAULT_PATH.read_text())
    shapes = load_room_shapes()
    tune, test = split_houses(str(e.get("house")) for e in raw)
    table = Table(title=f"Room shapes: {len(shapes)} of {len(raw)} outlines usable")
    table.add_column("set")
    table.add_column("houses", justify="right")
    table.add_column("rooms", justify="right")
    table.add_column("corners: rooms")
    for name, ids in (("all", tune | test), ("tune", tune), ("test", test)):
        corners = Counter(len(p) for h, p in shapes if h in ids)
        histogram = ", ".join(f"{k}: {corners[k]}" for k in sorted(corners))
        table.add_row(name, str(len(ids)), str(sum(corners.values())), histogram)
    Console().print(table)


if __name__ == "__main__":
    main()
