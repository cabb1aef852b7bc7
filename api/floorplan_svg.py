"""An SVG picture of a placement result: rooms and each fragment's walls in the site frame seen
from above (x to the right, y up).

Each fragment has its colour by id (:func:`api.colors.fragment_color`, the same in every
picture and in the web view) and its label at its walls, inside the room; a legend lists the
fragments, a scale bar gives its length in meters; the caption gives the status and
confidence, and an ambiguous result also shows its most probable runner-up's floorplan, dashed.
"""

from __future__ import annotations

from html import escape

import numpy as np

from api.colors import fragment_color
from schemas.result import FragmentResultModel, ResultModel, RoomModel
from services.types import FloatArray

__all__ = ["label_anchor", "nice_length", "render_floorplan_svg"]

_STATUS_COLORS = {
    "closed": "#2ca02c",
    "ambiguous": "#b8860b",
    "open": "#ff7f0e",
    "failed": "#d62728",
}
_ALTERNATIVE_STYLE = 'fill="none" stroke="#555" stroke-width="2" stroke-dasharray="8 6"'
_LEGEND_WIDTH = 200  # px right of the drawing
_LABEL_GAP = 8.0  # px between a wall and its label
_SCALE_BAR_PX = (60.0, 160.0)  # the bar's length on screen lies in this range


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


def nice_length(meters: float) -> float:
    """The largest of 1, 2, 5 x 10^k (k integer) not above ``meters`` (> 0).

    Examples
    --------
    >>> nice_length(3.7), nice_length(0.3), nice_length(10.0)
    (2.0, 0.2, 10.0)
    """
    power = 10.0 ** np.floor(np.log10(meters))
    for step in (5.0, 2.0, 1.0):
        if step * power <= meters * (1 + 1e-9):
            return float(step * power)
    return float(power)


def label_anchor(chain: FloatArray, towards: FloatArray, gap: float) -> tuple[float, float, str]:
    """Where a fragment's label goes, in SVG pixels (y down): beside the middle of its longest
    wall, ``gap`` away on the side of ``towards`` (the middle of all walls, inside the room).

    Parameters
    ----------
    chain : (K, 2) float64
        The fragment's wall keypoints, pixels; K >= 1.
    towards : (2,) float64
        A point on the side the label goes, pixels.
    gap : float
        Pixels between the wall and the label.

    Returns
    -------
    tuple of (float, float, str)
        Text position (x, baseline y) and its ``text-anchor`` (start, end or middle).

    Examples
    --------
    >>> label_anchor(np.array([[0.0, 0.0], [40.0, 0.0]]), np.array([20.0, 30.0]), 8.0)
    (20.0, 18.0, 'middle')
    >>> label_anchor(np.array([[0.0, 0.0], [0.0, 40.0]]), np.array([-9.0, 20.0]), 8.0)
    (-8.0, 24.0, 'end')
    """
    a, b = chain[0], chain[0]
    if len(chain) > 1:
        i = int(np.argmax(np.linalg.norm(np.diff(chain, axis=0), axis=1)))
        a, b = chain[i], chain[i + 1]
    x, y = float(a[0] + b[0]) / 2, float(a[1] + b[1]) / 2
    if abs(b[0] - a[0]) < abs(b[1] - a[1]):  # a vertical wall: the label left or right of it
        side = 1.0 if towards[0] >= x else -1.0
        return x + side * gap, y + 4, "start" if side > 0 else "end"
    below = towards[1] >= y
    return x, y + (gap + 10 if below else -gap), "middle"


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


def _rooms(rooms: list[FloatArray], others: list[FloatArray], view: _View) -> list[str]:
    parts = [
        f'<polygon points="{view.path(room)}" fill="#eeeeee" stroke="#333" stroke-width="2"/>'
        for room in rooms
        if len(room) >= 3
    ]
    parts += [
        f'<polygon points="{view.path(room)}" {_ALTERNATIVE_STYLE}/>'
        for room in others
        if len(room) >= 3
    ]
    return parts


