"""A frame's chain cut where one of its corners is contradicted by a wall seen past it.

A room's corner joins two walls that both end there: from inside the room neither can be
seen going on behind the other. Where a camera stands before a notch (the block between a
U room's legs, a T room's arm) it sees the block's face end at the block's corner and,
past that corner, the room's far wall running on into the leg. The wall graph may join the
face's line to that far wall's line across the leg (the stretch between them is at most a
doorway wide, and the camera saw space through it as it would through a door), making a
corner where there is open floor. The far wall's evidence then runs on past the face's
line, on the face's outer side, which a true corner never shows (a door does not reach up to
a corner: a jamb stands between).

Such a corner is taken out: the chain is cut there and keeps its larger part, which ends
where its wall was seen (the face's end, or the far wall's farthest seen point). Only wall
evidence on the lines themselves is used. A shorter run past suffices when the face is not
seen at the corner either (its last segment stops short of it, or its wall was deduced):
from far off, the block's corner hides all but a few decimetres of the leg's far wall, and a
true corner whose far wall runs on that much (depth noise at range) shows its other wall
up to it.

A right turn (a reflex corner of the room) is contradicted the same way, from the other
side: past such a corner each wall's line runs through the room, where no wall stands. When
one of its walls is seen going on past it (a window's sill and lintel, a door's lintel)
and the other is seen only from beyond that wall's line (it starts a wall's thickness or
more behind it), the other is a wall outside, seen through the opening: a neighbour's wall,
or the side of what stands outside. The chain is cut there and keeps the part along the
wall that goes on, carried as far as that wall was seen.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np

from services.geometry import cross
from services.types import FloatArray
from services.wall_lines import WallLine, run_axis, wall_line_of

__all__ = ["seen_past", "without_corners_seen_past"]

_TOUCH = 0.2  # m, a wall's seen run starts this close to the corner (or before it)
_PAST = 0.5  # m, and goes on at least this far beyond the other wall's line: no corner
# m, less suffices when the other wall is not seen at the corner either (it starts
# ``_UNSEEN_AT`` or more away, or was deduced): nothing there shows a corner (outside frames
# seeds 19-21: true corners reach 0.25 m past with the other wall seen up to them)
_PAST_UNSEEN = 0.27
_UNSEEN_AT = 0.3  # m
_MIN_PART = 0.3  # m, least length of the part of a chain kept
_SHORT = 0.3  # m, an end wall seen stopping this far short of its end does not reach it
_GAP = 0.3  # m, a wall seen with gaps this short is seen on through them
_FRONT_SLACK = 0.2  # m, a wall across this close to where a wall seen past stops meets it
_ON = 1e-6  # m, keypoints sit on their lines' offsets (and corners on both lines') exactly
_DETACHED = 0.15  # m, a wall first seen this far or more past a reflex corner is behind it
# m, how far a wall must be seen on past a reflex corner: less is often low clutter standing
# in line with it in the room (outside frames seed 20: 0.51 m at a T room's corner)
_PAST_REFLEX = 1.0

Keep = Literal["larger", "before", "after"]  # which part of a chain cut at a corner to keep


def _relative(spans: FloatArray, origin: float, direction: int) -> FloatArray:
    """(S, 2) run-coordinate ``spans`` as sorted spans of ``(run - origin) * direction``."""
    return np.sort((spans - origin) * direction, axis=1)


def _on_stretch(
    spans: FloatArray, start: FloatArray, towards: FloatArray, axis: int
) -> tuple[FloatArray, int]:
    """The run-coordinate ``spans`` of a line along ``axis`` as distances from ``start``
    walking towards ``towards`` (:func:`_relative`), only those overlapping the stretch
    between the two; and that walking direction along the axis (+1 or -1)."""
    direction = 1 if towards[axis] > start[axis] else -1
    relative = _relative(spans, float(start[axis]), direction)
    length = abs(float(towards[axis] - start[axis]))
    return relative[(relative[:, 1] > 0.0) & (relative[:, 0] < length)], direction


def seen_past(line: WallLine, corner: FloatArray, outward: int) -> float:
    """How far (m) ``line``'s seen wall runs on past ``corner`` in direction ``outward``
    (+1 or -1 along the line), from a segment starting within ``_TOUCH`` of the corner or
    before it; 0 when none does."""
    spans = _relative(line.seen_spans(_GAP), float(corner[line.axis]), outward)
    touching = spans[:, 0] <= _TOUCH
    return float(spans[touching, 1].max(initial=0.0))


def _outside(along: FloatArray, axis: int) -> int:
    """Along ``axis``, the direction away from the room of a wall walked along ``along``
    (interior on its left)."""
    left = np.array([-along[1], along[0]])
    return -1 if left[axis] > 0 else 1


def _past(lines: Sequence[WallLine], corner: FloatArray, axis: int, direction: int) -> float:
    """How far a seen wall along ``axis`` through ``corner`` runs on past it in
    ``direction`` (:func:`seen_past`, the most of every such line), unless a seen wall
    across it stands where it stops: then the chain's wall at the corner is a furniture
    front before that wall (seen at least ``_PAST`` long), and the wall seen past it is the
    room's (0)."""
    reach = max(
        (
            seen_past(line, corner, direction)
            for line in lines
            if not line.virtual and line.axis == axis and abs(line.offset - corner[1 - axis]) < _ON
        ),
        default=0.0,
    )
    stop = corner[axis] + direction * reach
    for line in lines:
        if line.virtual or line.axis == axis or abs(line.offset - stop) > _FRONT_SLACK:
            continue
        spans = line.seen_spans(_GAP)
        meets = (spans[:, 0] - _GAP <= corner[1 - axis]) & (corner[1 - axis] <= spans[:, 1] + _GAP)
        if np.any(meets & (spans[:, 1] - spans[:, 0] >= _PAST)):
            return 0.0
    return reach


