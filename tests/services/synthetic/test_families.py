"""Room shape families: every family gives valid rooms with its own corner counts."""

from __future__ import annotations

import collections

import numpy as np
import pytest

from services.synthetic.families import FAMILIES, family_corners, pick_family, random_room
from tests.services.synthetic.checks import assert_valid_polygon

pytestmark = pytest.mark.timeout(60)


@pytest.mark.parametrize("family", FAMILIES)
def test_families_give_valid_rooms(family):
    counts: collections.Counter[int] = collections.Counter()
    for seed in range(40):
        rng = np.random.default_rng(seed)
        size = (float(rng.uniform(2.0, 18.0)), float(rng.uniform(6.0, 20.0)))
        polygon = random_room(rng, family, size, (4, 16), 0.5)
        assert_valid_polygon(polygon, (4, 16), 0.5)
        assert np.allclose(polygon.min(axis=0), 0.0)
        assert len(polygon) in family_corners(family, (4, 16))
        counts[len(polygon)] += 1
    assert len(counts) == len(family_corners(family, (4, 16)))


def test_thin_rooms_are_three_to_six_times_longer_than_wide():
    for seed in range(40):
        polygon = random_room(np.random.default_rng(seed), "thin", (5.0, 18.0), (4, 16), 0.8)
        size = polygon.max(axis=0) - polygon.min(axis=0)
        assert 3.0 - 0.01 <= size.max() / size.min() <= 6.0 + 0.01
        assert size.max() == pytest.approx(18.0)


def test_families_follow_the_corner_range():
    assert family_corners("comb", (10, 14)) == (12,)
    assert family_corners("thin", (6, 16)) == ()
    picked = {pick_family(np.random.default_rng(seed), (6, 6)) for seed in range(50)}
    assert picked == {"carved", "L"}
    with pytest.raises(ValueError):
        random_room(np.random.default_rng(0), "U", (8.0, 8.0), (4, 6), 0.8)
