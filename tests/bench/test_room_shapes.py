"""The real-room-shape loader: cleaned polygons, bad entries skipped, a fixed house split."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bench.room_shapes import (
    DEFAULT_PATH,
    house_split,
    load_room_shapes,
    raw_outlines,
    split_houses,
)
from services.geometry import signed_area
from services.synthetic.shapes import is_simple_rectilinear

pytestmark = pytest.mark.timeout(60)

ROTATED_L = [[0, 0], [8, 0.1], [7.95, 3.1], [4.95, 3.05], [4.9, 6.05], [-0.1, 6.0]]


@pytest.fixture
def shapes_file(tmp_path: Path) -> Path:
    entries = [
        {"house": "a", "polygon": ROTATED_L},
        {"house": "a", "polygon": [[0, 0], [1, 0], [1, 1], [0, 1]]},  # too small
        {"house": "b", "polygon": [[0, 0], [0, 5], [5, 5], [5, 0]]},  # clockwise
        {"house": "b", "polygon": [[0, 0], [5, 0]]},  # degenerate
        {"house": "c", "polygon": "not a polygon"},
        {"polygon": [[0, 0], [5, 0], [5, 5], [0, 5]]},  # no house
    ]
    path = tmp_path / "shapes.json"
    path.write_text(json.dumps(entries))
    return path


def test_loader_cleans_and_skips(shapes_file: Path) -> None:
    shapes = load_room_shapes(shapes_file)
    assert [house for house, _ in shapes] == ["a", "b"]
    (_, l_room), (_, square) = shapes
    assert len(l_room) == 6 and len(square) == 4
    for _, polygon in shapes:
        assert is_simple_rectilinear(polygon) and signed_area(polygon) > 0.0
        assert np.allclose(polygon.min(axis=0), 0.0)
    assert [h for h, _ in load_room_shapes(shapes_file, houses=["b", "zzz"])] == ["b"]


def test_house_split_is_fixed_and_disjoint() -> None:
    houses = [f"house{k}" for k in range(40)]
    tune, test = split_houses(houses + houses[:5])
    assert tune.isdisjoint(test) and tune | test == set(houses)
    assert tune and test
    assert all(house_split(h) == "tune" for h in tune)
    assert split_houses(reversed(houses)) == (tune, test)


@pytest.mark.skipif(not DEFAULT_PATH.exists(), reason="real room shapes not present")
def test_real_shapes_load() -> None:
    shapes = load_room_shapes()
    raw = json.loads(DEFAULT_PATH.read_text())
    assert 0.8 * len(raw) <= len(shapes) <= len(raw)
    corners = np.array([len(p) for _, p in shapes])
    assert corners.min() >= 4 and corners.max() <= 16 and np.all(corners % 2 == 0)
    assert np.mean(corners > 4) > 0.3
    assert all(is_simple_rectilinear(p) and signed_area(p) >= 4.0 for _, p in shapes)
    tune, test = split_houses(h for h, _ in shapes)
    assert len(tune) >= 10 and len(test) >= 10
    on_tune = load_room_shapes(houses=tune)
    assert {h for h, _ in on_tune} == tune


def test_raw_outlines_keep_the_files_index_and_polygon_of_one_split(tmp_path: Path) -> None:
    houses = ["a", "e", "b", "f"]  # two of each split
    entries = [
        {"house": h, "polygon": [[0, 0], [k + 1, 0], [k + 1, 1]]} for k, h in enumerate(houses)
    ]
    path = tmp_path / "shapes.json"
    path.write_text(json.dumps(entries))
    tested = [
        (k, h, entries[k]["polygon"]) for k, h in enumerate(houses) if house_split(h) == "test"
    ]
    assert [k for k, _, _ in tested] == [1, 3]
    assert raw_outlines(path) == tested
    assert len(raw_outlines(path, "tune")) == len(houses) - len(tested)
    with pytest.raises(FileNotFoundError, match="is missing"):
        raw_outlines(tmp_path / "none.json")
