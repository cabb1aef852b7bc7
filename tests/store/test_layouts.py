"""The stored form of a local layout: a layout survives the round trip bit for bit."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from schemas.layout import LocalLayoutWire
from store.layouts import layout_from_wire, layout_to_wire
from tests.conftest import scene_layouts, small_scene

pytestmark = pytest.mark.timeout(300)


def test_layout_survives_the_wire_format():
    layout = scene_layouts()[small_scene("easy", 0).fragments[0].id]
    back = layout_from_wire(
        LocalLayoutWire.model_validate_json(layout_to_wire(layout).model_dump_json())
    )
    assert np.array_equal(back.keypoints, layout.keypoints)
    assert np.array_equal(back.source_boundary, layout.source_boundary)
    assert np.array_equal(back.footprint, layout.footprint)
    assert np.array_equal(back.frame.rotation, layout.frame.rotation)


@pytest.mark.parametrize("from_frames", [False, True])
def test_whether_a_layout_came_from_frames_survives_the_wire(from_frames: bool) -> None:
    layout = dataclasses.replace(
        scene_layouts()[small_scene("easy", 0).fragments[0].id], from_frames=from_frames
    )
    wire = LocalLayoutWire.model_validate_json(layout_to_wire(layout).model_dump_json())
    assert layout_from_wire(wire).from_frames is from_frames


def test_a_stored_layout_without_the_frames_flag_is_a_clouds():
    # Layouts stored before the flag existed were all estimated from point clouds.
    layout = scene_layouts()[small_scene("easy", 0).fragments[0].id]
    old = layout_to_wire(layout).model_dump(mode="json")
    del old["from_frames"]
    assert layout_from_wire(LocalLayoutWire.model_validate(old)).from_frames is False