def _seen_end(line: WallLine, start: FloatArray, corner: FloatArray) -> FloatArray | None:
    """Where the wall from ``start`` towards ``corner`` on ``line`` is last seen, walking
    from ``start`` (the far end of the segment reaching farthest that overlaps the chain's
    stretch, past the corner if the wall goes on); None when it is nowhere seen there."""
    spans, direction = _on_stretch(line.seen_spans(_GAP), start, corner, line.axis)
    if not len(spans):
        return None
    reach = float(spans[:, 1].max())
    end = start.copy()
    end[line.axis] += direction * reach
    return end


def _cut(
    kp: FloatArray, i: int, lines: Sequence[WallLine], keep: Keep = "larger"
) -> FloatArray | None:
    """The chain cut at corner ``i``, each part ending where its wall was seen: the larger
    part, or the part ``keep`` says ("before" or "after" the corner); None when that part
    (or neither) is long enough or seen."""
    parts = []
    before_line = wall_line_of(lines, kp[i - 1], kp[i], seen_only=True)
    if before_line is not None and keep != "after":
        end = _seen_end(before_line, kp[i - 1], kp[i])
        if end is not None:
            parts.append(np.vstack([kp[:i], end]))
    after_line = wall_line_of(lines, kp[i], kp[i + 1], seen_only=True)
    if after_line is not None and keep != "before":
        start = _seen_end(after_line, kp[i + 1], kp[i])
        if start is not None:
            parts.append(np.vstack([start, kp[i + 1 :]]))
    parts = [p for p in parts if _length(p) >= _MIN_PART]
    return max(parts, key=_length) if parts else None


def _length(kp: FloatArray) -> float:
    return float(np.linalg.norm(np.diff(kp, axis=0), axis=1).sum())


def _first_seen(line: WallLine | None, corner: FloatArray, far: FloatArray) -> float:
    """How far from ``corner`` (m), walking towards ``far`` along the chain's wall between
    them (on ``line``), its first segment starts (0 when at or before the corner; inf
    when none is there, or the wall was deduced: nothing to judge by). Segments, not any
    wall point: a window's reveal joins the wall outside to the corner at sill height."""
    if line is None:
        return np.inf
    spans, _ = _on_stretch(line.segments, corner, far, line.axis)
    return max(float(spans[:, 0].min(initial=np.inf)), 0.0)


