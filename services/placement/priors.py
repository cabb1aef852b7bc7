"""Hints as evidence: prior poses, known neighbours and known order (contract section 2).

A prior pose says where a fragment's chain lies in the hints' frame, with standard
deviations. The search scores an assembly's rotations and relative positions against the
priors with a robust (Cauchy) loss, so a hint the scans contradict costs a bounded amount
and is reported instead of obeyed. Known neighbour pairs and order become a cost on the
junctions that break them.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from schemas.hints import FragmentPrior
from services.types import FloatArray, LocalLayout

__all__ = [
    "FrameEstimate",
    "HintPair",
    "PiecePrior",
    "SiteHints",
    "chain_placement",
    "fit_frame",
    "frame_estimate",
    "frame_yaw_fit",
    "hint_pairs",
    "piece_prior",
    "position_costs",
    "position_costs_batch",
    "robust_cost",
    "wrap_angle",
]

_ROBUST_SCALE = 2.0  # nats: beyond a few sigma a hint's cost grows only logarithmically
_REWEIGHTS = 8  # iterations of the robust frame fit
# x and y of a point (x, y) turned by q quarter turns, q = 0..3 (rows).
_QUARTER_X = np.array([[1.0, 0.0], [0.0, -1.0], [-1.0, 0.0], [0.0, 1.0]])
_QUARTER_Y = np.array([[0.0, 1.0], [1.0, 0.0], [0.0, -1.0], [-1.0, 0.0]])
# frame_yaw_fit: how far from fit_frame's yaw it looks (radians), and how finely.
_YAW_SPAN = math.radians(15.0)
_YAW_STEP = math.radians(0.25)
_Angle = TypeVar("_Angle", float, FloatArray)
_OUTLIER_MISFIT = 11.34  # squared Mahalanobis distance: chi-square 99 % with 3 dof (x, y, yaw)


@dataclass(frozen=True)
class PiecePrior:
    """A prior of one piece's placement in the hints frame.

    yaw: angle (radians) of the piece's aligned x axis in the hints frame.
    source: (2,) hints-frame position of the chain's source keypoint.
    sigma_xy: meters; sigma_yaw: radians.
    lever: distance from the source to the middle of what the scan saw, meters.
    """

    yaw: float
    source: FloatArray
    sigma_xy: float
    sigma_yaw: float
    lever: float = 0.0

    @property
    def source_sigma(self) -> float:
        """Standard deviation of the source's position: the prior's own, and what its yaw
        error moves a point ``lever`` meters from the middle of the scan."""
        return math.hypot(self.sigma_xy, self.lever * self.sigma_yaw)


@dataclass(frozen=True)
class HintPair:
    """Two fragments known to be adjacent in the loop; ``directed``: b follows a."""

    a: str
    b: str
    directed: bool


@dataclass(frozen=True)
class SiteHints:
    """Hints resolved to piece ids: priors by piece id, and pair constraints."""

    priors: Mapping[str, PiecePrior] = field(default_factory=dict)
    pairs: tuple[HintPair, ...] = ()

    def prior_sigmas(self) -> dict[str, float]:
        """The standard deviation (m) of each hinted piece's prior position, by piece id."""
        return {fid: prior.source_sigma for fid, prior in self.priors.items()}


def chain_placement(layout: LocalLayout, pose: FloatArray) -> tuple[float, FloatArray]:
    """Where a pose (fragment-local -> some frame, (4, 4)) puts a fragment's chain: the
    yaw of its aligned x axis (radians) and its source keypoint's (2,) position."""
    to_frame = pose[:3, :3] @ layout.frame.rotation.T  # aligned -> frame
    source = pose[:3, :3] @ layout.keypoints_local()[0] + pose[:3, 3]
    return math.atan2(to_frame[1, 0], to_frame[0, 0]), source[:2]


def piece_prior(layout: LocalLayout, prior: FragmentPrior) -> PiecePrior:
    """The prior of a piece from its fragment's prior pose (local -> hints frame)."""
    yaw, source = chain_placement(layout, np.asarray(prior.pose, dtype=np.float64))
    seen = layout.footprint if len(layout.footprint) else layout.keypoints
    lever = float(np.linalg.norm(seen.mean(axis=0) - layout.keypoints[0]))
    yaw_sigma = math.radians(prior.sigma_yaw_deg)
    return PiecePrior(yaw, source, prior.sigma_xy, yaw_sigma, lever)


