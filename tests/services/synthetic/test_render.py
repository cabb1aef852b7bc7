"""A frame's true wall chain is the stretch of the room's loop its camera can see: parts its
rays reach first, not edge-on, not slivers, and one chain (hidden parts only where the walls
seen on both sides tell what lies between)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest

from services.synthetic.render import (
    FrameSpec,
    _ray_hits,
    _view_offsets,
    _visible_stretch,
    generate_frame_scene,
)
from services.synthetic.room import Room
from services.synthetic.scan import Stretch, stretch_keypoints
from services.types import FloatArray

pytestmark = pytest.mark.timeout(120)

SPEC = FrameSpec()


def seen(
    polygon: Sequence[Sequence[float]], camera: Sequence[float], yaw_deg: float
) -> FloatArray | None:
    """(K, 2) keypoints of the chain a Kinect at ``camera`` heading ``yaw_deg`` sees."""
    room = Room.from_polygon(np.array(polygon), 2.5)
    angles = math.radians(yaw_deg) + _view_offsets(SPEC.intrinsics)
    _, arc, edge = _ray_hits(room, np.array(camera), angles)
    stretch = _visible_stretch(room, edge, arc, angles, SPEC)
    return None if stretch is None else stretch_keypoints(room, Stretch(*stretch))


def test_a_sliver_of_wall_past_a_corner_is_not_in_the_chain() -> None:
    # The left image edge sees 0.2 m of the top wall: the chain ends in the corner.
    kp = seen([[0, 0], [8, 0], [8, 5], [0, 5]], [4.0, 2.5], 2.0)
    assert kp is not None
    expected = [[8.0, 2.5 - 4.0 * math.tan(math.radians(29.33))], [8.0, 5.0]]
    np.testing.assert_allclose(kp, expected, atol=0.03)


def test_a_wall_seen_edge_on_is_not_in_the_chain() -> None:
    # The bottom wall lies under 10 degrees from every ray that reaches it.
    kp = seen([[0, 0], [12, 0], [12, 8], [0, 8]], [1.5, 1.2], 22.0)
    assert kp is not None
    np.testing.assert_allclose(kp[:2], [[12.0, 0.0], [12.0, 8.0]], atol=1e-9)


def test_a_wall_hidden_between_two_seen_walls_stays_in_the_chain() -> None:
    # A block stands in the room from the bottom wall; its right side faces away from the
    # camera, but the block's top is seen to its corner: the side lies there.
    block: list[list[float]] = [
        [0, 0],
        [1.5, 0],
        [1.5, 1.6],
        [2.7, 1.6],
        [2.7, 0],
        [5, 0],
        [5, 6.5],
        [0, 6.5],
    ]
    kp = seen(block, [2.2, 3.4], -75.0)
    assert kp is not None
    np.testing.assert_allclose(kp[1:-1], [[2.7, 1.6], [2.7, 0.0], [5.0, 0.0]], atol=1e-9)
    assert kp[0][1] == pytest.approx(1.6) and kp[-1][0] == pytest.approx(5.0)


def test_walls_behind_a_protruding_corner_split_the_view_into_two_chains() -> None:
    # An L-shaped room: past its inner corner the camera sees the far wall, but neither the
    # wing's side nor its end, so nothing tells where the wing ends.
    ell = [[0, 0], [6, 0], [6, 3], [2, 3], [2, 6], [0, 6]]
    assert seen(ell, [4.0, 1.5], 120.0) is None
    assert seen(ell, [4.0, 1.5], 90.0) is not None  # the near walls only: one chain


def test_every_frame_sees_both_ends_of_its_chain() -> None:
    scene = generate_frame_scene(SPEC, 1003)
    room = Room.from_polygon(scene.polygon, scene.ceiling_z)
    for frame in scene.frames:
        camera = frame.pose[:2, 3]
        for end in (frame.keypoints_world[0], frame.keypoints_world[-1]):
            heading = end - camera
            distance, _, _ = _ray_hits(room, camera, np.array([math.atan2(*heading[::-1])]))
            assert distance[0] == pytest.approx(np.linalg.norm(heading), abs=1e-6), frame.id
