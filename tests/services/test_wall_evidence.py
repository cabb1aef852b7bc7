"""Walls the scans show inside the room that its floorplan misses."""

from __future__ import annotations

import numpy as np
import pytest

from schemas.params import LayoutParams
from services.types import LocalLayout, ManhattanFrame
from services.wall_evidence import unexplained_walls

pytestmark = pytest.mark.timeout(120)

ROOM = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [0.0, 4.0]])
CELL = LayoutParams().cell_size


def _turned_layout(cells: np.ndarray, yaw: float) -> tuple[LocalLayout, np.ndarray]:
    """A layout whose aligned frame is turned by ``yaw`` from its local frame and lifted,
    holding ``cells`` (room coordinates) as its unchained walls, and the pose that puts
    its local frame back in the room."""
    c, s = np.cos(yaw), np.sin(yaw)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # aligned = R @ local
    frame = ManhattanFrame(rotation=rotation, floor_z=-1.2, ceiling_z=1.4)
    layout = LocalLayout(
        keypoints=np.array([[0.0, 0.0], [6.0, 0.0]]), frame=frame, unchained_walls=cells
    )
    pose = np.eye(4)
    pose[:3, :3] = rotation  # local -> room: back through the aligned frame
    pose[2, 3] = 1.2
    return layout, pose


def _cells(start: tuple[float, float], stop: tuple[float, float]) -> np.ndarray:
    n = round(np.abs(np.subtract(stop, start)).sum() / CELL)
    return np.linspace(start, stop, n, endpoint=False)


def test_walls_inside_the_room_off_its_floorplan_are_counted_per_fragment():
    fin = _cells((3.0, 0.4), (3.0, 1.4))  # a fin's face 1 m long, standing in the room
    layout, pose = _turned_layout(fin, 0.7)
    meters = unexplained_walls(ROOM, {"a": layout}, {"a": pose}, CELL)
    assert meters == {"a": pytest.approx(len(fin) * CELL)}


def test_walls_on_the_floorplan_or_outside_the_room_are_explained():
    on_wall = _cells((1.0, 3.9), (3.0, 3.9))  # another scan's wall, 10 cm off after refinement
    next_room = _cells((1.0, -1.5), (3.0, -1.5))  # seen through a door
    layout, pose = _turned_layout(np.vstack([on_wall, next_room]), -1.1)
    assert unexplained_walls(ROOM, {"a": layout}, {"a": pose}, CELL) == {}
