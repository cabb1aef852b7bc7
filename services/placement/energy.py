"""The placement energy: a negative log-likelihood of an assembly, term by term.

An assembly chains the pieces end to end (each source at the previous target). Its energy
is a weighted sum of features (paper 3.2, extended):

* ``turns``: junctions where the loop turns (a corner hidden in the cut), a prior against
  corners the scans did not see (the paper's corner count; the pieces' own corners are
  the same in every assembly);
* ``hull``: edges of the convex hull, the paper's preference for simple rooms;
* ``closure``: how unlikely the gap left at the loop's end is, given that every junction
  hides an unknown overlap or gap along its wall (and a turning junction some wall on both
  sides of its corner): a Gaussian per axis whose variance grows with the junctions along
  that axis, and on both axes with each open end, where a frame's view lost the wall
  (:mod:`services.open_ends`; the paper measures the gap's Manhattan length instead);
* ``structure``: what crosses each junction, seen from both sides
  (:func:`services.placement.evidence.structure_match`);
* ``boundary``: the paper's boundary mismatch per junction;
* ``conflict``: meters of wall that run through space another scan saw empty;
* ``outside``: square meters of floor the scans saw that the closed loop leaves outside
  (the room holds everything its scans saw; a room too small or folded the wrong way
  does not);
* ``prior``: disagreement with the fleet's hints (already a negative log-likelihood).

The weights are fitted so that the energies, as a Boltzmann distribution over the
assemblies found, give calibrated probabilities (``bench/tune_placement.py``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from schemas.params import PlacementParams
from services.geometry import cross, distance_to_polygon, points_in_polygon
from services.placement.pieces import UNIT, Piece, evidence_share
from services.types import FloatArray

__all__ = [
    "FEATURES",
    "JunctionNoise",
    "closure_nll",
    "feature_weights",
    "hull_edges",
    "junction_displacement",
    "outside_area",
]

FEATURES = (
    "turns", "hull", "closure", "structure", "boundary", "conflict", "outside", "prior",
)  # fmt: skip
_HULL_TOLERANCE = 0.35  # m, hull vertices closer than this to their chord are dropped


@dataclass(frozen=True)
class JunctionNoise:
    """What a junction hides, per axis: mean and variance of its displacement.

    A straight junction moves the next piece along the wall by the overlap or gap between
    the two scans (negative: overlap); a turning one by some unseen wall before and after
    the hidden corner. Keypoint noise adds to both axes; an open end
    (:mod:`services.open_ends`) ``open_sigma`` more to both.
    """

    straight_mean: float
    straight_sigma: float
    turn_mean: float
    turn_sigma: float
    keypoint_sigma: float
    measured_sigma: float = 0.06
    open_sigma: float = 1.5

    @classmethod
    def from_params(cls, params: PlacementParams) -> JunctionNoise:
        """The model the placement parameters describe."""
        return cls(
            params.junction_mean,
            params.junction_sigma,
            params.hidden_corner_mean,
            params.hidden_corner_sigma,
            params.keypoint_sigma,
            params.measured_shift_sigma,
            params.open_end_sigma,
        )


def feature_weights(params: PlacementParams, pieces: Sequence[Piece] = ()) -> FloatArray:
    """(len(FEATURES),) weights of the energy's features; switched-off terms weigh 0.

    With ``params.frame_weights`` set, the weights move towards those by the share of
    ``pieces`` that are RGB-D frames."""
    weights = np.array(
        [
            params.weight_turn,
            params.weight_hull,
            params.weight_closure,
            params.weight_structure,
            params.weight_boundary,
            params.weight_conflict,
            params.weight_outside,
        ]
    )
    if params.frame_weights is not None:
        frames = evidence_share(pieces, "frame")
        weights = weights + frames * (np.asarray(params.frame_weights) - weights)
    switches = np.array(
        [
            params.use_complexity,
            params.use_complexity,
            params.use_closure,
            params.use_structure,
            params.use_boundary,
            params.use_free_space,
            params.use_outside,
        ],
        dtype=np.float64,
    )
    return np.append(weights * switches, 1.0)


def junction_displacement(
    noise: JunctionNoise, heading_in: int, heading_out: int, measured: float | None = None
) -> tuple[FloatArray, FloatArray]:
    """Mean (2,) and variance (2,) of one junction's hidden displacement.

    measured: the overlap (negative) or gap along the wall at a straight junction that the
    two ends' structure measured (``EndMatch.measured_shift``), if any.
    """
    mean, var = np.zeros(2), np.full(2, noise.keypoint_sigma**2)
    d_in, d_out = UNIT[heading_in % 4], UNIT[heading_out % 4]
    if heading_in % 4 == heading_out % 4 and measured is not None:
        mean += measured * d_in
        var += noise.measured_sigma**2 * np.abs(d_in)
    elif heading_in % 4 == heading_out % 4:
        mean += noise.straight_mean * d_in
        var += noise.straight_sigma**2 * np.abs(d_in)
    else:
        mean += noise.turn_mean * (d_in + d_out)
        var += noise.turn_sigma**2 * (np.abs(d_in) + np.abs(d_out))
    return mean, var


def closure_nll(end: FloatArray, mean: FloatArray, var: FloatArray) -> float:
    """Negative log-likelihood (up to a constant) of the loop's end gap.

    The hidden displacements must bring the chain's end back to its start: their sum is
    ``-end``, with the given per-axis mean and variance.

    >>> closure_nll(np.zeros(2), np.zeros(2), np.ones(2))
    0.0
    """
    residual = end + mean
    return float(np.sum(0.5 * residual**2 / var + 0.5 * np.log(var)))


def hull_edges(points: FloatArray) -> int:
    """Edges of the convex hull of (M, 2) points (near-collinear vertices dropped).

    >>> hull_edges(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0], [1.0, 0.5]]))
    4
    """
    pts = np.unique(np.round(points, 3), axis=0)
    if len(pts) < 3:
        return len(pts)

    def half(seq: FloatArray) -> list[FloatArray]:
        out: list[FloatArray] = []
        for p in seq:
            while len(out) >= 2:
                o, a = out[-2], out[-1]
                if (a[0] - o[0]) * (p[1] - o[1]) - (a[1] - o[1]) * (p[0] - o[0]) > 1e-9:
                    break
                out.pop()
            out.append(p)
        return out

    hull = np.array(half(pts)[:-1] + half(pts[::-1])[:-1])
    # Unrefined chains leave small gaps; a hull vertex barely off the line through its
    # neighbours is such a gap, not an edge of the room.
    while len(hull) > 3:
        prev, nxt = np.roll(hull, 1, axis=0), np.roll(hull, -1, axis=0)
        chord = nxt - prev
        lever = hull - prev
        off = np.abs(cross(chord, lever))
        off /= np.maximum(np.linalg.norm(chord, axis=1), 1e-9)
        weakest = int(np.argmin(off))
        if off[weakest] >= _HULL_TOLERANCE:
            break
        hull = np.delete(hull, weakest, axis=0)
    return len(hull)


def outside_area(
    cells: Sequence[FloatArray], cell: float, polygon: FloatArray, margin: float, cap: float
) -> float:
    """Square meters of seen floor lying outside a closed (V, 2) loop by more than
    ``margin``, at most ``cap`` per piece; ``cells``: per piece, (M, 2) centres of the
    free cells (side ``cell``) it saw.

    A room holds all the floor its scans saw; floor seen beyond its walls says the room is
    too small, or a piece faces the wrong way. The margin absorbs what the unrefined loop
    still gets wrong at its junctions (overlaps and gaps along the walls, the closure gap);
    the cap, floor seen through another scan's doorway or past a chain that is a little
    wrong, which the true room shows too.

    >>> square = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
    >>> outside_area([np.array([[1.0, 1.0], [4.1, 1.0], [5.0, 1.0]])], 0.5, square, 0.3, 1.0)
    0.25
    """
    counts = [len(c) for c in cells]
    if sum(counts) == 0 or len(polygon) < 3:
        return 0.0
    xy = np.concatenate(cells)
    far = ~points_in_polygon(xy, polygon)
    if far.any():
        far[far] = distance_to_polygon(xy[far], polygon) > margin
    piece = np.repeat(np.arange(len(cells)), counts)
    per_piece = np.bincount(piece, weights=far.astype(np.float64), minlength=len(cells))
    return float(np.minimum(per_piece * cell * cell, cap).sum())