def wrap_angle(angle: _Angle) -> _Angle:
    """Angle (or array of angles) wrapped to [-pi, pi)."""
    wrapped: _Angle = (angle + math.pi) % (2.0 * math.pi) - math.pi
    return wrapped


def robust_cost(squared: float) -> float:
    """Cauchy loss of a squared Mahalanobis distance: about half of it when small.

    >>> round(robust_cost(0.0), 6), round(robust_cost(0.02), 3)
    (0.0, 0.01)
    """
    return _ROBUST_SCALE * math.log1p(0.5 * squared / _ROBUST_SCALE)


def _robust_costs(squared: FloatArray) -> FloatArray:
    """:func:`robust_cost` of every element of an array."""
    costs: FloatArray = _ROBUST_SCALE * np.log1p(0.5 * squared / _ROBUST_SCALE)
    return costs


def _cauchy_weights(misfit: FloatArray) -> FloatArray:
    """Weights of the reweighted least squares whose loss is :func:`robust_cost`."""
    weights: FloatArray = 1.0 / (1.0 + 0.5 * misfit / _ROBUST_SCALE)
    return weights


def fit_frame(
    priors: Mapping[str, PiecePrior],
    rotations: Mapping[str, int],
    sources: Mapping[str, FloatArray],
) -> tuple[float, FloatArray]:
    """Yaw and (2,) shift of the site -> hints transform that best fits the priors.

    rotations: quarter turns of each piece in the site frame; sources: (2,) site position
    of each piece's source. A weighted fit (circular mean for the yaw), reweighted a few
    times with the Cauchy loss of the search, so that a prior the assembly contradicts
    does not drag the others' frame along.
    """
    ids = [i for i in priors if i in rotations]
    offsets = np.array([wrap_angle(priors[i].yaw - rotations[i] * math.pi / 2) for i in ids])
    yaw_precision = np.array([1.0 / priors[i].sigma_yaw ** 2 for i in ids])
    xy_precision = np.array([1.0 / priors[i].source_sigma ** 2 for i in ids])
    targets = np.array([priors[i].source for i in ids])
    placed = np.array([sources[i] for i in ids])
    weights = np.ones(len(ids))
    for step in range(_REWEIGHTS + 1):
        yaw = float(np.angle(np.sum(weights * yaw_precision * np.exp(1j * offsets))))
        turn = _rotation(yaw)
        residual = targets - placed @ turn.T
        w = weights * xy_precision
        shift = (w[:, None] * residual).sum(axis=0) / w.sum()
        misfit = np.sum((residual - shift) ** 2, axis=1) * xy_precision
        misfit += np.array([wrap_angle(o - yaw) ** 2 for o in offsets]) * yaw_precision
        weights = _cauchy_weights(misfit)
        if step == _REWEIGHTS - 1:
            # Last pass: the priors the assembly contradicts get no say at all.
            inliers = misfit < _OUTLIER_MISFIT
            weights = inliers.astype(np.float64) if inliers.any() else np.ones(len(ids))
    return yaw, shift


