"""Walls the scans show that the floorplan does not explain: a check of the closed room.

Each local layout keeps the wall cells its chain does not follow (``unchained_walls``):
a fin or notch the chain cut across, a wall it skipped, the next room's walls seen through
a door. Placed with the fragment's pose, those outside the room or on one of its walls are
explained; those standing inside the room, away from every wall of the floorplan, are
walls the floorplan misses. Its shape is then wrong however well the pieces close, so such
a room is never reported as sure (paper 3.1 assumes every wall a scan shows is in its chain).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from services.geometry import distance_to_polygon, points_in_polygon
from services.types import FloatArray, LocalLayout

__all__ = ["unexplained_walls"]

# m: a wall cell this close to a wall of the floorplan is that wall, a little off (the
# refinement leaves a few centimetres, a chain's wall line up to a few decimetres)
_ON_FLOORPLAN = 0.3


def unexplained_walls(
    polygon: FloatArray,
    layouts: Mapping[str, LocalLayout],
    poses: Mapping[str, FloatArray],
    cell_size: float,
) -> dict[str, float]:
    """Meters of wall each placed fragment shows inside the room, off its floorplan.

    Parameters
    ----------
    polygon : (V, 2) the room's floorplan, site frame.
    layouts : local layouts by fragment id (their ``unchained_walls``, aligned frame).
    poses : (4, 4) fragment-local -> site poses of the placed fragments.
    cell_size : length of wall one cell stands for, m (``LayoutParams.cell_size``).

    Returns
    -------
    Fragment id -> meters, for the fragments with any such wall.
    """
    out = {}
    for fid, pose in poses.items():
        layout = layouts[fid]
        cells = layout.unchained_walls
        if len(cells) == 0:
            continue
        site = layout.floor_points_local(cells) @ pose[:3, :3].T + pose[:3, 3]
        xy = site[:, :2]
        inside = points_in_polygon(xy, polygon) & (distance_to_polygon(xy, polygon) > _ON_FLOORPLAN)
        if inside.any():
            out[fid] = float(np.count_nonzero(inside)) * cell_size
    return out
