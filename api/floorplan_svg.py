"""An SVG picture of a placement result: rooms, each fragment's walls and origin, in the site
frame seen from above (x to the right, y up); the caption gives the status and confidence,
and an ambiguous result also shows its most probable runner-up's floorplan, dashed."""

from __future__ import annotations

from html import escape

import numpy as np

from schemas.result import FragmentResultModel, ResultModel, RoomModel
from services.types import FloatArray

__all__ = ["render_floorplan_svg"]

_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf")
_STATUS_COLORS = {
    "closed": "#2ca02c",
    "ambiguous": "#b8860b",
    "open": "#ff7f0e",
    "failed": "#d62728",
}
_ALTERNATIVE_STYLE = 'fill="none" stroke="#555" stroke-width="2" stroke-dasharray="8 6"'


def _polygons(rooms: list[RoomModel]) -> list[FloatArray]:
    return [np.asarray(r.polygon, dtype=np.float64).reshape(-1, 2) for r in rooms]


def _walls_site(fragment: FragmentResultModel) -> FloatArray:
    """(K, 2) wall keypoints of a placed fragment in the site frame (empty if unplaced)."""
    keypoints = np.asarray(fragment.local_layout.keypoints, dtype=np.float64).reshape(-1, 3)
    if fragment.pose is None or not fragment.placed or len(keypoints) == 0:
        return np.zeros((0, 2))
    pose = np.asarray(fragment.pose, dtype=np.float64)
    site: FloatArray = keypoints @ pose[:3, :3].T + pose[:3, 3]
    return np.ascontiguousarray(site[:, :2], dtype=np.float64)


class _View:
    """Maps site-frame meters to SVG pixels (y flipped)."""

    def __init__(self, points: FloatArray, size: int, margin: int) -> None:
        if len(points) == 0:
            points = np.zeros((1, 2))
        self.low: FloatArray = points.min(axis=0)
        span = float(np.max(points.max(axis=0) - self.low)) or 1.0
        self.scale = (size - 2 * margin) / span
        self.margin, self.size = margin, size

    def xy(self, points: FloatArray) -> FloatArray:
        pixels: FloatArray = (points - self.low) * self.scale + self.margin
        pixels[:, 1] = self.size - pixels[:, 1]
        return pixels

    def path(self, points: FloatArray) -> str:
        return " ".join(f"{x:.1f},{y:.1f}" for x, y in self.xy(points))


def render_floorplan_svg(
    result: ResultModel, *, title: str = "", size: int = 800, margin: int = 40
) -> str:
    """Draw a result as a standalone SVG document.

    Parameters
    ----------
    result : ResultModel
        A placement result (contract section 3); unplaced fragments are listed, not drawn.
    title : str
        Caption (e.g. the site id).
    size, margin : int
        Square canvas side and border, pixels.

    Returns
    -------
    str
        The SVG text. An empty result gives a canvas with the caption only.

    Examples
    --------
    >>> render_floorplan_svg(ResultModel(status="failed")).startswith("<svg")
    True
    """
    rooms = _polygons(result.floorplan.rooms)
    ambiguous = result.status == "ambiguous" and result.alternatives
    runner_up = result.alternatives[0] if ambiguous else None
    other_rooms = _polygons(runner_up.floorplan.rooms) if runner_up is not None else []
    walls = [_walls_site(f) for f in result.fragments]
    origins = np.array(
        [np.asarray(f.pose)[:2, 3] for f in result.fragments if f.placed and f.pose is not None]
    ).reshape(-1, 2)
    everything = [*rooms, *other_rooms, *walls, origins, np.zeros((0, 2))]
    view = _View(np.vstack(everything), size, margin)
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{size}" height="{size}" '
        f'viewBox="0 0 {size} {size}" font-family="sans-serif" font-size="12">',
        f'<rect width="{size}" height="{size}" fill="white"/>',
    ]
    for room in rooms:
        if len(room) >= 3:
            parts.append(
                f'<polygon points="{view.path(room)}" fill="#eeeeee" stroke="#333" '
                'stroke-width="2"/>'
            )
    for room in other_rooms:
        if len(room) >= 3:
            parts.append(f'<polygon points="{view.path(room)}" {_ALTERNATIVE_STYLE}/>')
    for index, (fragment, wall) in enumerate(zip(result.fragments, walls, strict=True)):
        color = _COLORS[index % len(_COLORS)]
        label = escape(fragment.id)
        if len(wall) >= 2:
            parts.append(
                f'<polyline points="{view.path(wall)}" fill="none" stroke="{color}" '
                f'stroke-width="4" stroke-linecap="round"><title>{label}</title></polyline>'
            )
        if fragment.placed and fragment.pose is not None:
            x, y = view.xy(np.asarray(fragment.pose)[:2, 3].reshape(1, 2))[0]
            parts.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="4" fill="{color}"/>')
            parts.append(f'<text x="{x + 6:.1f}" y="{y - 6:.1f}" fill="{color}">{label}</text>')
    unplaced = [escape(f.id) for f in result.fragments if not f.placed]
    status_color = _STATUS_COLORS.get(result.status, "#333")
    caption = f"{escape(title)} status: {escape(result.status)}".strip()
    caption += f", confidence {result.confidence:.2f}"
    if result.alternatives:
        caption += f", {len(result.alternatives)} alternative(s)"
    parts.append(f'<text x="10" y="20" font-size="16" fill="{status_color}">{caption}</text>')
    if other_rooms and runner_up is not None:
        legend = f"dashed: the runner-up floorplan (probability {runner_up.probability:.2f})"
        parts.append(f'<text x="10" y="38" fill="#555">{legend}</text>')
    if unplaced:
        parts.append(f'<text x="10" y="{size - 10}">not placed: {", ".join(unplaced)}</text>')
    parts.append("</svg>")
    return "\n".join(parts)