def frame_yaw_fit(
    priors: Mapping[str, PiecePrior],
    rotations: Mapping[str, int],
    sources: Mapping[str, FloatArray],
) -> float:
    """The yaw of the site -> hints transform at which an assembly's priors cost least, yaw
    and position together (the search's robust costs; the shift fitted out at each yaw).

    :func:`fit_frame`'s yaw is searched about, within :data:`_YAW_SPAN`: it reads the yaw
    from the pieces' yaw priors alone, while their positions tell it too (a piece 5 m from
    the others, 1.5 m off, says 17 degrees).

    >>> yaw = 0.2
    >>> turn = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    >>> at = {"a": np.zeros(2), "b": np.array([6.0, 0.0]), "c": np.array([0.0, 4.0])}
    >>> priors = {k: PiecePrior(yaw, turn @ v, 1.0, 0.5) for k, v in at.items()}
    >>> round(frame_yaw_fit(priors, dict.fromkeys(at, 0), at), 3)
    0.2
    """
    ids = [i for i in priors if i in rotations]
    near, _ = fit_frame(priors, rotations, sources)
    steps = round(_YAW_SPAN / _YAW_STEP)
    grid = near + _YAW_STEP * np.arange(-steps, steps + 1)  # (G,)
    turned = np.array([priors[i].yaw - rotations[i] * math.pi / 2 for i in ids])  # (k,)
    yaw_sigma = np.array([priors[i].sigma_yaw for i in ids])
    residual = wrap_angle(turned[None, :] - grid[:, None])
    yaw_cost = _robust_costs((residual / yaw_sigma) ** 2)
    placed = np.array([sources[i] for i in ids])  # (k, 2)
    cos, sin = np.cos(grid)[:, None], np.sin(grid)[:, None]
    anchors = np.empty((len(grid), len(ids), 5))
    anchors[:, :, :2] = np.array([priors[i].source for i in ids])
    anchors[:, :, 2] = cos * placed[:, 0] - sin * placed[:, 1]
    anchors[:, :, 3] = sin * placed[:, 0] + cos * placed[:, 1]
    anchors[:, :, 4] = np.array([1.0 / priors[i].source_sigma ** 2 for i in ids])
    position = position_costs_batch(anchors, np.zeros(len(grid), dtype=np.intp))
    return float(grid[int(np.argmin(yaw_cost.sum(axis=1) + position))])


def priors_in_site_frame(
    priors: Mapping[str, PiecePrior],
    rotations: Mapping[str, int],
    sources: Mapping[str, FloatArray],
) -> dict[str, FloatArray]:
    """Each prior's source position (2,) brought into the site frame by the frame
    :func:`fit_frame` fits to the assembly (``rotations``, ``sources`` as there)."""
    yaw, shift = fit_frame(priors, rotations, sources)
    back = _rotation(-yaw)
    return {fid: back @ (prior.source - shift) for fid, prior in priors.items() if fid in rotations}


@dataclass(frozen=True)
class FrameEstimate:
    """The site frame's yaw in the hints frame, from every prior at once.

    The first piece is fixed (rotation 0), so each piece with a prior tells the yaw up to
    its unknown quarter turns, which a prior of less than 45 degrees fixes.
    yaw: radians; variance: rad^2 (the priors' yaw variances combined).
    """

    yaw: float
    variance: float


def frame_estimate(first: str, priors: Mapping[str, PiecePrior]) -> FrameEstimate | None:
    """The frame yaw from the priors, relative to the piece ``first``; None without its prior.

    Every piece's axes are the room's, so all priors agree on the yaw modulo a quarter turn:
    that is their weighted circular mean of four times the yaw. Which quarter turn is the
    first piece's own (it is fixed at rotation 0). Rounding each prior's turn against the
    first one's instead goes wrong as soon as two priors err by 45 degrees between them.

    >>> axis = PiecePrior(0.3, np.zeros(2), 1.0, 0.1)
    >>> turned = PiecePrior(0.3 + math.pi / 2 + 0.05, np.zeros(2), 1.0, 0.1)
    >>> round(frame_estimate("a", {"a": axis, "b": turned}).yaw, 3)
    0.325
    """
    root = priors.get(first)
    if root is None:
        return None
    yaws = np.array([prior.yaw for prior in priors.values()])
    weights = np.array([1.0 / prior.sigma_yaw**2 for prior in priors.values()])
    axis = float(np.angle(np.sum(weights * np.exp(4j * yaws)))) / 4.0
    # Refined by the plain weighted mean of each prior's offset from it (within 45 degrees):
    # the circular mean of four times the angle is pulled towards the wrap at large spread.
    offsets = (yaws - axis + math.pi / 4) % (math.pi / 2) - math.pi / 4
    axis += float(weights @ offsets / weights.sum())
    turns = round(wrap_angle(root.yaw - axis) / (math.pi / 2))
    return FrameEstimate(wrap_angle(axis + turns * math.pi / 2), float(1.0 / weights.sum()))


