"""Shared corners: two pieces that both saw one corner of the room.

RGB-D stations of one room often overlap by metres, and where such an overlap spans a
corner, that corner is the last of one piece's chain and the first of the next one's.
Joined end to end, the next piece's first wall would start where the last piece ends, as if
a concave corner hid in the cut with a metre or two of unseen wall on each side, which the
closure term rightly finds very unlikely: the true room lost to rooms that fold the
overlap away elsewhere (outside frames, seeds 19-22: 5 of 19 such rooms right, 45 of 62 of
the others). A *shared* junction puts the next piece's first corner on the last piece's:
its first wall overlaps the wall before that corner, its second the wall after it, and the
junction's displacement is known but for the two corners' noise.

Downstream (refinement, floorplan, confidence) a shared junction is a straight one: the
piece entered at the corner loses its first wall (:func:`corner_view`) and the overlap along
the wall after the corner is a measurement, as if the two ends' structure had measured it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from services.placement.pieces import FreeSpace, Piece, rot90
from services.types import FloatArray

__all__ = ["corner_offsets", "corner_shift", "corner_view", "entered_at_corner", "shareable"]

_OUTRUN = 0.05  # m, the next piece's wall after the corner must run on past the last's end
_OVERRUN = 0.3  # m, its wall before the corner may reach this far past the last's


def shareable(a: Piece, b: Piece) -> bool:
    """Whether b may follow a at a shared corner: both are RGB-D frames, a's last corner
    and b's first turn the same way, b's wall after the corner runs on past a's end (else b
    would lie inside a's stretch, or turn across a's last wall) and b's wall before it
    reaches no further back than a's (give or take ``_OVERRUN``; further, it would overlap
    the piece before a, which a straight junction there does not allow)."""
    if a.id == b.id or a.evidence != "frame" or b.evidence != "frame":
        return False
    if a.last_turn == 0 or a.last_turn != b.first_turn:
        return False
    last, first = a.wall_lengths, b.wall_lengths
    return bool(first[1] > last[-1] + _OUTRUN and first[0] <= last[-2] + _OVERRUN)


def corner_shift(a: Piece, a_rotation: int, b: Piece, b_rotation: int) -> FloatArray:
    """(2,) b's source less a's target, site frame, when b follows a at a shared corner:
    back along a's last wall to the corner, then back along b's first wall."""
    pa, pb = a.rotated[a_rotation][0], b.rotated[b_rotation][0]
    shift: FloatArray = -(pa[-1] - pa[-2]) - (pb[1] - pb[0])
    return shift


def entered_at_corner(piece: Piece) -> Piece:
    """The piece without its first wall, its source at its first corner: how a piece that
    follows another at a shared corner joins it (a straight junction, overlapping)."""
    corner = piece.keypoints[1]
    free = piece.free
    moved = FreeSpace(
        free.grid, free.origin - corner, free.cell, free.lo - corner, free.hi - corner
    )
    return replace(
        piece,
        keypoints=piece.keypoints[1:] - corner,
        directions=piece.directions[1:],
        source_region=np.zeros((0, 3)),  # the end regions lie at the old source
        footprint=piece.footprint - corner,
        free=moved,
        cameras=piece.cameras - corner,
        open_ends=(False, piece.open_ends[1]),
    )


def corner_offsets(
    ordered: Sequence[Piece], rotations: Sequence[int], shared: Sequence[bool]
) -> FloatArray:
    """(n, 2) how far each piece's source moves, site frame, when :func:`corner_view`
    enters it at its first corner: along its first wall where it follows the piece before
    at a shared corner, nowhere elsewhere. ``shared``: per loop position (position 0: the
    junction closing the loop; see ``PlacementCandidate.shared``), empty for none."""
    out = np.zeros((len(ordered), 2))
    for k, is_shared in enumerate(shared):
        if is_shared:
            out[k] = rot90(rotations[k]) @ ordered[k].keypoints[1]
    return out


def corner_view(
    ordered: Sequence[Piece],
    shared: Sequence[bool],
    measured: Mapping[tuple[str, str], float],
) -> tuple[list[Piece], dict[tuple[str, str], float]]:
    """A loop with shared corners as one of plain junctions: the pieces in loop order with
    each one entered at a corner replaced by :func:`entered_at_corner` (its source moved by
    :func:`corner_offsets`), and ``measured`` (overlaps along the wall by ordered pair of
    ids) with each shared junction's overlap in it: the earlier piece's wall after the
    corner, which both saw."""
    out, known = list(ordered), dict(measured)
    for k, is_shared in enumerate(shared):
        if is_shared:
            prev, piece = ordered[k - 1], ordered[k]
            out[k] = entered_at_corner(piece)
            known[prev.id, piece.id] = -float(prev.wall_lengths[-1])
    return out, known
