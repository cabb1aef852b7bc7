"""A frame's chain end that stops inside its view: the junction there may hide metres.

A frame's chain normally runs from one edge of its view to the other (paper, supplement:
source and target from the frustum), so the next frame's chain starts about where it ends.
Where the chain stops well inside the view and the walls seen just past its end stand at
another distance, the camera saw past the end and found no wall to follow: the wall turned
away behind a protruding corner (the camera stands on the next wall's line, or behind it),
or furniture hid its foot. The wall the loop continues with is then out of sight, and the
junction can hide metres of it, or a step of the room. On the rendered tune frames
(2000-2059, three cameras, 1520 chain ends) 10 ends stop 10 degrees or more short of the
view's edge with such a jump of 0.1 m or more; 8 of them miss over 1 m of their true wall,
against 26 of the other 1510.

So such an end is *open*: its junction's hidden displacement gets a wide spread on both
axes (``placement.open_end_sigma``), in the placement energy's closure and in the
refinement, which does not make the walls either side of it collinear: a step may hide
there (:func:`services.layout_model.build_polygon` draws it next to the open end). A chain
that went wrong (furniture taken for a wall) stops inside its view too, and the spread
lets such a chain fit a wrong room more easily: the loop's other junctions still decide.
"""

from __future__ import annotations

import math

import numpy as np

from services.types import LocalLayout

__all__ = ["open_ends"]

_JUMP_ARC = math.radians(6.0)  # the walls just past an end: this much azimuth beyond it
_LEAST_JUMP = 0.1  # m


def open_ends(
    layout: LocalLayout,
    least_angle: float,
    least_view: float = 0.0,
    least_jump: float = _LEAST_JUMP,
) -> tuple[bool, bool]:
    """Whether the view of a single frame continues past its chain's source and target by
    at least ``least_angle`` (radians) of azimuth around its camera, the walls seen just past
    the end standing nearer or farther than the end by ``least_jump`` (m) or more. Frames
    seeing less than ``least_view`` (radians) across have no open end.

    The jump tells a lost wall from a chain that merely stopped short on a wall that goes
    on (seen past the end at the end's own distance, the chains there missed decimeters,
    not metres). Clouds, merged frames (no view ranges), chains without walls and
    ``least_angle`` 0 have no open end. The chain runs counter-clockwise around a camera
    inside the room: past the source lies lower azimuth, past the target higher.

    >>> from services.types import ManhattanFrame
    >>> frame = ManhattanFrame(np.eye(3), 0.0, None)
    >>> azimuth = np.radians(np.arange(-40.0, 40.0, 0.5))
    >>> ranges = np.column_stack([azimuth, np.where(azimuth > 0.25, 4.0, 2.0)])
    >>> layout = LocalLayout(np.array([[2.0, -1.6], [2.0, 0.5]]), frame, view_angle=1.4,
    ...                      cameras=np.zeros((1, 2)), view_ranges=ranges)
    >>> open_ends(layout, math.radians(10.0))
    (False, True)
    """
    if least_angle <= 0 or not layout.ok or len(layout.cameras) != 1:
        return False, False
    if (layout.view_angle or 0.0) < least_view:
        return False, False
    if len(layout.view_ranges) == 0:
        return False, False
    ends = layout.keypoints[[0, -1]] - layout.cameras[0]
    azimuth = np.arctan2(ends[:, 1], ends[:, 0])
    distance = np.hypot(ends[:, 0], ends[:, 1])
    # Each bin's azimuth past each end, wrapped to (-pi, pi]: negative is before it.
    past = (layout.view_ranges[None, :, 0] - azimuth[:, None] + math.pi) % (2 * math.pi) - math.pi
    past[0] = -past[0]  # past the source is before it
    ahead = (past > 0) & (past < math.pi / 2)
    beyond = np.where(ahead, past, 0.0).max(axis=1)
    near = ahead & (past <= _JUMP_ARC)
    out = []
    for k in range(2):
        ranges = layout.view_ranges[near[k], 1]
        jump = abs(float(np.median(ranges)) - distance[k]) if len(ranges) else 0.0
        out.append(bool(beyond[k] >= least_angle and jump >= least_jump))
    return out[0], out[1]
