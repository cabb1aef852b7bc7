"""Outline cleaning: near-Manhattan outlines in, clean rectilinear CCW polygons (or None) out."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.geometry import signed_area
from services.synthetic.room import Room
from services.synthetic.shapes import (
    OutlineLimits,
    clean_outline,
    dominant_angle,
    is_simple_rectilinear,
)

pytestmark = pytest.mark.timeout(30)

L_ROOM = np.array([[0, 0], [8, 0], [8, 3], [5, 3], [5, 6], [0, 6]], dtype=np.float64)


def rotate(points: np.ndarray, degrees: float) -> np.ndarray:
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return points @ np.array([[c, -s], [s, c]]).T


def same_shape(a: np.ndarray, b: np.ndarray, atol: float) -> bool:
    """Equal polygons up to a quarter turn, a shift and the starting vertex."""
    for quarter in range(4):
        turned = rotate(b, 90.0 * quarter)
        turned = turned - turned.min(axis=0)
        shifted = a - a.min(axis=0)
        for start in range(len(b)):
            if np.allclose(np.roll(turned, -start, axis=0), shifted, atol=atol):
                return True
    return False


def assert_clean(polygon: np.ndarray | None) -> np.ndarray:
    assert polygon is not None
    assert is_simple_rectilinear(polygon)
    assert signed_area(polygon) > 0.0
    assert np.allclose(polygon.min(axis=0), 0.0)
    room = Room.from_polygon(polygon, 2.5)
    assert np.all(room.lengths > 0.0)
    return polygon


@pytest.mark.parametrize("degrees", [-40.0, -7.0, 0.0, 4.0, 30.0, 95.0])
def test_slightly_rotated_l_comes_back_rectilinear(degrees):
    rng = np.random.default_rng(1)
    noisy = rotate(L_ROOM, degrees) + rng.normal(scale=0.01, size=L_ROOM.shape) + [3.0, -2.0]
    cleaned = assert_clean(clean_outline(noisy))
    assert len(cleaned) == 6
    assert signed_area(cleaned) == pytest.approx(signed_area(L_ROOM), rel=0.02)
    assert same_shape(np.round(cleaned, 1), L_ROOM, atol=0.05)


def test_clockwise_input_comes_back_counter_clockwise():
    cleaned = assert_clean(clean_outline(L_ROOM[::-1]))
    assert same_shape(cleaned, L_ROOM, atol=1e-9)


def test_repeated_collinear_and_closing_vertices_are_merged():
    square = np.array(
        [[0, 0], [2, 0], [2, 0], [4, 0], [4, 2.5], [4, 4], [0, 4], [0, 0.0000001], [0, 0]]
    )
    cleaned = assert_clean(clean_outline(square))
    assert same_shape(cleaned, np.array([[0, 0], [4, 0], [4, 4], [0, 4.0]]), atol=1e-6)


def test_a_short_jog_is_snapped_away():
    # A 10 cm step in the bottom wall: below the 0.3 m minimum edge, so the two halves of the
    # wall meet on one line at their length-weighted mean (y = 0.06).
    jog = np.array([[0, 0], [4, 0], [4, 0.1], [10, 0.1], [10, 5], [0, 5.0]])
    cleaned = assert_clean(clean_outline(jog))
    assert len(cleaned) == 4
    assert np.allclose(cleaned.max(axis=0), [10.0, 5.0 - 0.06])
    kept = assert_clean(clean_outline(jog, OutlineLimits(min_edge=0.05)))
    assert len(kept) == 6


def test_non_manhattan_pentagon_is_rejected():
    angles = np.radians(90.0 + 72.0 * np.arange(5))
    pentagon = 4.0 * np.column_stack([np.cos(angles), np.sin(angles)])
    assert clean_outline(pentagon) is None


def test_a_mostly_manhattan_room_with_one_long_slanted_wall_is_rejected():
    # A trapezoid: the slanted wall is 26 degrees off and a fifth of the perimeter.
    trapezoid = np.array([[0, 0], [8, 0], [8, 4], [2, 4.0]])
    assert clean_outline(trapezoid) is None
    # A small chamfer (3 % of the perimeter) is fine: it is snapped onto an axis.
    chamfer = np.array([[0, 0], [8, 0], [8, 3.6], [7.6, 4], [0, 4.0]])
    assert len(assert_clean(clean_outline(chamfer))) == 4


@pytest.mark.parametrize(
    "outline",
    [
        np.array([[0, 0], [1.8, 0], [1.8, 1.8], [0, 1.8]]),  # 3.2 m2 < 4 m2
        np.array([[0, 0], [9, 0], [9, 1.2], [0, 1.2]]),  # 1.2 m wide < 1.5 m
        np.zeros((3, 2)),
        np.array([[0, 0], [4, 0], [4, np.nan], [0, 4]]),
    ],
)
def test_small_thin_or_degenerate_outlines_are_rejected(outline):
    assert clean_outline(outline) is None


def test_self_intersecting_outline_is_rejected():
    # Two rectangles drawn as one loop whose walls cross twice: rectilinear but not simple.
    crossing = np.array(
        [[0, 0], [4, 0], [4, 4], [8, 4], [8, 8], [6, 8], [6, 2], [0, 2.0]], dtype=np.float64
    )
    assert not is_simple_rectilinear(crossing)
    assert clean_outline(crossing) is None


def comb(teeth: int) -> np.ndarray:
    """A comb of 1 m wide, 3 m long teeth on a 3 m deep base: 4 * teeth corners, CCW."""
    width = 2.0 * teeth - 1.0
    notches = [
        [[2.0 * i, 6.0], [2.0 * i, 3.0], [2.0 * i - 1, 3.0], [2.0 * i - 1, 6.0]]
        for i in range(teeth - 1, 0, -1)
    ]
    top = np.array(notches).reshape(-1, 2)
    return np.vstack([[[0.0, 0.0], [width, 0.0], [width, 6.0]], top, [[0.0, 6.0]]])


def test_corner_limits():
    assert len(assert_clean(clean_outline(comb(4)))) == 16
    assert len(assert_clean(clean_outline(comb(5), OutlineLimits(max_corners=20)))) == 20
    assert clean_outline(comb(5)) is None


def test_dominant_angle_is_in_a_quarter_turn():
    for degrees in (-44.0, -10.0, 0.0, 10.0, 45.0, 80.0, 135.0):
        angle = math.degrees(dominant_angle(rotate(L_ROOM, degrees)))
        assert -45.0 < angle <= 45.0
        assert (angle - degrees) % 90.0 == pytest.approx(0.0, abs=1e-6) or (
            angle - degrees
        ) % 90.0 == pytest.approx(90.0, abs=1e-6)
