"""The floorplan picture: valid SVG for full, partial and empty results."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

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
