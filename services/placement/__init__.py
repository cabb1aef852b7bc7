"""Global placement (paper 3.2): each fragment's rotation and place in the room loop.

``pieces`` prepares the wall chains, ``evidence`` compares neighbouring chain ends,
``energy`` scores an assembly, ``priors`` turns the fleet's hints into costs, and
``search`` finds the best assemblies; :func:`place_pieces` is the stage's entry.
"""

from services.placement.pieces import (
    Piece,
    direction_index,
    evidence_share,
    make_piece,
    open_end_count,
    rot90,
)
from services.placement.priors import SiteHints, hint_pairs, piece_prior
from services.placement.search import (
    Placement,
    PlacementCandidate,
    evaluate_placement,
    loop_frame_yaw,
    place_pieces,
    translations_of,
)

__all__ = [
    "Piece",
    "Placement",
    "PlacementCandidate",
    "SiteHints",
    "direction_index",
    "evaluate_placement",
    "evidence_share",
    "hint_pairs",
    "loop_frame_yaw",
    "make_piece",
    "open_end_count",
    "piece_prior",
    "place_pieces",
    "rot90",
    "translations_of",
]
