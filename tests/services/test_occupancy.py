"""The floorplan's occupancy grid: walls occupied, rooms free, the rest unknown."""

from __future__ import annotations

import numpy as np
import pytest

from services.occupancy import FREE, OCCUPIED, UNKNOWN, rasterize_floorplan

pytestmark = pytest.mark.timeout(30)

L_ROOM = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 2.0], [2.0, 2.0], [2.0, 3.0], [0.0, 3.0]])


def _cell(grid, x: float, y: float) -> int:
    col, row = np.floor((np.array([x, y]) - grid.origin) / grid.resolution).astype(int)
    return int(grid.cells[row, col])


def test_l_room_cells_walls_inside_and_outside() -> None:
    grid = rasterize_floorplan([L_ROOM + np.array([0.013, 0.027])], resolution=0.05, margin=0.5)
    assert grid.cells.dtype == np.int8
    assert set(np.unique(grid.cells).tolist()) == {UNKNOWN, FREE, OCCUPIED}
    # The origin is a multiple of the resolution and the rooms lie inside the margin.
    assert np.allclose(np.array(grid.origin) / 0.05, np.round(np.array(grid.origin) / 0.05))
    assert grid.origin[0] <= 0.013 - 0.5 and grid.origin[1] <= 0.027 - 0.5
    assert grid.origin[0] + grid.width * 0.05 >= 4.013 + 0.5
    assert grid.origin[1] + grid.height * 0.05 >= 3.027 + 0.5
    shifted = L_ROOM + np.array([0.013, 0.027])
    assert _cell(grid, 1.0, 1.0) == FREE
    assert _cell(grid, 3.0, 2.5) == UNKNOWN  # the L's notch is outside
    assert _cell(grid, -0.3, 1.0) == UNKNOWN
    for x, y in shifted:  # every corner, and a point on every wall, is occupied
        assert _cell(grid, x, y) == OCCUPIED
    for (x1, y1), (x2, y2) in zip(shifted, np.roll(shifted, -1, axis=0), strict=True):
        assert _cell(grid, (x1 + x2) / 2, (y1 + y2) / 2) == OCCUPIED


def test_walls_are_one_closed_line_between_free_and_unknown() -> None:
    """No free cell touches an unknown one: the wall line has no gap (4-neighbourhood)."""
    rotated = L_ROOM @ np.array([[np.cos(0.4), np.sin(0.4)], [-np.sin(0.4), np.cos(0.4)]])
    for polygon in (L_ROOM + 0.013, rotated):
        cells = rasterize_floorplan([polygon], resolution=0.05).cells
        free, unknown = cells == FREE, cells == UNKNOWN
        assert not (free[1:] & unknown[:-1]).any() and not (free[:-1] & unknown[1:]).any()
        assert not (free[:, 1:] & unknown[:, :-1]).any()
        assert not (free[:, :-1] & unknown[:, 1:]).any()
        # An axis-parallel wall takes one or two cells across, not a thick band.
        assert (cells == OCCUPIED).sum() * 0.05 < 2.5 * 14.0


def test_free_area_matches_the_polygon_area() -> None:
    grid = rasterize_floorplan([L_ROOM], resolution=0.02)
    covered = np.isin(grid.cells, (FREE, OCCUPIED)).sum() * 0.02**2
    assert covered == pytest.approx(10.0, rel=0.03)  # 4 x 2 + 2 x 1 square meters


def test_several_rooms_and_degenerate_input() -> None:
    far = L_ROOM + np.array([10.0, 0.0])
    grid = rasterize_floorplan([L_ROOM, far, np.zeros((2, 2))], resolution=0.1)
    assert _cell(grid, 1.0, 1.0) == FREE and _cell(grid, 11.0, 1.0) == FREE
    assert _cell(grid, 7.0, 1.0) == UNKNOWN
    empty = rasterize_floorplan([np.zeros((0, 2))])
    assert empty.cells.shape == (0, 0) and (empty.width, empty.height) == (0, 0)


@pytest.mark.parametrize(
    ("polygons", "kwargs", "match"),
    [
        ([L_ROOM], {"resolution": 0.0}, "resolution"),
        ([L_ROOM], {"resolution": float("nan")}, "resolution"),
        ([L_ROOM], {"margin": -1.0}, "margin"),
        ([L_ROOM * np.nan], {}, "finite"),
        ([L_ROOM * 1e4], {"max_cells": 1_000_000}, "exceeds"),
    ],
)
def test_refusals(polygons, kwargs, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        rasterize_floorplan(polygons, **kwargs)


def test_grid_is_frozen() -> None:
    grid = rasterize_floorplan([L_ROOM])
    with pytest.raises(AttributeError):
        grid.resolution = 1.0  # type: ignore[misc]
