"""A frame's short end wall that may be a furniture side: the chain with and without it.

Where a frame's view ends beside a wardrobe or shelf standing against a wall, its chain can
start or end on the furniture's side (or, having turned at its edge, on its front): a short
wall meeting the room's wall at a convex corner, just as a real corner of the room would.
One frame cannot tell the two apart (the view's top stays below the furniture's, and
nothing is seen past its edge), but the loop can: a side taken for a corner adds a turn
the room does not make, which the other pieces must undo with a hidden corner and a gap
that does not close. So each such chain is also offered without that wall, and the
placement keeps it so where the room then closes with an energy lower by
``end_wall_prior`` (most such walls are the room's own corners;
:func:`services.pipeline.place_site`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from services.frame_layout import side_like
from services.types import LocalLayout

__all__ = ["END_WALLS", "without_end_wall"]

END_WALLS = ("first", "last")
_LEAST_WALL_BESIDE = 1.5  # m: the wall a dropped end wall turns from, at least


def without_end_wall(
    layout: LocalLayout, end: str, longest: float, least_view: float = 0.0
) -> LocalLayout | None:
    """The frame's chain without its ``end`` wall ("first" or "last"), where that wall is no
    longer than ``longest`` (m), turns into its neighbour at a convex (left) corner, and that
    neighbour is at least 1.5 m long and twice as long as it; None otherwise, and for
    clouds, frames seeing less than ``least_view`` across (radians), chains of one wall, or
    ``longest`` 0.

    The dropped end's boundary region is left empty: its points lay around the dropped
    wall's far end, and nothing was seen around the new end but the wall it continues.

    >>> from services.types import ManhattanFrame
    >>> frame = ManhattanFrame(np.eye(3), 0.0, None)
    >>> side_first = np.array([[0.0, 0.0], [0.5, 0.0], [0.5, 3.0], [-2.0, 3.0]])
    >>> lay = LocalLayout(side_first, frame, evidence="frame")
    >>> without_end_wall(lay, "first", 1.3).keypoints.tolist()
    [[0.5, 0.0], [0.5, 3.0], [-2.0, 3.0]]
    >>> without_end_wall(lay, "last", 1.3) is None  # 2.5 m: a wall, not a side
    True
    """
    kp = layout.keypoints
    if layout.evidence != "frame" or longest <= 0.0 or len(kp) < 3:
        return None
    if (layout.view_angle or 0.0) < least_view:
        return None
    # The step from the end wall's corner to the chain's free end, and the wall it turns
    # off (chain order), as the frame's own layout judges a furniture side.
    along, step = (
        (kp[2] - kp[1], kp[0] - kp[1]) if end == "first" else (kp[-2] - kp[-3], kp[-1] - kp[-2])
    )
    # A side or front stands against a wall the view follows for longer: a short wall
    # after a shorter one is more likely the room's own jog.
    beside = max(_LEAST_WALL_BESIDE, 2.0 * float(np.linalg.norm(step)))
    if not side_like(along, step, longest) or float(np.linalg.norm(along)) < beside:
        return None
    if end == "first":
        return replace(layout, keypoints=kp[1:].copy(), source_boundary=np.zeros((0, 3)))
    return replace(layout, keypoints=kp[:-1].copy(), target_boundary=np.zeros((0, 3)))
