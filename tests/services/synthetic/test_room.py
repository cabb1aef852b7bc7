"""Random rectilinear rooms: simple, counter-clockwise, axis-aligned, bounding box kept."""

from __future__ import annotations

import numpy as np
import pytest

from services.synthetic.room import random_rectilinear_polygon
from tests.services.synthetic.checks import assert_valid_polygon

pytestmark = pytest.mark.timeout(120)


@pytest.mark.parametrize("seed", range(200))
def test_random_polygons_are_valid(seed):
    rng = np.random.default_rng(seed)
    size = (float(rng.uniform(2.0, 18.0)), float(rng.uniform(6.0, 20.0)))
    target = int(rng.choice(np.arange(4, 17, 2)))
    polygon = random_rectilinear_polygon(rng, size, target, 0.8)
    assert_valid_polygon(polygon, (4, target), 0.8)
    assert np.allclose(polygon.min(axis=0), 0.0)
    assert np.allclose(polygon.max(axis=0), size)


def test_corner_targets_are_mostly_reached():
    reached = 0
    for seed in range(100):
        rng = np.random.default_rng(seed)
        target = int(rng.choice(np.arange(4, 17, 2)))
        reached += len(random_rectilinear_polygon(rng, (12.0, 16.0), target, 0.8)) == target
    assert reached >= 90