def _fragments(result: ResultModel, walls: list[FloatArray], view: _View) -> list[str]:
    """Each placed fragment's wall chain in its colour, its label at its walls."""
    drawn = [w for w in walls if len(w)]
    middle = np.vstack(drawn).mean(axis=0) if drawn else np.zeros(2)
    middle_px = view.xy(middle.reshape(1, 2))[0]
    parts = []
    for fragment, wall in zip(result.fragments, walls, strict=True):
        if len(wall) == 0:
            continue
        color, label = fragment_color(fragment.id), escape(fragment.id)
        if len(wall) >= 2:
            parts.append(
                f'<polyline points="{view.path(wall)}" fill="none" stroke="{color}" '
                f'stroke-width="4" stroke-linecap="round" data-fragment="{label}">'
                f"<title>{label}</title></polyline>"
            )
        x, y, anchor = label_anchor(view.xy(wall), middle_px, _LABEL_GAP)
        parts.append(
            f'<text x="{x:.1f}" y="{y:.1f}" fill="{color}" text-anchor="{anchor}" '
            f'font-weight="bold" class="label">{label}</text>'
        )
    return parts


def _scale_bar(view: _View) -> list[str]:
    """A bar of a round length in meters at the bottom left, with its length written."""
    meters = nice_length(_SCALE_BAR_PX[1] / view.scale)
    pixels = meters * view.scale
    x, y = 10.0, view.size - 28.0
    text = f"{meters:g} m"
    return [
        f'<g class="scale-bar"><path d="M{x:.1f},{y - 5:.1f} V{y:.1f} H{x + pixels:.1f} '
        f'V{y - 5:.1f}" fill="none" stroke="#000" stroke-width="2"/>'
        f'<text x="{x + pixels / 2:.1f}" y="{y - 8:.1f}" text-anchor="middle">{text}</text></g>'
    ]


def _legend(result: ResultModel, left: int) -> list[str]:
    parts = [f'<text x="{left}" y="20" font-weight="bold">fragments</text>']
    for row, fragment in enumerate(result.fragments):
        y = 40 + 18 * row
        note = "" if fragment.placed else " (not placed)"
        parts.append(
            f'<rect x="{left}" y="{y - 10}" width="12" height="12" '
            f'fill="{fragment_color(fragment.id)}"/>'
            f'<text x="{left + 18}" y="{y}">{escape(fragment.id)}{note}</text>'
        )
    return parts


def _captions(result: ResultModel, title: str, size: int) -> list[str]:
    status_color = _STATUS_COLORS.get(result.status, "#333")
    caption = f"{escape(title)} status: {escape(result.status)}".strip()
    caption += f", confidence {result.confidence:.2f}"
    if result.alternatives:
        caption += f", {len(result.alternatives)} alternative(s)"
    parts = [f'<text x="10" y="20" font-size="16" fill="{status_color}">{caption}</text>']
    if result.status == "ambiguous" and result.alternatives:
        probability = result.alternatives[0].probability
        legend = f"dashed: the runner-up floorplan (probability {probability:.2f})"
        parts.append(f'<text x="10" y="38" fill="#555">{legend}</text>')
    unplaced = [escape(f.id) for f in result.fragments if not f.placed]
    if unplaced:
        parts.append(f'<text x="10" y="{size - 10}">not placed: {", ".join(unplaced)}</text>')
    return parts


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
        Side of the square drawing and its border, pixels; the legend adds 200 px on the
        right.

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
    other_rooms = _polygons(result.alternatives[0].floorplan.rooms) if ambiguous else []
    walls = [_walls_site(f) for f in result.fragments]
    view = _View(np.vstack([*rooms, *other_rooms, *walls, np.zeros((0, 2))]), size, margin)
    width = size + _LEGEND_WIDTH
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{size}" '
        f'viewBox="0 0 {width} {size}" font-family="sans-serif" font-size="12">',
        f'<rect width="{width}" height="{size}" fill="white"/>',
        *_rooms(rooms, other_rooms, view),
        *_fragments(result, walls, view),
        *_scale_bar(view),
        *_legend(result, size + 10),
        *_captions(result, title, size),
        "</svg>",
    ]
    return "\n".join(parts)
