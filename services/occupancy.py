"""Occupancy grid of a floorplan, with the cell values of ``nav_msgs/msg/OccupancyGrid``.

A cell is occupied (100) when a room's wall (an edge of its polygon) passes through it, free
(0) when its centre lies inside a room, unknown (-1) elsewhere: outside the rooms the service
has no evidence to call anything free or occupied. Pure: numpy in, a frozen record out.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from services.geometry import points_in_polygon
from services.types import FloatArray

__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "OccupancyGrid", "rasterize_floorplan"]

OCCUPIED, FREE, UNKNOWN = 100, 0, -1
# Wall samples per cell edge: an axis-parallel wall hits every cell it crosses; a slanted
# one may miss a cell whose corner it clips for under a quarter cell.
_SAMPLES_PER_CELL = 4


@dataclass(frozen=True)
class OccupancyGrid:
    """A rasterised floorplan.

    cells: (height, width) int8, row-major as ``OccupancyGrid.data``: cell ``[row, col]``
    covers x in ``origin[0] + col * resolution`` (one cell wide), y in
    ``origin[1] + row * resolution``; values :data:`OCCUPIED`, :data:`FREE`, :data:`UNKNOWN`.
    resolution: cell side, meters. origin: (x, y) of the corner of cell ``[0, 0]`` in the
    site frame, meters (a multiple of the resolution, so grids of one site line up).
    """

    cells: NDArray[np.int8]
    resolution: float
    origin: tuple[float, float]

    @property
    def width(self) -> int:
        """Cells along x."""
        return int(self.cells.shape[1])

    @property
    def height(self) -> int:
        """Cells along y."""
        return int(self.cells.shape[0])


def _edge_samples(polygon: FloatArray, step: float) -> FloatArray:
    """(M, 2) points along every edge of a closed (V, 2) polygon, at most ``step`` apart."""
    ends = np.roll(polygon, -1, axis=0)
    counts = np.ceil(np.linalg.norm(ends - polygon, axis=1) / step).astype(np.int64) + 1
    edge = np.repeat(np.arange(len(polygon)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)  # index of each edge's first sample
    t = (np.arange(len(edge)) - first) / np.maximum(counts[edge] - 1, 1)
    samples: FloatArray = polygon[edge] + t[:, None] * (ends - polygon)[edge]
    return samples


def rasterize_floorplan(
    polygons: Sequence[ArrayLike],
    resolution: float = 0.05,
    margin: float = 0.5,
    max_cells: int = 25_000_000,
) -> OccupancyGrid:
    """Rasterise room polygons into an occupancy grid.

    Parameters
    ----------
    polygons : (V, 2) vertices of each room, site frame, meters, first vertex not repeated;
        polygons of fewer than 3 vertices are ignored.
    resolution : cell side, meters.
    margin : unknown border around the rooms' bounding box, meters.
    max_cells : largest grid made (a bogus polygon must not exhaust memory).

    Returns
    -------
    OccupancyGrid
        Empty (0 x 0 cells, origin (0, 0)) when no polygon has 3 vertices.

    Raises
    ------
    ValueError
        Resolution or margin not positive and finite, non-finite vertices, or a grid of more
        than ``max_cells`` cells.

    Examples
    --------
    >>> grid = rasterize_floorplan([[[0, 0], [1, 0], [1, 1], [0, 1]]], 0.25, margin=0.25)
    >>> grid.origin, (grid.height, grid.width)
    ((-0.25, -0.25), (7, 7))
    >>> grid.cells[3].tolist()
    [-1, 100, 0, 0, 0, 100, -1]
    >>> rasterize_floorplan([]).cells.shape
    (0, 0)
    """
    if not (math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"resolution must be positive, not {resolution}")
    if not (math.isfinite(margin) and margin >= 0):
        raise ValueError(f"margin must be non-negative, not {margin}")
    rooms = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in polygons]
    rooms = [room for room in rooms if len(room) >= 3]
    if not rooms:
        return OccupancyGrid(np.zeros((0, 0), dtype=np.int8), resolution, (0.0, 0.0))
    vertices = np.concatenate(rooms)
    if not np.isfinite(vertices).all():
        raise ValueError("polygon vertices must be finite")
    origin = np.floor((vertices.min(axis=0) - margin) / resolution) * resolution
    width, height = np.ceil((vertices.max(axis=0) + margin - origin) / resolution).astype(int) + 1
    if width * height > max_cells:
        raise ValueError(f"a {width}x{height} grid exceeds {max_cells} cells")

    xs = origin[0] + (np.arange(width) + 0.5) * resolution
    ys = origin[1] + (np.arange(height) + 0.5) * resolution
    centres = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)  # row-major: y, then x
    inside = np.zeros(len(centres), dtype=bool)
    for room in rooms:  # a few rooms; each test is vectorised over every cell
        inside |= points_in_polygon(centres, room)
    cells = np.where(inside, FREE, UNKNOWN).astype(np.int8).reshape(height, width)

    walls = np.concatenate([_edge_samples(r, resolution / _SAMPLES_PER_CELL) for r in rooms])
    col, row = np.floor((walls - origin) / resolution).astype(np.int64).T
    cells[row, col] = OCCUPIED
    return OccupancyGrid(cells, float(resolution), (float(origin[0]), float(origin[1])))
