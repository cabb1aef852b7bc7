"""Hints as evidence: prior of a piece, robust cost, frame fit, pair constraints."""

from __future__ import annotations

import math

import numpy as np
import pytest

from schemas.hints import FragmentPrior
from services.placement.priors import (
    HintPair,
    PiecePrior,
    fit_frame,
    frame_estimate,
    hint_pairs,
    piece_prior,
    position_costs_batch,
    robust_cost,
    wrap_angle,
)
from services.types import LocalLayout, ManhattanFrame

pytestmark = pytest.mark.timeout(120)


def _rz(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot2(angle: float) -> np.ndarray:
    return _rz(angle)[:2, :2]


# ---------------------------------------------------------------------------------------------
# piece_prior
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("align", "pose_yaw"), [(0.0, 0.0), (-0.3, 0.5), (1.2, -2.8)])
def test_piece_prior_is_the_chain_in_the_hints_frame(align, pose_yaw):
    # aligned = Rz(align) @ local; the prior pose maps local to hints: Rz(pose_yaw), t.
    frame = ManhattanFrame(rotation=_rz(align), floor_z=0.3, ceiling_z=2.8)
    keypoints = np.array([[1.0, 2.0], [4.0, 2.0], [4.0, 5.0]])
    layout = LocalLayout(keypoints=keypoints, frame=frame)
    pose = np.eye(4)
    pose[:3, :3] = _rz(pose_yaw)
    pose[:3, 3] = [7.0, -3.0, 0.5]
    prior = piece_prior(layout, FragmentPrior(pose=pose.tolist(), sigma_xy=1.5, sigma_yaw_deg=20))
    # The aligned frame turns by pose_yaw - align to reach the hints frame.
    assert wrap_angle(prior.yaw - (pose_yaw - align)) == pytest.approx(0.0, abs=1e-9)
    expected = _rot2(pose_yaw - align) @ keypoints[0] + np.array([7.0, -3.0])
    assert prior.source == pytest.approx(expected)
    assert prior.sigma_xy == 1.5
    assert prior.sigma_yaw == pytest.approx(math.radians(20))


def test_piece_prior_of_a_tilted_scan_keeps_the_yaw():
    # A scan tilted by 2 degrees about x: the aligned frame undoes the tilt.
    tilt = np.array(
        [
            [1.0, 0.0, 0.0],
            [0.0, math.cos(0.035), -math.sin(0.035)],
            [0.0, math.sin(0.035), math.cos(0.035)],
        ]
    )
    frame = ManhattanFrame(rotation=_rz(0.4) @ tilt, floor_z=0.0, ceiling_z=None)
    layout = LocalLayout(keypoints=np.array([[0.0, 0.0], [2.0, 0.0]]), frame=frame)
    pose = np.eye(4)
    pose[:3, :3] = _rz(0.9) @ tilt  # the true pose: local -> world
    prior = piece_prior(layout, FragmentPrior(pose=pose.tolist()))
    assert prior.yaw == pytest.approx(0.5, abs=1e-6)
    assert prior.source == pytest.approx([0.0, 0.0], abs=1e-9)


# ---------------------------------------------------------------------------------------------
# robust_cost and wrap_angle
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("squared", [0.0, 1e-4, 0.01, 0.1])
def test_robust_cost_is_half_the_squared_distance_when_small(squared):
    assert robust_cost(squared) == pytest.approx(0.5 * squared, rel=0.03, abs=1e-12)


def test_robust_cost_grows_only_logarithmically_when_large():
    assert robust_cost(100.0) < 0.2 * 50.0
    # Ten times the squared distance far out costs about log(10) times the scale more.
    step = robust_cost(1e5) - robust_cost(1e4)
    assert step == pytest.approx(2.0 * math.log(10.0), rel=0.01)
    costs = [robust_cost(s) for s in (0.0, 1.0, 10.0, 100.0, 1e4, 1e8)]
    assert costs == sorted(costs) and len(set(costs)) == len(costs)


@pytest.mark.parametrize(
    ("angle", "wrapped"),
    [(0.0, 0.0), (math.pi, -math.pi), (-math.pi, -math.pi), (3 * math.pi / 2, -math.pi / 2)],
)
def test_wrap_angle(angle, wrapped):
    assert wrap_angle(angle) == pytest.approx(wrapped)