def position_costs(anchors: Sequence[tuple[float, float, float, float, float]]) -> FloatArray:
    """Robust misfit of the placed pieces' sources to their priors, per quarter turn of the
    frame (4,), the shift between the frames fitted out (iteratively reweighted least
    squares, Cauchy loss).

    anchors: per placed piece with a prior, (px, py, tx, ty, w): its prior source (hints
    frame), its placed source turned by the frame estimate, and 1 / variance. Quarter turn q
    turns the placed sources q times more. Adding an anchor never lowers a cost, so a
    partial assembly's costs bound every completion's.

    >>> costs = position_costs([(0.0, 0.0, 0.0, 0.0, 1.0), (2.0, 0.0, 2.0, 0.0, 1.0)])
    >>> [round(float(c), 3) for c in costs]  # turned by half a turn: 2 m off each, = 2 log 2
    [0.0, 1.622, 2.773, 1.622]
    """
    if len(anchors) < 2:
        return np.zeros(4)
    costs: FloatArray = position_costs_batch(np.asarray(anchors, dtype=np.float64)[None])[0]
    return costs


def position_costs_batch(
    anchors: FloatArray, quarters: NDArray[np.intp] | None = None
) -> FloatArray:
    """:func:`position_costs` of B sets of k anchors at once: (B, k, 5) -> (B, 4); with
    ``quarters`` (B,), only that quarter turn of the frame per set: (B,).

    >>> one = [(0.0, 0.0, 0.0, 0.0, 1.0), (2.0, 0.0, 2.0, 0.0, 1.0)]
    >>> costs = position_costs_batch(np.array([one, one]))
    >>> costs.shape, bool(np.allclose(costs[1], position_costs(one)))
    ((2, 4), True)
    >>> bool(np.array_equal(position_costs_batch(np.array([one]), np.array([2])), costs[:1, 2]))
    True
    """
    if quarters is None:
        # Each quarter turn as a set of its own, as when one is asked for: a set's costs
        # are then the same to the last bit whether its four are costed at once or not.
        every = np.tile(np.arange(4), len(anchors))
        return position_costs_batch(np.repeat(anchors, 4, axis=0), every).reshape(-1, 4)
    # Prior less placed source under the set's quarter turn of the frame, (B, k) per axis
    # (the quarter-turn matrices hold only 0 and 1 in magnitude: the turned sources are exact).
    qx, qy = _QUARTER_X[quarters], _QUARTER_Y[quarters]
    px, py = anchors[:, :, 2], anchors[:, :, 3]
    dx = anchors[:, :, 0] - (px * qx[:, :1] + py * qx[:, 1:])
    dy = anchors[:, :, 1] - (px * qy[:, :1] + py * qy[:, 1:])
    return _robust_fit(dx, dy, anchors[:, :, 4])


def _robust_fit(dx: FloatArray, dy: FloatArray, w: FloatArray) -> FloatArray:
    """Robust cost (B,) of the misfits dx, dy (B, k) of k anchors weighing w (B, k) once the
    best shift between the frames is taken out (reweighted least squares)."""
    # Small arrays: the number of numpy operations is what costs time here, not their size.
    stacked = np.stack([dx, dy, np.ones(dx.shape)], axis=-1)  # (B, k, 3)
    half = 0.5 / _ROBUST_SCALE
    weights = w
    misfit = w
    for _ in range(_REWEIGHTS):
        # Weighted sums of dx, dy and the weights in one product: the fitted shift.
        sums = weights[:, None, :] @ stacked  # (B, 1, 3)
        shift = sums[:, :, :2] / sums[:, :, 2:]
        ex, ey = dx - shift[:, :, 0], dy - shift[:, :, 1]
        misfit = (ex * ex + ey * ey) * w
        weights = w / (misfit * half + 1.0)  # w times the Cauchy weight (_cauchy_weights)
    costs: FloatArray = _robust_costs(misfit).sum(axis=1)
    return costs


def _rotation(angle: float) -> FloatArray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def hint_pairs(neighbours: Sequence[tuple[str, str]], order: Sequence[str]) -> tuple[HintPair, ...]:
    """The hints' pair constraints: neighbours (either may follow the other) and the
    consecutive fragments of the known order (b directly follows a)."""
    undirected = [HintPair(a, b, False) for a, b in neighbours]
    directed = [HintPair(a, b, True) for a, b in itertools.pairwise(order)]
    return tuple(undirected + directed)
