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

Furniture standing in the corner itself leaves a step instead: the chain turns off the wall
beside it onto its front, then back onto its side, and ends where that side meets the wall
behind. A real jog of the room looks the same from one frame, so that chain too is offered
flattened (the front moved back onto the wall behind, :func:`flattened_end_step`) and kept
so on the same terms.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from services.frame_layout import side_like
from services.geometry import cross
from services.types import LocalLayout

__all__ = ["END_WALLS", "flattened_end_step", "without_end_wall"]

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
    if not _trimmable(layout, longest, least_view, 3):
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


def _trimmable(layout: LocalLayout, limit: float, least_view: float, least_keypoints: int) -> bool:
    """Whether a chain end trial applies: a frame seeing at least ``least_view`` across,
    with ``least_keypoints`` or more, the trial on (``limit`` over 0)."""
    return (
        layout.evidence == "frame"
        and limit > 0.0
        and len(layout.keypoints) >= least_keypoints
        and (layout.view_angle or 0.0) >= least_view
    )


def _turn(a: np.ndarray, b: np.ndarray) -> int:
    """+1 for a left (convex) turn from heading a to heading b, -1 for a right one, 0 else."""
    z = float(cross(a, b))
    return 1 if z > 1e-9 else (-1 if z < -1e-9 else 0)


def flattened_end_step(
    layout: LocalLayout, end: str, deepest: float, least_view: float = 0.0
) -> LocalLayout | None:
    """The frame's chain with a step at its ``end`` ("first" or "last") flattened: the
    front and the side of furniture standing in the corner, taken for the wall behind.

    Where a wardrobe stands in a corner at the view's edge, the chain turns off the wall
    beside it onto the wardrobe's front (convex), then back onto its side (concave), and
    ends where that side meets the wall behind it. The variant moves the front back by the
    side's length onto that wall and drops the side; the wall it turned off runs on by as
    much. Only a side no longer than ``deepest`` (m) qualifies; None otherwise, and for
    clouds, frames seeing less than ``least_view`` across (radians), chains of fewer than
    three walls, or ``deepest`` 0.

    >>> from services.types import ManhattanFrame
    >>> frame = ManhattanFrame(np.eye(3), 0.0, None)
    >>> wardrobe_last = np.array([[0.0, 3.0], [0.0, 0.6], [1.9, 0.6], [1.9, 0.0]])
    >>> lay = LocalLayout(wardrobe_last, frame, evidence="frame")
    >>> flattened_end_step(lay, "last", 0.8).keypoints.tolist()
    [[0.0, 3.0], [0.0, 0.0], [1.9, 0.0]]
    >>> flattened_end_step(lay, "first", 0.8) is None
    True
    """
    kp = layout.keypoints
    if not _trimmable(layout, deepest, least_view, 4):
        return None
    if end == "last":
        wall, front, side = kp[-3] - kp[-4], kp[-2] - kp[-3], kp[-1] - kp[-2]
        turns = (_turn(wall, front), _turn(front, side))
    else:
        side, front, wall = kp[1] - kp[0], kp[2] - kp[1], kp[3] - kp[2]
        turns = (_turn(front, wall), _turn(side, front))
    if turns != (1, -1) or float(np.linalg.norm(side)) > deepest:
        return None
    if end == "last":
        flat = np.vstack([kp[:-3], kp[-3] + side, kp[-1:]])
        return replace(layout, keypoints=flat, target_boundary=np.zeros((0, 3)))
    flat = np.vstack([kp[:1], kp[2] - side, kp[3:]])
    return replace(layout, keypoints=flat, source_boundary=np.zeros((0, 3)))
