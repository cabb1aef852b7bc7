"""The stored form of a local layout: a layout survives the round trip bit for bit."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from schemas.layout import LocalLayoutWire
from services.types import ChainVariant, Evidence, LocalLayout
from store.layouts import layout_from_wire, layout_to_wire
from tests.conftest import scene_layouts, small_scene

pytestmark = pytest.mark.timeout(300)


def _round_trip(layout: LocalLayout) -> LocalLayout:
    """The layout written to its wire form as JSON and read back."""
    return layout_from_wire(
        LocalLayoutWire.model_validate_json(layout_to_wire(layout).model_dump_json())
    )


def test_layout_survives_the_wire_format():
    layout = scene_layouts()[small_scene("easy", 0).fragments[0].id]
    back = _round_trip(layout)
    assert np.array_equal(back.keypoints, layout.keypoints)
    assert np.array_equal(back.source_boundary, layout.source_boundary)
    assert np.array_equal(back.footprint, layout.footprint)
    assert np.array_equal(back.unchained_walls, layout.unchained_walls)
    assert np.array_equal(back.frame.rotation, layout.frame.rotation)


@pytest.mark.parametrize("evidence", ["cloud", "thin_cloud", "frame"])
def test_what_a_layout_rests_on_survives_the_wire(evidence: Evidence) -> None:
    layout = dataclasses.replace(
        scene_layouts()[small_scene("easy", 0).fragments[0].id], evidence=evidence
    )
    wire = LocalLayoutWire.model_validate_json(layout_to_wire(layout).model_dump_json())
    assert layout_from_wire(wire).evidence == evidence


def test_the_walls_a_chain_does_not_follow_survive_the_wire():
    cells = np.array([[3.0, 0.34], [3.0, 0.42], [-1.5, 2.0]])
    layout = dataclasses.replace(
        scene_layouts()[small_scene("easy", 0).fragments[0].id], unchained_walls=cells
    )
    wire = LocalLayoutWire.model_validate_json(layout_to_wire(layout).model_dump_json())
    assert np.array_equal(layout_from_wire(wire).unchained_walls, cells)
    old = layout_to_wire(layout).model_dump(mode="json")
    del old["unchained_walls"]  # stored before the field existed: none known
    assert layout_from_wire(LocalLayoutWire.model_validate(old)).unchained_walls.shape == (0, 2)


def test_a_stored_layout_without_its_evidence_is_a_clouds():
    # Layouts stored before the field existed read as clouds (a frame stored then keeps the
    # clouds' calibration until it is laid out again).
    layout = scene_layouts()[small_scene("easy", 0).fragments[0].id]
    old = layout_to_wire(layout).model_dump(mode="json")
    del old["evidence"]
    assert layout_from_wire(LocalLayoutWire.model_validate(old)).evidence == "cloud"


def test_a_frames_view_angle_survives_the_wire():
    layout = dataclasses.replace(
        scene_layouts()[small_scene("easy", 0).fragments[0].id], evidence="frame", view_angle=1.4
    )
    wire = layout_to_wire(layout)
    back = _round_trip(layout)
    assert back.view_angle == 1.4
    old = wire.model_dump(mode="json")
    del old["view_angle"]  # stored before the field existed: unknown, no shift
    assert layout_from_wire(LocalLayoutWire.model_validate(old)).view_angle is None


def test_a_frames_cameras_survive_the_wire():
    cameras = np.array([[0.0, 0.0], [0.31, -0.02]])
    layout = dataclasses.replace(
        scene_layouts()[small_scene("easy", 0).fragments[0].id], evidence="frame", cameras=cameras
    )
    wire = layout_to_wire(layout)
    back = _round_trip(layout)
    assert np.array_equal(back.cameras, cameras)
    old = wire.model_dump(mode="json")
    del old["cameras"]  # stored before the field existed: no camera known, no station
    assert layout_from_wire(LocalLayoutWire.model_validate(old)).cameras.shape == (0, 2)
    cloud = scene_layouts()[small_scene("easy", 0).fragments[0].id]
    assert layout_to_wire(cloud).cameras is None


def test_a_frames_view_ranges_survive_the_wire():
    ranges = np.array([[-1.2, 3.4], [-1.19, 3.41]])
    layout = dataclasses.replace(
        scene_layouts()[small_scene("easy", 0).fragments[0].id],
        evidence="frame",
        view_ranges=ranges,
    )
    wire = layout_to_wire(layout)
    back = _round_trip(layout)
    assert np.array_equal(back.view_ranges, ranges)
    old = wire.model_dump(mode="json")
    del old["view_ranges"]  # stored before the field existed: no station told from the view
    assert layout_from_wire(LocalLayoutWire.model_validate(old)).view_ranges.shape == (0, 2)
    cloud = scene_layouts()[small_scene("easy", 0).fragments[0].id]
    assert layout_to_wire(cloud).view_ranges is None


def test_a_frames_runner_up_chain_survives_the_wire():
    runner_up = ChainVariant(
        np.array([[0.0, 0.0], [2.5, 0.0], [2.5, 1.75]]),
        np.array([[0.1, 0.2, 0.3]]),
        np.array([[2.4, 1.7, 0.5], [2.45, 1.72, 1.5]]),
    )
    layout = dataclasses.replace(
        scene_layouts()[small_scene("easy", 0).fragments[0].id],
        evidence="frame",
        runner_up=runner_up,
    )
    wire = layout_to_wire(layout)
    back = _round_trip(layout)
    assert back.runner_up is not None
    assert np.array_equal(back.runner_up.keypoints, runner_up.keypoints)
    assert np.array_equal(back.runner_up.source_boundary, runner_up.source_boundary)
    assert np.array_equal(back.runner_up.target_boundary, runner_up.target_boundary)
    old = wire.model_dump(mode="json")
    del old["runner_up"]  # stored before the field existed: the chain alone is tried
    assert layout_from_wire(LocalLayoutWire.model_validate(old)).runner_up is None
    cloud = scene_layouts()[small_scene("easy", 0).fragments[0].id]
    assert layout_to_wire(cloud).runner_up is None