# ---------------------------------------------------------------------------------------------
# fit_frame
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("yaw", "shift"), [(0.0, (0.0, 0.0)), (0.7, (3.0, -2.0)), (-2.9, (-5, 1))])
def test_fit_frame_recovers_the_site_to_hints_transform(yaw, shift):
    rotations = {"a": 0, "b": 3, "c": 2, "d": 1}
    sources = {
        "a": np.array([0.0, 0.0]),
        "b": np.array([4.0, 0.5]),
        "c": np.array([3.0, 6.0]),
        "d": np.array([-1.0, 4.0]),
    }
    sigmas = {"a": (0.5, 0.1), "b": (2.0, 0.3), "c": (1.0, 0.05), "d": (1.5, 0.2)}
    turn, t = _rot2(yaw), np.array(shift, dtype=float)
    priors = {
        k: PiecePrior(
            yaw=wrap_angle(yaw + rotations[k] * math.pi / 2),
            source=turn @ sources[k] + t,
            sigma_xy=sigmas[k][0],
            sigma_yaw=sigmas[k][1],
        )
        for k in rotations
    }
    found_yaw, found_shift = fit_frame(priors, rotations, sources)
    assert wrap_angle(found_yaw - yaw) == pytest.approx(0.0, abs=1e-9)
    assert found_shift == pytest.approx(t)


def test_fit_frame_weighs_priors_by_precision():
    # Two priors disagree by 1 m; the sure one (sigma 0.1) wins over the vague one (10).
    rotations = {"a": 0, "b": 0}
    sources = {"a": np.zeros(2), "b": np.array([2.0, 0.0])}
    priors = {
        "a": PiecePrior(0.0, np.array([0.0, 0.0]), 0.1, 0.05),
        "b": PiecePrior(0.0, np.array([3.0, 0.0]), 10.0, 0.05),
    }
    _, shift = fit_frame(priors, rotations, sources)
    assert shift == pytest.approx([0.0001, 0.0], abs=1e-3)


def test_fit_frame_ignores_priors_of_unplaced_pieces():
    rotations = {"a": 1}
    sources = {"a": np.array([1.0, 1.0])}
    priors = {
        "a": PiecePrior(math.pi / 2, np.array([1.0, 1.0]), 1.0, 0.1),
        "gone": PiecePrior(2.0, np.array([50.0, 50.0]), 1.0, 0.1),
    }
    yaw, shift = fit_frame(priors, rotations, sources)
    assert yaw == pytest.approx(0.0, abs=1e-9)
    assert shift == pytest.approx([0.0, 0.0], abs=1e-9)


# ---------------------------------------------------------------------------------------------
# hint_pairs
# ---------------------------------------------------------------------------------------------


def test_hint_pairs_from_neighbours_and_order():
    pairs = hint_pairs([("a", "d"), ("c", "b")], ["b", "a", "c"])
    assert pairs == (
        HintPair("a", "d", False),
        HintPair("c", "b", False),
        HintPair("b", "a", True),
        HintPair("a", "c", True),
    )


def test_hint_pairs_of_nothing():
    assert hint_pairs([], []) == ()
    assert hint_pairs([], ["a"]) == ()  # a one-fragment order says nothing


def test_frame_estimate_takes_the_axis_from_every_prior_and_the_turn_from_the_first():
    # The room's axes lie at 0 degrees; six priors err by up to 30 degrees, the first one
    # +30, the others mostly the other way. Rounding each one's quarter turn against the
    # first put one of them a quarter turn off and the frame 11 degrees off the axes; the
    # priors' mean error is -2.5 degrees.
    errors = [30.0, -20.0, -15.0, -10.0, 5.0, -5.0]
    priors = {
        f"p{k}": PiecePrior(math.radians(e + 90.0 * k), np.zeros(2), 1.0, 0.35)
        for k, e in enumerate(errors)
    }
    frame = frame_estimate("p0", priors)
    assert frame is not None
    assert math.degrees(frame.yaw) == pytest.approx(-2.5)  # the first piece's quarter turn
    assert frame.variance == pytest.approx(0.35**2 / 6)
    assert frame_estimate("absent", priors) is None


def test_position_costs_of_one_quarter_turn_are_those_of_all_four_to_the_last_bit():
    # The search fits only the quarter turns that can be a child's least: their costs
    # must be the very numbers the four at once give, padding rows of zero weight included.
    rng = np.random.default_rng(7)
    anchors = rng.normal(0.0, 3.0, (40, 6, 5))
    anchors[..., 4] = rng.uniform(0.05, 2.0, (40, 6))
    anchors[:, :2, 4] = 0.0
    every = position_costs_batch(anchors)
    assert every.shape == (40, 4)
    quarters = rng.integers(0, 4, 40)
    assert np.array_equal(position_costs_batch(anchors, quarters), every[np.arange(40), quarters])
    some = np.array([3, 17, 29])
    assert np.array_equal(
        position_costs_batch(anchors[some], quarters[some]), every[some, quarters[some]]
    )
