"""Checks shared by the generator tests."""

from __future__ import annotations

import numpy as np

from services.synthetic.room import signed_area
from services.synthetic.scene import SyntheticFragment
from services.types import FloatArray

__all__ = ["assert_valid_polygon", "world_points"]


def world_points(fragment: SyntheticFragment) -> FloatArray:
    return fragment.points @ fragment.pose[:3, :3].T + fragment.pose[:3, 3]


def assert_valid_polygon(polygon: np.ndarray, n_range: tuple[int, int], min_edge: float) -> None:
    n = len(polygon)
    assert n_range[0] <= n <= n_range[1] and n % 2 == 0
    assert signed_area(polygon) > 0.0, "not counter-clockwise"
    delta = np.roll(polygon, -1, axis=0) - polygon
    assert np.all((delta[:, 0] == 0) ^ (delta[:, 1] == 0)), "not rectilinear"
    assert np.all(np.abs(delta).sum(axis=1) >= min_edge - 0.011), "edge too short"
    turns = (
        delta[:, 0] * np.roll(delta, -1, axis=0)[:, 1] - delta[:, 1] * np.roll(delta, -1, 0)[:, 0]
    )
    assert np.all(turns != 0), "collinear vertex"
    lo = np.minimum(polygon, np.roll(polygon, -1, axis=0))
    hi = np.maximum(polygon, np.roll(polygon, -1, axis=0))
    for i in range(n):
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue  # neighbours share a vertex
            touching = np.all(lo[i] <= hi[j]) and np.all(lo[j] <= hi[i])
            assert not touching, f"edges {i} and {j} touch"
