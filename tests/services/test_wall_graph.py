"""Wall estimation graph and the chain between source and target."""

from __future__ import annotations

import numpy as np
import pytest

from schemas.params import LayoutParams
from services.wall_graph import find_wall_chain
from services.wall_lines import WallLine

pytestmark = pytest.mark.timeout(60)

CELL = 0.08


def _line(axis: int, offset: float, travel: int, spans: list[tuple[float, float]]) -> WallLine:
    origin = -2.0
    high = np.zeros(int(14.0 / CELL), dtype=bool)
    for lo, hi in spans:
        high[round((lo - origin) / CELL) : round((hi - origin) / CELL)] = True
    return WallLine(axis, offset, travel, origin, CELL, high, np.array(spans, dtype=np.float64))


@pytest.mark.parametrize("rule", ["spanning_forest", "evidence"])
def test_l_shaped_chain_with_an_occluded_corner(rule):
    # Wall along x at y = 0 (interior +y) seen from x = 0 to 4.5; wall along y at x = 5
    # (interior -x) seen from y = 0.6 to 3: the corner (5, 0) is occluded.
    lines = [_line(0, 0.0, 1, [(0.0, 4.5)]), _line(1, 5.0, 1, [(0.6, 3.0)])]
    chain = find_wall_chain(lines, LayoutParams(source_target=rule))
    assert chain is not None
    assert np.allclose(chain.keypoints, [[0.0, 0.0], [5.0, 0.0], [5.0, 3.0]], atol=0.05)


def test_gap_of_a_door_stays_one_wall():
    lines = [_line(0, 1.0, 1, [(0.0, 2.0), (3.0, 6.0)])]
    chain = find_wall_chain(lines, LayoutParams())
    assert chain is not None
    assert np.allclose(chain.keypoints, [[0.0, 1.0], [6.0, 1.0]], atol=0.05)


def test_chain_follows_the_travel_direction():
    # Interior -y: the wall is travelled towards -x, so the source is its right end.
    lines = [_line(0, 2.0, -1, [(1.0, 4.0)])]
    chain = find_wall_chain(lines, LayoutParams())
    assert chain is not None
    assert chain.keypoints[0][0] == pytest.approx(4.0)
    assert chain.keypoints[-1][0] == pytest.approx(1.0)


def test_no_lines_no_chain():
    assert find_wall_chain([], LayoutParams()) is None
