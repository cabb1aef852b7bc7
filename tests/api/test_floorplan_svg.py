"""The floorplan picture: valid SVG for full, partial and empty results."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from api.colors import fragment_color
from api.floorplan_svg import render_floorplan_svg
from schemas.result import ResultModel

pytestmark = pytest.mark.timeout(10)

NS = "{http://www.w3.org/2000/svg}"


def _pose(yaw_deg: float, tx: float, ty: float) -> list[list[float]]:
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    return [[c, -s, 0, tx], [s, c, 0, ty], [0, 0, 1, 0], [0, 0, 0, 1]]


def test_full_result() -> None:
    result = ResultModel.model_validate(
        {
            "status": "closed",
            "fragments": [
                {
                    "id": "a<&>",
                    "placed": True,
                    "pose": _pose(0, 0, 0),
                    "loop_index": 0,
                    "local_layout": {"keypoints": [[0, 0, 0], [4, 0, 0], [4, 3, 0]]},
                },
                {
                    "id": "b",
                    "placed": True,
                    "pose": _pose(180, 4, 3),
                    "loop_index": 1,
                    "local_layout": {"keypoints": [[0, 0, 0], [4, 0, 0], [4, 3, 0]]},
                },
                {"id": "c", "placed": False},
            ],
            "floorplan": {"rooms": [{"id": "room_0", "polygon": [[0, 0], [4, 0], [4, 3], [0, 3]]}]},
        }
    )
    root = ET.fromstring(render_floorplan_svg(result, title="site-1"))
    assert root.tag == f"{NS}svg"
    assert len(root.findall(f"{NS}polygon")) == 1
    lines = root.findall(f"{NS}polyline")
    title = lines[0].find(f"{NS}title")
    assert len(lines) == 2 and title is not None and title.text == "a<&>"
    texts = " ".join(t.text or "" for t in root.findall(f"{NS}text"))
    assert "site-1" in texts and "closed" in texts and "not placed: c" in texts
    # Site-frame y up becomes SVG y down; everything inside the canvas.
    polygon = root.find(f"{NS}polygon")
    assert polygon is not None
    points = str(polygon.get("points"))
    xy = np.array([[float(v) for v in p.split(",")] for p in points.split()])
    assert xy.min() >= 0 and xy.max() <= 800
    assert xy[2, 1] < xy[1, 1]  # (4, 3) is drawn above (4, 0)


@pytest.mark.parametrize(
    "result",
    [
        ResultModel(status="failed"),
        ResultModel.model_validate({"status": "open", "fragments": [{"id": "x", "placed": False}]}),
        ResultModel.model_validate(
            {"status": "open", "fragments": [{"id": "x", "placed": True, "pose": _pose(0, 1, 1)}]}
        ),
    ],
)
def test_degenerate_results(result: ResultModel) -> None:
    root = ET.fromstring(render_floorplan_svg(result))
    assert root.tag == f"{NS}svg"


def test_ambiguous_result_shows_confidence_and_the_runner_up_dashed() -> None:
    square = [[0, 0], [4, 0], [4, 3], [0, 3]]
    swapped = [[0, 0], [3, 0], [3, 4], [0, 4]]
    result = ResultModel.model_validate(
        {
            "status": "ambiguous",
            "confidence": 0.6,
            "fragments": [{"id": "a", "placed": True, "pose": _pose(0, 0, 0)}],
            "floorplan": {"rooms": [{"id": "room_0", "polygon": square}]},
            "alternatives": [
                {
                    "probability": 0.35,
                    "fragments": [{"id": "a", "pose": _pose(90, 0, 0)}],
                    "floorplan": {"rooms": [{"id": "room_0", "polygon": swapped}]},
                }
            ],
        }
    )
    root = ET.fromstring(render_floorplan_svg(result, title="s"))
    polygons = root.findall(f"{NS}polygon")
    assert len(polygons) == 2
    dashed = [p for p in polygons if p.get("stroke-dasharray")]
    assert len(dashed) == 1 and dashed[0].get("fill") == "none"
    texts = " ".join(t.text or "" for t in root.findall(f"{NS}text"))
    assert "ambiguous" in texts and "confidence 0.60" in texts and "1 alternative" in texts
    assert "probability 0.35" in texts
    # A closed result: the confidence too, and no dashed runner-up.
    closed = result.model_copy(update={"status": "closed", "confidence": 0.97})
    root = ET.fromstring(render_floorplan_svg(closed))
    assert not [p for p in root.findall(f"{NS}polygon") if p.get("stroke-dasharray")]
    assert "confidence 0.97" in " ".join(t.text or "" for t in root.findall(f"{NS}text"))


def test_colours_by_id_labels_at_walls_legend_and_scale_bar() -> None:
    fragments = [
        {
            "id": fid,
            "placed": True,
            "pose": _pose(yaw, tx, ty),
            "local_layout": {"keypoints": [[0, 0, 0], [6, 0, 0], [6, 4, 0]]},
        }
        for fid, yaw, tx, ty in (("north", 180, 6, 4), ("south", 0, 0, 0))
    ]
    room = {"id": "room_0", "polygon": [[0, 0], [6, 0], [6, 4], [0, 4]]}
    result = ResultModel.model_validate(
        {"status": "closed", "fragments": fragments, "floorplan": {"rooms": [room]}}
    )
    root = ET.fromstring(render_floorplan_svg(result))
    swapped = result.model_copy(update={"fragments": result.fragments[::-1]})
    again = ET.fromstring(render_floorplan_svg(swapped))
    for svg in (root, again):  # the colour follows the id, not the order
        strokes = {p.get("data-fragment"): p.get("stroke") for p in svg.iter(f"{NS}polyline")}
        assert strokes == {"north": fragment_color("north"), "south": fragment_color("south")}
    polygon = root.find(f"{NS}polygon")
    assert polygon is not None
    corners = np.array(
        [[float(v) for v in p.split(",")] for p in str(polygon.get("points")).split()]
    )
    low, high = corners.min(axis=0), corners.max(axis=0)
    labels = {t.text: t for t in root.iter(f"{NS}text") if t.get("class") == "label"}
    for fid in ("north", "south"):
        x, y = float(labels[fid].get("x", 0)), float(labels[fid].get("y", 0))
        assert low[0] <= x <= high[0] and low[1] <= y <= high[1]  # inside the room
        assert min(abs(y - low[1]), abs(y - high[1])) < 25  # beside a long wall, not at the origin
    assert float(labels["south"].get("y", 0)) > float(labels["north"].get("y", 0))
    legend = [t.text for t in root.iter(f"{NS}text")]
    assert "fragments" in legend and legend.count("north") == 2  # label and legend entry
    bar = [t.text or "" for t in root.iter(f"{NS}text") if t.text and t.text.endswith(" m")]
    assert len(bar) == 1 and float(bar[0].split()[0]) in (0.5, 1.0, 2.0, 5.0)
