"""Junction evidence: structure voxels at chain ends, their registration, boundary mismatch."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from schemas.params import PlacementParams
from services.placement import Piece
from services.placement.evidence import (
    EndMatch,
    EndVoxels,
    boundary_mismatch,
    end_voxels,
    register_ends,
)
from tests.conftest import CEILING, FURNITURE, bare_piece, end_boxes, end_shell

pytestmark = pytest.mark.timeout(120)

SHELF = [((-0.8, 1.8, 1.6), (0.8, 2.2, 2.0))]  # something else entirely


def _a_end(rng, boxes=FURNITURE):
    """a: a straight chain ending at the cut, its scan reaching 0.8 m past its end."""
    seen = (-1.0, 0.8)
    piece = bare_piece("a", np.array([[-3.0, 0.0], [0.0, 0.0]]))
    region = np.vstack([end_shell(rng, seen), end_boxes(rng, boxes, seen)]) if boxes else None
    region = end_shell(rng, seen) if region is None else region
    return dataclasses.replace(piece, target_region=region, ceiling=CEILING)


def _b_start(rng, boxes=FURNITURE, shift: float = 0.0):
    """b: a straight chain starting ``shift`` past a's end (negative: they overlap), its scan
    reaching 0.8 m before its start."""
    seen_b = (-0.8, 1.0)
    seen_a = (seen_b[0] + shift, seen_b[1] + shift)
    piece = bare_piece("b", np.array([[0.0, 0.0], [3.0, 0.0]]))
    parts = [end_shell(rng, seen_b)]
    if boxes:
        parts.append(end_boxes(rng, boxes, seen_a, shift))
    return dataclasses.replace(piece, source_region=np.vstack(parts), ceiling=CEILING)


# ---------------------------------------------------------------------------------------------
# end_voxels
# ---------------------------------------------------------------------------------------------


def test_the_shared_planes_are_not_structure():
    rng = np.random.default_rng(0)
    bare = end_voxels(_a_end(rng, boxes=[]), "target")
    assert bare.cells == 0
    assert bare.seen[:2].all() and bare.seen[-2:].sum() == 0  # seen from -1.0 to 0.8 m
    furnished = end_voxels(_a_end(rng), "target")
    assert furnished.cells > 60


def test_the_chain_own_walls_near_the_end_are_not_structure():
    # The chain turns 1 m before its target: in the target's travel frame (+y) its first
    # wall runs across the region at x = -1, y from 0 to 2.
    rng = np.random.default_rng(1)
    piece = bare_piece("c", np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0]]))
    across = np.column_stack(
        [rng.normal(-1.0, 0.005, 2000), rng.uniform(0.1, 2.0, 2000), rng.uniform(0.1, 2.4, 2000)]
    )
    turned = dataclasses.replace(piece, target_region=across, ceiling=CEILING)
    assert end_voxels(turned, "target").cells == 0
    # The same points in front of a straight chain are structure.
    straight = bare_piece("s", np.array([[0.0, 0.0], [0.0, 1.0]]))
    plain = dataclasses.replace(straight, target_region=across, ceiling=CEILING)
    assert end_voxels(plain, "target").cells > 50


def test_a_missing_ceiling_keeps_high_structure():
    rng = np.random.default_rng(2)
    high = np.column_stack([rng.uniform(-0.5, 0.5, 500), rng.uniform(0.5, 1.0, 500)])
    high = np.column_stack([high, np.full(500, CEILING)])
    piece = bare_piece("a", np.array([[-3.0, 0.0], [0.0, 0.0]]))
    with_ceiling = dataclasses.replace(piece, target_region=high, ceiling=CEILING)
    without = dataclasses.replace(piece, target_region=high, ceiling=None)
    assert end_voxels(with_ceiling, "target").cells == 0  # on the ceiling plane
    assert end_voxels(without, "target").cells > 0


def test_an_end_without_points_is_empty():
    empty = end_voxels(bare_piece("a", np.array([[0.0, 0.0], [1.0, 0.0]])), "source")
    assert empty.cells == 0 and not empty.seen.any()


# ---------------------------------------------------------------------------------------------
# register_ends
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("shift", [-0.4, -0.15, 0.0, 0.25])
def test_the_same_structure_registers_at_its_shift(shift):
    rng = np.random.default_rng(10)
    a = end_voxels(_a_end(rng), "target")
    b = end_voxels(_b_start(rng, shift=shift), "source")
    match = register_ends(a, b)
    assert match.score < -0.9
    assert abs(match.shift - shift) <= 0.1 + 1e-9
    assert match.measured_shift == match.shift


def _block_at(column: int) -> EndVoxels:
    """An end seen along its whole grid, with one block of structure in ``column``."""
    occupied = np.zeros((20, 28, 32), dtype=bool)
    occupied[column, 5:8, 5:9] = True
    return EndVoxels(occupied, np.ones(20, dtype=bool))


def test_a_best_shift_at_the_end_of_the_range_is_no_measurement():
    # b's column c lies at a's c + shift: the blocks meet 0.5 m into an overlap (inside the
    # range), or only at the 0.6 m the range ends with, where agreement still rising would
    # be as high for structure along the whole wall, whatever the shift.
    inside = register_ends(_block_at(4), _block_at(9))
    assert inside.shift == pytest.approx(-0.5) and inside.measured_shift == inside.shift
    edge = register_ends(_block_at(4), _block_at(10))
    assert edge.shift == pytest.approx(-0.6) and edge.agreement == 1.0
    assert not edge.bounded and edge.measured_shift is None
    assert edge.score == -1.0  # still evidence that the two ends belong together


def test_different_structures_are_no_evidence_for_the_junction():
    rng = np.random.default_rng(11)
    a = end_voxels(_a_end(rng), "target")
    b = end_voxels(_b_start(rng, boxes=SHELF), "source")
    match = register_ends(a, b)
    assert match.score == 0.0
    assert match.measured_shift is None


def test_structure_on_one_side_only_is_no_evidence_for_the_junction():
    # b's scan saw the floor where a saw a table: the table is not there.
    rng = np.random.default_rng(12)
    a = end_voxels(_a_end(rng), "target")
    b = end_voxels(_b_start(rng, boxes=[]), "source")
    assert register_ends(a, b).score == 0.0


def test_the_same_furniture_a_voxel_off_is_little_evidence():
    # Furniture of the same kind against the wall in two rooms: near, but not the same
    # voxels. A tolerant comparison would call it a junction.
    rng = np.random.default_rng(13)
    a = end_voxels(_a_end(rng), "target")
    moved = [
        ((lo[0], lo[1] + 0.1, lo[2] + 0.1), (hi[0], hi[1] + 0.1, hi[2] + 0.1))
        for lo, hi in FURNITURE
    ]
    b = end_voxels(_b_start(rng, boxes=moved), "source")
    assert register_ends(a, b).score > -0.5


def test_clutter_that_agrees_only_as_often_as_chance_is_no_evidence():
    # Two ends dense with unrelated clutter (a third of every voxel both scans reached):
    # at some shift they share about a third of their voxels, as any two such ends would.
    rng = np.random.default_rng(16)
    a = EndVoxels(rng.random((20, 28, 32)) < 0.33, np.ones(20, dtype=bool))
    b = EndVoxels(rng.random((20, 28, 32)) < 0.33, np.ones(20, dtype=bool))
    match = register_ends(a, b)
    assert match.agreement > 0.3
    assert match.score == 0.0


def test_the_same_clutter_registers_though_clutter_is_everywhere():
    rng = np.random.default_rng(17)
    clutter = rng.random((30, 28, 32)) < 0.33
    a = EndVoxels(clutter[:20], np.ones(20, dtype=bool))
    b = EndVoxels(clutter[3:23], np.ones(20, dtype=bool))  # b's column c is a's c + 3
    match = register_ends(a, b)
    assert match.score == -1.0
    assert match.shift == pytest.approx(0.3)


def test_no_structure_gives_no_evidence():
    rng = np.random.default_rng(13)
    a = end_voxels(_a_end(rng, boxes=[]), "target")
    b = end_voxels(_b_start(rng, boxes=[]), "source")
    assert register_ends(a, b) == EndMatch()


def test_ends_that_never_see_the_same_stretch_give_no_evidence():
    # a saw only 0.75 to 1 m before its end, b only 0.75 to 1 m after its start: more apart
    # than any overlap or gap the registration tries, so there is nothing to compare.
    rng = np.random.default_rng(14)
    box = [((-1.0, 0.6, 0.3), (-0.8, 1.2, 0.9))]
    a_region = np.vstack([end_shell(rng, (-1.0, -0.75)), end_boxes(rng, box, (-1.0, -0.75))])
    b_region = np.vstack([end_shell(rng, (0.75, 1.0)), end_boxes(rng, box, (-1.0, -0.75), -1.8)])
    a_piece, b_piece = _a_end(rng), _b_start(rng)
    a = end_voxels(dataclasses.replace(a_piece, target_region=a_region), "target")
    b = end_voxels(dataclasses.replace(b_piece, source_region=b_region), "source")
    assert a.cells > 10 and b.cells > 10
    assert register_ends(a, b) == EndMatch()


def test_a_speck_of_matching_structure_is_no_evidence():
    rng = np.random.default_rng(15)
    speck = [((0.12, 0.22, 1.22), (0.16, 0.26, 1.26))]  # one or two voxels
    a = end_voxels(_a_end(rng, boxes=speck), "target")
    b = end_voxels(_b_start(rng, boxes=speck), "source")
    assert 0 < a.cells < 4 and 0 < b.cells < 4
    assert register_ends(a, b) == EndMatch()


# ---------------------------------------------------------------------------------------------
# boundary_mismatch (the paper's term)
# ---------------------------------------------------------------------------------------------


def _profile(rng, extra=None, x=(-0.1, 0.1), n=600) -> np.ndarray:
    """Wall and floor in a cutting plane (within the 10 cm band), plus an optional box."""
    parts = [
        np.column_stack([rng.uniform(*x, n), rng.normal(0, 0.005, n), rng.uniform(0, 2.5, n)]),
        np.column_stack([rng.uniform(*x, n), rng.uniform(0, 2.0, n), rng.normal(0, 0.005, n)]),
    ]
    if extra is not None:
        (y0, y1), (z0, z1) = extra
        parts.append(
            np.column_stack([rng.uniform(*x, n), rng.uniform(y0, y1, n), rng.uniform(z0, z1, n)])
        )
    return np.vstack(parts)


def _pair(source_region, target_region) -> tuple[Piece, Piece]:
    chain = np.array([[0.0, 0.0], [3.0, 0.0]])
    a = dataclasses.replace(bare_piece("a", chain), target_region=target_region)
    b = dataclasses.replace(bare_piece("b", chain), source_region=source_region)
    return a, b


def test_boundary_mismatch_of_the_same_profile_is_low():
    rng = np.random.default_rng(20)
    params = PlacementParams()
    same = boundary_mismatch(*_pair(_profile(rng), _profile(rng)), params)
    other = boundary_mismatch(
        *_pair(_profile(rng, extra=((0.5, 1.5), (0.5, 1.5))), _profile(rng)), params
    )
    assert same < 0.1
    assert other > 0.15 and other > same + 0.1
    cabinet = np.column_stack(
        [rng.uniform(-0.1, 0.1, 600), rng.uniform(0.8, 2.0, 600), rng.uniform(1.0, 2.5, 600)]
    )
    assert boundary_mismatch(*_pair(cabinet, _profile(rng)), params) > 0.9


def _as_frames(pair: tuple[Piece, Piece]) -> tuple[Piece, Piece]:
    a, b = pair
    return dataclasses.replace(a, evidence="frame"), dataclasses.replace(b, evidence="frame")


def test_frames_compare_only_the_part_of_the_section_both_saw():
    rng = np.random.default_rng(22)
    params = PlacementParams()
    near = _profile(rng)
    near = near[(near[:, 2] < 1.2) & (near[:, 1] < 0.6)]  # close by: low wall, little floor
    far = _profile(rng)
    clouds = boundary_mismatch(*_pair(near, far), params)
    framed = boundary_mismatch(*_as_frames(_pair(near, far)), params)
    assert framed < 0.1 < clouds
    # What both saw still tells a cabinet from a bare wall.
    cabinet = _profile(rng, extra=((0.0, 0.5), (0.0, 0.9)))
    framed_cabinet = boundary_mismatch(*_as_frames(_pair(near, cabinet)), params)
    assert framed_cabinet > framed + 0.1


def test_boundary_mismatch_without_enough_points_in_the_band_is_neutral():
    rng = np.random.default_rng(21)
    params = PlacementParams()
    few = _profile(rng)[:20]
    assert boundary_mismatch(*_pair(few, _profile(rng)), params) == 0.5
    # Points outside the band do not count, however many.
    away = _profile(rng, x=(0.3, 1.0))
    assert boundary_mismatch(*_pair(away, _profile(rng)), params) == 0.5
