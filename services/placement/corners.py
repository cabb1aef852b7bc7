"""Shared corners: two pieces that both saw one corner of the room.

RGB-D stations of one room often overlap by metres, and where such an overlap spans a
corner, that corner is the last of one piece's chain and the first of the next one's.
Joined end to end, the next piece's first wall would start where the last piece ends, as if
a concave corner hid in the cut with a metre or two of unseen wall on each side, which the
closure term rightly finds very unlikely: the true room lost to rooms that fold the
overlap away elsewhere (outside frames, seeds 19-22: 5 of 19 such rooms right, 45 of 62 of
the others). A *shared* junction puts the next piece's first corner on the last piece's:
its first wall overlaps the wall before that corner, its second the wall after it, and the
junction's displacement is known but for the two corners' noise. An overlap may span two
corners: the next piece's first two on the last piece's last two, the wall between them as
long in both.

Downstream (refinement, floorplan, confidence) a shared junction is a straight one: the
piece entered at its last shared corner loses the walls before it (:func:`corner_view`) and
the overlap along the wall after that corner is a measurement, as if the two ends'
structure had measured it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from services.placement.pieces import FreeSpace, Piece, rot90
from services.types import FloatArray

__all__ = [
    "MOST_SHARED",
    "corner_offsets",
    "corner_shift",
    "corner_view",
    "entered_at_corner",
    "shared_turn",
    "sharings",
]

MOST_SHARED = 2  # corners two pieces may share at one junction
_OUTRUN = 0.05  # m, the next piece's wall after the corners must run on past the last's end
_OVERRUN = 0.3  # m, its wall before the corners may reach this far past the last's
# m, a wall between two shared corners, seen whole by both pieces, is as long in both
_SAME_WALL = 0.25


def sharings(a: Piece, b: Piece) -> tuple[int, ...]:
    """How many corners b may share with a when it follows a (none: empty).

    Both must be RGB-D frames; a's last k corners turn as b's first k do; the walls between
    them are as long in both (within ``_SAME_WALL``); b's wall after them runs on past a's
    end (else b would lie inside a's stretch, or turn across a's last wall); and b's wall
    before them reaches no further back than a's (give or take ``_OVERRUN``; further, it
    would overlap the piece before a, which a straight junction there does not allow).
    """
    if a.id == b.id or a.evidence != "frame" or b.evidence != "frame":
        return ()
    last, first = a.wall_lengths, b.wall_lengths
    out = []
    for k in range(1, MOST_SHARED + 1):
        if len(last) < k + 1 or len(first) < k + 1:
            break
        if a.turns[len(a.turns) - k :] != b.turns[:k]:
            continue
        between = np.abs(last[len(last) - k : -1] - first[1:k])
        if (between > _SAME_WALL).any():
            continue
        if first[k] > last[-1] + _OUTRUN and first[0] <= last[-1 - k] + _OVERRUN:
            out.append(k)
    return tuple(out)


def shared_turn(piece: Piece, corners: int) -> int:
    """The turn (quarter turns, left positive) of a junction into ``piece`` sharing its
    first ``corners`` corners: back by as much as they turn."""
    return -sum(piece.turns[:corners])


def corner_shift(a: Piece, a_rotation: int, b: Piece, b_rotation: int, corners: int) -> FloatArray:
    """(2,) b's source less a's target, site frame, when b follows a sharing ``corners``
    corners: back along a's last wall to its last corner, then back along b's chain from
    its corner ``corners`` to its source."""
    pa, pb = a.rotated[a_rotation][0], b.rotated[b_rotation][0]
    shift: FloatArray = -(pa[-1] - pa[-2]) - (pb[corners] - pb[0])
    return shift


def entered_at_corner(piece: Piece, corners: int) -> Piece:
    """The piece without its first ``corners`` walls, its source at that corner: how a
    piece that follows another sharing that many corners joins it (a straight junction,
    overlapping)."""
    corner = piece.keypoints[corners]
    free = piece.free
    moved = FreeSpace(
        free.grid, free.origin - corner, free.cell, free.lo - corner, free.hi - corner
    )
    return replace(
        piece,
        keypoints=piece.keypoints[corners:] - corner,
        directions=piece.directions[corners:],
        source_region=np.zeros((0, 3)),  # the end regions lie at the old source
        footprint=piece.footprint - corner,
        free=moved,
        cameras=piece.cameras - corner,
        open_ends=(False, piece.open_ends[1]),
    )


def corner_offsets(
    ordered: Sequence[Piece], rotations: Sequence[int], shared: Sequence[int]
) -> FloatArray:
    """(n, 2) how far each piece's source moves, site frame, when :func:`corner_view`
    enters it at a shared corner: along its chain to that corner where it follows the piece
    before sharing corners, nowhere elsewhere. ``shared``: per loop position, how many
    corners that piece shares with the one before (position 0: at the junction closing the
    loop; see ``PlacementCandidate.shared``), empty for none."""
    out = np.zeros((len(ordered), 2))
    for k, corners in enumerate(shared):
        if corners:
            out[k] = rot90(rotations[k]) @ ordered[k].keypoints[corners]
    return out


def corner_view(
    ordered: Sequence[Piece],
    shared: Sequence[int],
    measured: Mapping[tuple[str, str], float],
) -> tuple[list[Piece], dict[tuple[str, str], float]]:
    """A loop with shared corners as one of plain junctions: the pieces in loop order with
    each one entered at a shared corner replaced by :func:`entered_at_corner` (its source
    moved by :func:`corner_offsets`), and ``measured`` (overlaps along the wall by ordered
    pair of ids) with each shared junction's overlap in it: the earlier piece's wall after
    its last corner, which both saw."""
    out, known = list(ordered), dict(measured)
    for k, corners in enumerate(shared):
        if corners:
            prev, piece = ordered[k - 1], ordered[k]
            out[k] = entered_at_corner(piece, corners)
            known[prev.id, piece.id] = -float(prev.wall_lengths[-1])
    return out, known
