"""A small hand-made result for the exports' and the layout model's tests: two placed
fragments (a and b) and one unplaced (c), in an L-shaped room when closed."""

from __future__ import annotations

import numpy as np

from schemas.result import (
    FloorplanModel,
    FragmentResultModel,
    LocalLayoutModel,
    ResultModel,
    RoomModel,
)

L_SHAPE = np.array([[0, 0], [4, 0], [4, 2], [2, 2], [2, 3], [0, 3]], dtype=np.float64)


def yaw_pose(yaw_deg: float, shift: tuple[float, float, float]) -> np.ndarray:
    """A 4x4 pose: ``yaw_deg`` about z, then ``shift``."""
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    pose = np.eye(4)
    pose[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    pose[:3, 3] = shift
    return pose


def small_result(closed: bool = True) -> ResultModel:
    """Two placed fragments (a and b) and one unplaced (c)."""
    chain = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.0]]
    fragments = [
        FragmentResultModel(
            id="a",
            placed=True,
            pose=yaw_pose(0.0, (0.0, 0.0, 0.0)).tolist(),
            loop_index=0,
            local_layout=LocalLayoutModel(keypoints=chain),
        ),
        FragmentResultModel(
            id="b",
            placed=True,
            pose=yaw_pose(90.0, (1.0, 2.0, 0.5)).tolist(),
            loop_index=1,
            local_layout=LocalLayoutModel(keypoints=chain[:2]),
        ),
        FragmentResultModel(id="c", placed=False, local_layout=LocalLayoutModel(keypoints=[])),
    ]
    rooms = [RoomModel(id="room_0", polygon=L_SHAPE.tolist(), ceiling_z=2.6)] if closed else []
    return ResultModel(
        status="closed" if closed else "open",
        fragments=fragments,
        floorplan=FloorplanModel(rooms=rooms),
    )
