"""The records passed between stages: snapping a layout to fixed grids."""

from __future__ import annotations

import numpy as np

from tests.conftest import off_in_last_bits, scene_layouts


def test_layouts_that_differ_in_their_last_bits_snap_to_the_same_bits():
    for index, layout in enumerate(scene_layouts("easy", 2, 40_000).values()):
        other = off_in_last_bits(layout, index)
        assert not np.array_equal(other.keypoints, layout.keypoints)  # the test has teeth
        a, b = layout.snapped(), other.snapped()
        for field in ("keypoints", "source_boundary", "target_boundary", "footprint"):
            assert np.array_equal(getattr(a, field), getattr(b, field)), field
        assert np.array_equal(a.frame.rotation, b.frame.rotation)
        assert a.frame.floor_z == b.frame.floor_z
        # Snapped, the layout is where it was to a micrometre, its rotation still a rotation.
        assert np.abs(a.keypoints - layout.keypoints).max() <= 5e-7
        assert np.abs(a.frame.rotation - layout.frame.rotation).max() < 1e-8
        assert np.abs(a.frame.rotation @ a.frame.rotation.T - np.eye(3)).max() < 1e-15
        assert np.linalg.det(a.frame.rotation) > 0