def _contradicted(kp: FloatArray, i: int, lines: Sequence[WallLine]) -> Keep | None:
    """Which part of the chain to keep when its corner ``i`` (0 < i < K - 1) is
    contradicted, else None.

    A left turn (the room's inner corner) with the wall before it seen on behind the next
    wall, or the next wall seen from behind the wall before it (``_PAST``, or
    ``_PAST_UNSEEN`` when the other wall is not seen at the corner): the larger part
    ("larger").
    A right turn (a reflex corner) with the wall before it seen on past it while the next is
    first seen from behind its line (a seen wall, not one deduced across what the camera
    did not see): the part before ("before"); and the other way round ("after").
    """
    before, after = kp[i] - kp[i - 1], kp[i + 1] - kp[i]
    turn = float(cross(before, after))
    a, b = run_axis(before), run_axis(after)
    forward = 1 if before[a] > 0 else -1
    backward = -1 if after[b] > 0 else 1
    if turn == 0.0:
        return None
    line_before = wall_line_of(lines, kp[i - 1], kp[i], seen_only=True)
    line_after = wall_line_of(lines, kp[i], kp[i + 1], seen_only=True)
    if turn > 0.0:
        past_before, past_after = _past(lines, kp[i], a, forward), _past(lines, kp[i], b, backward)
        if max(past_before, past_after) >= _PAST:
            return "larger"
        # The wall seen on farther past the corner, and the other one (whose line it crosses).
        if past_before >= past_after:
            past, unseen = past_before, _first_seen(line_after, kp[i], kp[i + 1])
        else:
            past, unseen = past_after, _first_seen(line_before, kp[i], kp[i - 1])
        return "larger" if past >= _PAST_UNSEEN and unseen >= _UNSEEN_AT else None
    if (
        line_before is not None
        and seen_past(line_before, kp[i], forward) >= _PAST_REFLEX
        and _DETACHED <= _first_seen(line_after, kp[i], kp[i + 1]) < np.inf
    ):
        return "before"
    if (
        line_after is not None
        and seen_past(line_after, kp[i], backward) >= _PAST_REFLEX
        and _DETACHED <= _first_seen(line_before, kp[i], kp[i - 1]) < np.inf
    ):
        return "after"
    return None


def without_corners_seen_past(keypoints: FloatArray, lines: Sequence[WallLine]) -> FloatArray:
    """The chain cut at corners a wall is seen running on past, and with ends that stop at
    such a corner moved to where their own wall was last seen.

    keypoints: (K, 2) float64, aligned frame, interior on the left; lines: the frame's
    candidate walls (the keypoints lie on their offsets).
    """
    kp = keypoints.copy()
    for _ in range(len(keypoints)):
        found = ((i, _contradicted(kp, i, lines)) for i in range(1, len(kp) - 1))
        corner, keep = next(((i, k) for i, k in found if k is not None), (None, None))
        if corner is None or keep is None:
            break
        cut = _cut(kp, corner, lines, keep)
        if cut is None:
            return kp
        kp = cut
    for end, inner in ((len(kp) - 1, len(kp) - 2), (0, 1)):
        if len(kp) < 2:
            break
        a, b = (kp[inner], kp[end]) if end else (kp[end], kp[inner])  # chain order
        axis = 1 - run_axis(b - a)
        if _past(lines, kp[end], axis, _outside(b - a, axis)) < _PAST:
            continue
        line = wall_line_of(lines, a, b, seen_only=True)
        seen = None if line is None else _seen_end(line, kp[inner], kp[end])
        if seen is None:
            continue
        kept = float(np.linalg.norm(seen - kp[inner]))
        if kept >= _MIN_PART and float(np.linalg.norm(kp[end] - seen)) >= _SHORT:
            kp[end] = seen
    return kp
