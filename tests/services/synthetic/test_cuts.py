"""Cuts of the room loop: counts, spacing, margins, corners, and the junctions they make."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from services.synthetic import SceneSpec, SyntheticScene, generate_scene
from services.synthetic.cuts import Cut, arc_cuts, cut_turns, stretches
from services.synthetic.room import Room

pytestmark = pytest.mark.timeout(60)

RECTANGLE = np.array([[0.0, 0.0], [12.0, 0.0], [12.0, 8.0], [0.0, 8.0]])
ARC = replace(
    SceneSpec.paper(),
    cut_model="arc",
    gap_range=(-0.5, 0.3),
    end_margin=0.0,
    points_per_fragment=(1_500, 2_500),
    furniture=False,
    openings=False,
)


def loop_gap(scene: SyntheticScene, from_id: str, to_id: str) -> float:
    """Signed loop distance from one fragment's stretch end to the next one's start."""
    ends = {f.id: f for f in scene.fragments}
    p = scene.perimeter
    return (ends[to_id].loop_start - ends[from_id].loop_end + p / 2) % p - p / 2


@pytest.mark.parametrize("n", [2, 5, 9, 16])
def test_arc_cuts_give_the_requested_count_on_a_four_corner_room(n):
    spec = replace(ARC, n_fragments_range=(n, n))
    room = Room.from_polygon(RECTANGLE, 2.5)
    for seed in range(10):
        cuts = arc_cuts(np.random.default_rng(seed), spec, room)
        assert cuts is not None and len(cuts) == n
        arcs = np.array([room.arcs[c.edge] + c.t for c in cuts])
        assert np.all(np.diff(arcs) > 0.0) and arcs[-1] < room.perimeter
        spacing = np.diff(np.append(arcs, arcs[0] + room.perimeter))
        assert spacing.min() >= spec.min_stretch + spec.gap_range[1] - 1e-9
        assert all(spec.gap_range[0] <= c.gap <= spec.gap_range[1] for c in cuts)
        lengths = [s.length for s in stretches(room, cuts)]
        assert min(lengths) >= spec.min_stretch - 1e-9


def test_a_room_too_short_for_the_count_is_redrawn_or_fitted():
    spec = replace(ARC, n_fragments_range=(16, 16))
    small = Room.from_polygon(RECTANGLE / 2.0, 2.5)  # 20 m: 15 cuts 1.3 m apart at most
    assert arc_cuts(np.random.default_rng(0), spec, small) is None
    assert len(arc_cuts(np.random.default_rng(0), spec, small, fit=True) or []) == 15


def test_sixteen_fragments_on_a_rectangle_many_see_a_single_wall():
    spec = replace(ARC, n_fragments_range=(16, 16))
    scene = generate_scene(spec, 3, outline=RECTANGLE)
    assert len(scene.fragments) == 16 and len(scene.polygon) == 4
    single = [f for f in scene.fragments if f.single_wall]
    assert len(single) >= 12  # at most four stretches hold a corner
    assert all(len(f.keypoints_world) == 2 for f in single)


def test_stretches_cover_the_loop_with_the_truth_gaps():
    overlaps = gaps = 0
    for seed in range(6):
        scene = generate_scene(replace(ARC, n_fragments_range=(6, 12)), seed)
        frags = sorted(scene.fragments, key=lambda f: f.loop_index)
        assert [j.from_id for j in scene.junctions] == [f.id for f in frags]
        assert [j.to_id for j in scene.junctions] == [f.id for f in frags[1:] + frags[:1]]
        for junction in scene.junctions:
            gap = loop_gap(scene, junction.from_id, junction.to_id)
            assert gap == pytest.approx(junction.gap, abs=1e-9)
            assert -0.5 <= junction.gap <= 0.3
            overlaps += junction.gap < -0.1
            gaps += junction.gap > 0.1
        p = scene.perimeter
        lengths = sum((f.loop_end - f.loop_start) % p for f in frags)
        assert lengths + sum(j.gap for j in scene.junctions) == pytest.approx(p, abs=1e-6)
    assert overlaps >= 5 and gaps >= 5


def test_arc_cuts_keep_end_margin_from_corners_unless_on_a_corner():
    spec = replace(ARC, end_margin=0.6, corner_cut_share=0.5, n_fragments_range=(4, 10))
    on_corner = 0
    for seed in range(20):
        room = Room.from_polygon(RECTANGLE * 1.5, 2.5)
        cuts = arc_cuts(np.random.default_rng(seed), spec, room)
        assert cuts is not None
        for c in cuts:
            if c.t == 0.0:
                on_corner += 1
            else:
                assert spec.end_margin - 1e-9 <= c.t <= room.lengths[c.edge] - spec.end_margin
    assert on_corner >= 10


def test_junction_turns_say_where_a_corner_lies_between_neighbours():
    spec = replace(ARC, corner_cut_share=1.0, n_fragments_range=(4, 8), gap_range=(0.05, 0.3))
    turned = 0
    for seed in range(8):
        scene = generate_scene(spec, seed)
        ends = {f.id: f for f in scene.fragments}
        for junction in scene.junctions:
            end = ends[junction.from_id].keypoints_world[-1]
            start = ends[junction.to_id].keypoints_world[0]
            same_wall = np.isclose(end, start, atol=1e-9).any()
            if junction.turn == 0:
                assert same_wall and np.linalg.norm(start - end) == pytest.approx(junction.gap)
            else:
                turned += 1
                assert not same_wall and np.abs(start - end).sum() == pytest.approx(junction.gap)
    assert turned >= 10


def test_cut_turns_count_convex_and_reflex_corners():
    l_room = Room.from_polygon(
        np.array([[0, 0], [8, 0], [8, 3], [5, 3], [5, 6], [0, 6]], dtype=np.float64), 2.5
    )
    cuts = [Cut(1, 0.0, 0.2), Cut(3, 0.0, -0.4), Cut(4, 1.0, 0.3), Cut(5, 0.1, 0.3)]
    # Vertex 1 is convex, vertex 3 reflex; 1 m into edge 4 holds no corner; 0.1 m into
    # edge 5 with 0.15 m either side holds vertex 5 (convex).
    assert cut_turns(l_room, cuts) == [1, -1, 0, 1]


def test_edge_exactly_long_enough_for_two_cuts_does_not_break_the_generator():
    # Seed 70004 draws a 3.8 m edge: exactly two end margins plus a straight stretch, which
    # rounding once made an empty sampling interval.
    spec = replace(
        SceneSpec.paper(),
        n_fragments_range=(16, 16),
        n_corners_range=(16, 16),
        size_range=((14.0, 16.0), (18.0, 20.0)),
        straight_fragments=True,
        points_per_fragment=(500, 500),
        furniture=False,
    )
    scene = generate_scene(spec, 70004)
    assert len(scene.fragments) >= 2


def test_edge_cuts_can_fall_on_corners():
    # A corner then lies in the unseen gap between two neighbours: one ends just before it,
    # the next starts just after it on the perpendicular wall.
    spec = replace(SceneSpec.paper(), corner_cut_share=1.0, points_per_fragment=(500, 500))
    starts_at_corner = 0
    for seed in range(6):
        scene = generate_scene(spec, seed)
        for fragment in scene.fragments:
            start = fragment.keypoints_world[0]
            nearest = np.linalg.norm(scene.polygon - start, axis=1).min()
            assert nearest >= 0.05 - 1e-9  # the corner itself stays unseen
            starts_at_corner += nearest <= 0.2 + 1e-9
        assert sum(abs(j.turn) for j in scene.junctions) <= len(scene.fragments)
    assert starts_at_corner >= 3
