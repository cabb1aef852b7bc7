"""Polygon helpers: inside test and distance to the boundary, checked against dense sampling;
grid cells counted as numpy's row-wise unique counts them; column extremes as numpy's."""

from __future__ import annotations

import numpy as np
import pytest

from services.geometry import (
    column_max,
    column_min,
    distance_to_polygon,
    is_simple_rectilinear,
    points_in_polygon,
    unique_cells,
)

L_ROOM = np.array([[0, 0], [8, 0], [8, 3], [5, 3], [5, 6], [0, 6]], dtype=np.float64)
SLANTED = np.array([[0, 0], [6, 1], [5, 5], [1, 4]], dtype=np.float64)


def _sampled_distance(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    following = np.roll(polygon, -1, axis=0)
    t = np.linspace(0.0, 1.0, 2001)[:, None, None]
    boundary = (polygon[None] + t * (following - polygon)[None]).reshape(-1, 2)
    return np.linalg.norm(points[:, None, :] - boundary[None], axis=2).min(axis=1)


@pytest.mark.parametrize("polygon", [L_ROOM, SLANTED], ids=["rectilinear", "slanted"])
def test_distance_matches_dense_boundary_sampling(polygon):
    points = np.random.default_rng(3).uniform(-3.0, 11.0, size=(400, 2))
    expected = _sampled_distance(points, polygon)
    assert np.allclose(distance_to_polygon(points, polygon), expected, atol=5e-3)


def test_inside_test_on_an_l_shaped_room():
    points = np.array([[1.0, 1.0], [7.0, 2.0], [7.0, 5.0], [-1.0, 1.0], [4.0, 5.5]])
    assert points_in_polygon(points, L_ROOM).tolist() == [True, True, False, False, True]


@pytest.mark.parametrize(
    ("polygon", "valid"),
    [
        (L_ROOM, True),
        (L_ROOM[::-1], True),  # clockwise: still a room's outline
        (L_ROOM + np.array([[0, 0], [0, 0], [0, 0.005], [0, 0.005], [0, 0], [0, 0]]), True),
        # A corner chain missed: one wall runs askew across the notch.
        (np.delete(L_ROOM, 3, axis=0), False),
        # Two walls of the loop cross (a piece folded back over another).
        (np.array([[0, 0], [4, 0], [4, 2], [1, 2], [1, -1], [0, -1]], dtype=np.float64), False),
        # Two parallel walls on one line, touching: no room between them.
        (np.array([[0, 0], [4, 0], [4, 1], [2, 1], [2, 0], [1, 0], [1, 1], [0, 1]], float), False),
        (L_ROOM[:3], False),
    ],
)
def test_is_simple_rectilinear(polygon, valid):
    assert is_simple_rectilinear(polygon) is valid


@pytest.mark.parametrize("span", [3, 400, 2**31 - 1], ids=["dense", "floor plan", "extremes"])
def test_unique_cells_are_numpys_row_wise_unique(span):
    rng = np.random.default_rng(span)
    cells = rng.integers(-span, span, size=(5000, 2), endpoint=True)
    cells[:3] = [[-span, span], [span, -span], [-span, -span]]
    rows, counts = unique_cells(cells)
    expected_rows, expected_counts = np.unique(cells, axis=0, return_counts=True)
    assert rows.dtype == np.int64 and counts.dtype == np.int64
    assert np.array_equal(rows, expected_rows) and np.array_equal(counts, expected_counts)


def test_unique_cells_of_nothing_is_empty():
    rows, counts = unique_cells(np.zeros((0, 2), dtype=np.int64))
    assert rows.shape == (0, 2) and counts.shape == (0,)


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int64, np.int32])
def test_column_extremes_are_numpys_along_the_rows(dtype):
    rng = np.random.default_rng(7)
    values = (rng.normal(0.0, 1e3, (10_001, 3)) * rng.uniform(0, 1, (10_001, 1))).astype(dtype)
    for low, high in [(values, values), (values[::3, :2], values[1::2, 1:])]:
        assert column_min(low).dtype == dtype and column_max(high).dtype == dtype
        assert np.array_equal(column_min(low), low.min(axis=0))
        assert np.array_equal(column_max(high), high.max(axis=0))
