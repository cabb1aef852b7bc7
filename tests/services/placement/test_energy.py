"""The placement energy's terms: closure likelihood, junction noise, hull edges, weights,
floor seen outside the room."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from schemas.params import PlacementParams
from services.placement.energy import (
    FEATURES,
    JunctionNoise,
    closure_nll,
    feature_weights,
    hull_edges,
    junction_displacement,
    outside_area,
)
from services.placement.pieces import UNIT, Piece
from services.types import Evidence
from tests.conftest import bare_piece

pytestmark = pytest.mark.timeout(120)

NOISE = JunctionNoise(
    straight_mean=-0.2, straight_sigma=0.3, turn_mean=0.15, turn_sigma=0.4, keypoint_sigma=0.05
)


# ---------------------------------------------------------------------------------------------
# closure_nll
# ---------------------------------------------------------------------------------------------


def test_closure_is_most_likely_when_the_hidden_displacements_close_the_loop():
    mean, var = np.array([0.3, -0.2]), np.array([0.09, 0.25])
    best = closure_nll(-mean, mean, var)
    assert best == pytest.approx(0.5 * np.log(var).sum())
    rng = np.random.default_rng(0)
    for step in rng.normal(0.0, 0.2, size=(50, 2)):
        assert closure_nll(-mean + step, mean, var) > best


def test_closure_cost_grows_with_the_gap():
    mean, var = np.zeros(2), np.array([0.1, 0.1])
    costs = [closure_nll(np.array([gap, 0.0]), mean, var) for gap in (0.0, 0.1, 0.5, 1.0, 3.0)]
    assert costs == sorted(costs) and len(set(costs)) == len(costs)
    # Quadratic: twice the gap, four times the excess over the minimum.
    excess = [c - costs[0] for c in costs]
    assert excess[3] == pytest.approx(4 * excess[2])
    # Each axis is scored against its own variance.
    along_y = closure_nll(np.array([0.0, 1.0]), mean, np.array([0.1, 1.0]))
    along_x = closure_nll(np.array([1.0, 0.0]), mean, np.array([0.1, 1.0]))
    assert along_y < along_x


def test_more_variance_forgives_a_gap():
    end, mean = np.array([1.0, -0.5]), np.zeros(2)
    tight, loose = np.array([0.05, 0.05]), np.array([0.5, 0.5])
    quad = lambda v: closure_nll(end, mean, v) - 0.5 * np.log(v).sum()  # noqa: E731
    assert quad(loose) < quad(tight)
    assert quad(loose) == pytest.approx(0.5 * (1.0 + 0.25) / 0.5)
    # For a large gap the whole cost falls too; for no gap the spread costs more.
    assert closure_nll(end, mean, loose) < closure_nll(end, mean, tight)
    assert closure_nll(np.zeros(2), mean, loose) > closure_nll(np.zeros(2), mean, tight)


# ---------------------------------------------------------------------------------------------
# junction_displacement
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("heading", range(4))
def test_a_straight_junction_moves_along_its_wall(heading):
    mean, var = junction_displacement(NOISE, heading, heading)
    along = [0, 1, 0, 1][heading]
    unit = [(1, 0), (0, 1), (-1, 0), (0, -1)][heading]
    assert mean == pytest.approx(-0.2 * np.array(unit))
    assert var[along] == pytest.approx(0.3**2 + 0.05**2)
    assert var[1 - along] == pytest.approx(0.05**2)


@pytest.mark.parametrize(("heading_in", "heading_out"), [(0, 1), (1, 2), (2, 3), (3, 0), (1, 0)])
def test_a_turning_junction_spreads_over_both_axes(heading_in, heading_out):
    units = np.array([(1, 0), (0, 1), (-1, 0), (0, -1)], dtype=float)
    mean, var = junction_displacement(NOISE, heading_in, heading_out)
    assert mean == pytest.approx(0.15 * (units[heading_in] + units[heading_out]))
    assert var == pytest.approx(np.full(2, 0.4**2 + 0.05**2))


def test_junction_headings_wrap():
    for a, b in ((0, 4), (5, 1), (-1, 3)):
        m1, v1 = junction_displacement(NOISE, a, b)
        m2, v2 = junction_displacement(NOISE, a % 4, b % 4)
        assert np.allclose(m1, m2) and np.allclose(v1, v2)


def test_junction_noise_from_params():
    params = PlacementParams(
        junction_mean=-0.1,
        junction_sigma=0.2,
        hidden_corner_mean=0.3,
        hidden_corner_sigma=0.25,
        keypoint_sigma=0.02,
        measured_shift_sigma=0.04,
    )
    assert JunctionNoise.from_params(params) == JunctionNoise(-0.1, 0.2, 0.3, 0.25, 0.02, 0.04)


@pytest.mark.parametrize("heading", range(4))
def test_a_measured_overlap_replaces_the_model_along_the_wall(heading):
    mean, var = junction_displacement(NOISE, heading, heading, measured=-0.4)
    along = np.abs(UNIT[heading]) > 0.5
    assert mean[along] == pytest.approx(-0.4 * UNIT[heading][along])
    assert var[along] == pytest.approx(NOISE.keypoint_sigma**2 + NOISE.measured_sigma**2)
    assert mean[~along] == 0.0 and var[~along] == pytest.approx(NOISE.keypoint_sigma**2)
    # A turning junction has no overlap along one wall to measure: the model stands.
    turned = junction_displacement(NOISE, heading, heading + 1, measured=-0.4)
    model = junction_displacement(NOISE, heading, heading + 1)
    assert np.array_equal(turned[0], model[0]) and np.array_equal(turned[1], model[1])


# ---------------------------------------------------------------------------------------------
# hull_edges
# ---------------------------------------------------------------------------------------------


def test_hull_of_a_rectangle_with_extra_points_has_four_edges():
    rect = np.array([[0, 0], [6, 0], [6, 3], [0, 3]], dtype=float)
    midpoints = np.array([[3, 0], [6, 1.5], [3, 3], [0, 1.5], [2, 1], [4, 2]], dtype=float)
    assert hull_edges(rect) == 4
    assert hull_edges(np.vstack([rect, midpoints, rect])) == 4  # repeats and inner points


def test_hull_of_an_l_room_has_five_edges(l_room):
    assert hull_edges(l_room) == 5
    # The notch of a U room is invisible to the hull.
    u_room = np.array([[0, 0], [9, 0], [9, 6], [6, 6], [6, 2], [3, 2], [3, 6], [0, 6]], float)
    assert hull_edges(u_room) == 4


def test_hull_ignores_small_gaps_of_unrefined_chains():
    # A rectangle whose chains leave 10 to 20 cm steps at the junctions.
    jagged = np.array(
        [[0, 0], [4, 0], [4.0, 0.1], [6, 0.1], [6, 3], [5.85, 3], [0, 3.0], [0.2, 1.5]], float
    )
    assert hull_edges(jagged) == 4
    # A real chamfer, 1.5 m across, is an edge.
    chamfered = np.array([[0, 0], [6, 0], [6, 2], [5, 3], [0, 3]], float)
    assert hull_edges(chamfered) == 5


def test_hull_of_degenerate_input():
    assert hull_edges(np.zeros((0, 2))) == 0
    assert hull_edges(np.array([[1.0, 1.0], [1.0, 1.0]])) == 1
    assert hull_edges(np.array([[0.0, 0.0], [2.0, 0.0]])) == 2
    assert hull_edges(np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]])) == 3


# ---------------------------------------------------------------------------------------------
# feature_weights
# ---------------------------------------------------------------------------------------------


SWITCHED = {
    "use_complexity": ("turns", "hull"),
    "use_closure": ("closure",),
    "use_structure": ("structure",),
    "use_boundary": ("boundary",),
    "use_free_space": ("conflict",),
    "use_outside": ("outside",),
}


def test_feature_weights_follow_the_params():
    params = PlacementParams(
        weight_turn=1.5,
        weight_hull=0.5,
        weight_closure=2.0,
        weight_structure=3.0,
        weight_boundary=0.25,
        weight_conflict=4.0,
        weight_outside=5.0,
    )
    weights = dict(zip(FEATURES, feature_weights(params).tolist(), strict=True))
    assert weights == {
        "turns": 1.5,
        "hull": 0.5,
        "closure": 2.0,
        "structure": 3.0,
        "boundary": 0.25,
        "conflict": 4.0,
        "outside": 5.0,
        "prior": 1.0,
    }


@pytest.mark.parametrize("switch", sorted(SWITCHED))
def test_a_switched_off_term_weighs_zero(switch):
    full = dict(zip(FEATURES, feature_weights(PlacementParams()).tolist(), strict=True))
    params = PlacementParams(**{switch: False})
    weights = dict(zip(FEATURES, feature_weights(params).tolist(), strict=True))
    for name in FEATURES:
        if name in SWITCHED[switch]:
            assert weights[name] == 0.0
        else:
            assert weights[name] == full[name] > 0.0
    assert weights["prior"] == 1.0  # hints are never switched off


def _pieces(kinds: list[Evidence]) -> list[Piece]:
    wall = np.array([[0.0, 0.0], [2.0, 0.0]])
    return [
        dataclasses.replace(bare_piece(f"p{k}", wall), evidence=kind)
        for k, kind in enumerate(kinds)
    ]


FRAME_WEIGHTS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7)


def test_frames_take_their_own_weights_in_their_share_of_the_pieces():
    params = PlacementParams(frame_weights=FRAME_WEIGHTS)
    clouds = feature_weights(params, _pieces(["cloud", "cloud"]))
    frames = feature_weights(params, _pieces(["frame", "frame"]))
    half = feature_weights(params, _pieces(["frame", "thin_cloud"]))
    assert np.array_equal(clouds, feature_weights(params))
    assert frames.tolist() == pytest.approx([*FRAME_WEIGHTS, 1.0])
    assert half.tolist() == pytest.approx(((clouds + frames) / 2).tolist())


def test_without_frame_weights_frames_weigh_as_clouds():
    params = PlacementParams(frame_weights=None)
    assert np.array_equal(feature_weights(params, _pieces(["frame"])), feature_weights(params))


def test_a_switched_off_term_weighs_zero_for_frames_too():
    params = PlacementParams(frame_weights=FRAME_WEIGHTS, use_structure=False)
    weights = dict(zip(FEATURES, feature_weights(params, _pieces(["frame"])).tolist(), strict=True))
    assert weights["structure"] == 0.0
    assert weights["boundary"] == pytest.approx(0.5)


SQUARE = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])


def _cells(x0: float, x1: float, y0: float, y1: float, cell: float = 0.25) -> np.ndarray:
    xs, ys = np.meshgrid(np.arange(x0, x1, cell) + cell / 2, np.arange(y0, y1, cell) + cell / 2)
    return np.column_stack([xs.ravel(), ys.ravel()])


def test_floor_inside_the_room_is_not_outside():
    assert outside_area([_cells(0.0, 4.0, 0.0, 4.0)], 0.25, SQUARE, 0.3, 10.0) == 0.0


def test_floor_within_the_margin_is_not_outside():
    # One column of cells whose centres lie 0.125 m past the wall.
    assert outside_area([_cells(4.0, 4.25, 0.0, 4.0)], 0.25, SQUARE, 0.3, 10.0) == 0.0


def test_floor_beyond_the_margin_counts_its_area():
    # A 1 x 2 m block from 0.5 m past the wall: 32 cells of 1/16 m².
    area = outside_area([_cells(4.5, 5.5, 1.0, 3.0)], 0.25, SQUARE, 0.3, 10.0)
    assert area == pytest.approx(2.0)


def test_outside_floor_counts_at_most_the_cap_per_piece():
    block = _cells(4.5, 5.5, 1.0, 3.0)
    assert outside_area([block], 0.25, SQUARE, 0.3, 0.5) == pytest.approx(0.5)
    assert outside_area([block, block], 0.25, SQUARE, 0.3, 0.5) == pytest.approx(1.0)


def test_pieces_without_floor_add_nothing():
    block = _cells(4.5, 5.5, 1.0, 3.0)
    empty = np.zeros((0, 2))
    assert outside_area([empty, block, empty], 0.25, SQUARE, 0.3, 10.0) == pytest.approx(2.0)
    assert outside_area([empty], 0.25, SQUARE, 0.3, 10.0) == 0.0
