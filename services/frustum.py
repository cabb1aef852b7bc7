"""Camera frustums of RGB-D frames on the floorplan (paper supplement, "RGB-D images").

A frame's points all lie inside its camera's frustum. Projected on the floor plan it bounds
where the frame's wall chain can start and end (the widest pair of keypoints seen from the
camera, :func:`services.wall_graph.find_wall_chain`), and over each floor-plan column it
bounds the height the camera saw: a wall near the camera shows only its lower part, so the
"reaches the ceiling" test of the wall evidence is measured against what was visible
(:func:`services.wall_lines.find_wall_lines`). And every ray crossed open space on its way to
the point it hit: the floor-plan cells it crossed hold no wall (:func:`swept_cells`), which
the placement uses to refuse other fragments' walls there.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from schemas.frames import IntrinsicsModel
from services.geometry import unique_cells
from services.types import FloatArray

__all__ = [
    "CameraView",
    "in_any_view",
    "side_rays",
    "swept_cells",
    "view_angle",
    "visible_band",
]

_FLAT = 1e-9
_SWEEP_BIN = np.radians(0.5)  # bearing bins of the swept rays: 5 cm apart at 6 m
_SWEEP_QUANTILE = 0.9  # a bin's reach: this quantile of its points' distances (not a stray)
_SWEEP_SHORT = 0.15  # m, rays stop this short of what they hit (noise, the wall's own cell)


@dataclass(frozen=True)
class CameraView:
    """One camera's frustum, in a fragment's aligned frame (z up).

    centre: (3,) float64, the camera's optical centre.
    normals: (4, 3) float64, unit normals of the frustum's side planes (left, right, top,
    bottom image edges, each through the centre), pointing into the frustum.
    """

    centre: FloatArray
    normals: FloatArray

    @classmethod
    def from_intrinsics(
        cls, intrinsics: IntrinsicsModel, rotation: FloatArray, centre: FloatArray
    ) -> CameraView:
        """The frustum of a pinhole camera.

        Parameters
        ----------
        intrinsics : image size and focal lengths, pixels.
        rotation : (3, 3) optical frame -> aligned frame.
        centre : (3,) the optical centre, aligned frame.
        """
        k = intrinsics
        u0, u1 = (-0.5 - k.cx) / k.fx, (k.width - 0.5 - k.cx) / k.fx
        v0, v1 = (-0.5 - k.cy) / k.fy, (k.height - 0.5 - k.cy) / k.fy
        corners = np.array([[u0, v0, 1.0], [u1, v0, 1.0], [u1, v1, 1.0], [u0, v1, 1.0]])
        # Edges left (bottom-left to top-left), right, top, bottom as corner pairs.
        pairs = ((3, 0), (1, 2), (0, 1), (2, 3))
        normals = np.array([np.cross(corners[a], corners[b]) for a, b in pairs])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        normals *= np.sign(normals @ np.array([0.0, 0.0, 1.0]))[:, None]  # into the view
        return cls(np.asarray(centre, dtype=np.float64), normals @ rotation.T)

    @property
    def forward(self) -> FloatArray:
        """(2,) unit heading of the optical axis on the floor plan."""
        axis = self.normals.sum(axis=0)[:2]
        norm = float(np.linalg.norm(axis))
        return axis / norm if norm > 0 else np.array([1.0, 0.0])

    def band(self, xy: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Lowest and highest height the camera sees over each floor-plan column.

        Parameters
        ----------
        xy : (M, 2) float64, column positions, aligned frame.

        Returns
        -------
        low, high : (M,) float64, aligned z; ``low > high`` where the column lies outside
            the frustum.
        """
        d = np.asarray(xy, dtype=np.float64) - self.centre[:2]
        low = np.full(len(d), -np.inf)
        high = np.full(len(d), np.inf)
        for n in self.normals:
            across = d @ n[:2]
            if n[2] > _FLAT:  # n . (d, z) >= 0 bounds z from below
                low = np.maximum(low, -across / n[2])
            elif n[2] < -_FLAT:
                high = np.minimum(high, -across / n[2])
            else:
                high = np.where(across < 0.0, -np.inf, high)
        return low + self.centre[2], high + self.centre[2]


def visible_band(views: Sequence[CameraView], xy: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The union over cameras of :meth:`CameraView.band`: (low, high), ``low > high`` (both
    NaN) where no camera sees the column.

    >>> view = CameraView.from_intrinsics(
    ...     IntrinsicsModel(width=640, height=480, fx=525, fy=525, cx=319.5, cy=239.5),
    ...     np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]), np.zeros(3))
    >>> low, high = visible_band([view], np.array([[0.0, 2.0], [0.0, -2.0]]))
    >>> bool(abs(high[0] - 2.0 * 240 / 525) < 1e-9), bool(np.isnan(high[1]))
    (True, True)
    """
    low = np.full(len(xy), np.inf)
    high = np.full(len(xy), -np.inf)
    for view in views:
        lo, hi = view.band(xy)
        seen = lo <= hi
        low = np.where(seen, np.minimum(low, lo), low)
        high = np.where(seen, np.maximum(high, hi), high)
    unseen = low > high
    low[unseen] = np.nan
    high[unseen] = np.nan
    return low, high


def in_any_view(
    views: Sequence[CameraView], xy: FloatArray, tolerance_deg: float = 3.0
) -> NDArray[np.bool_]:
    """(M,) True where a floor-plan point lies within some camera's frustum projected on the
    floor plan (the wedge its four corner rays span, widened by ``tolerance_deg``).

    The projection, not the frustum's cut at the camera's height: a camera looking down sees
    the foot of a wall further out to the side than its eye-level edge (a few degrees at a
    20 degree pitch), and the chain's ends lie there.

    xy : (M, 2) float64, aligned frame.
    """
    points = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    found = np.zeros(len(points), dtype=bool)
    slack = np.radians(tolerance_deg)
    for view in views:
        low, high = _wedge(view)
        d = points - view.centre[:2]
        heading = np.arctan2(view.forward[1], view.forward[0])
        bearing = np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - heading)))
        found |= (bearing >= low - slack) & (bearing <= high + slack) & (d @ view.forward > 0)
    return found


def _wedge(view: CameraView) -> tuple[float, float]:
    """Least and greatest bearing (radians, from the heading) of the corner rays' floor-plan
    projections: each corner ray lies in two adjacent side planes."""
    n = view.normals  # left, right, top, bottom
    corners = np.array([np.cross(n[a], n[b]) for a, b in ((0, 2), (2, 1), (1, 3), (3, 0))])
    flat = corners[:, :2] * np.sign(corners[:, :2] @ view.forward)[:, None]
    heading = np.arctan2(view.forward[1], view.forward[0])
    bearing = np.angle(np.exp(1j * (np.arctan2(flat[:, 1], flat[:, 0]) - heading)))
    return float(bearing.min()), float(bearing.max())


def side_rays(view: CameraView) -> FloatArray:
    """(2, 2) unit floor-plan directions of the frustum's right and left edges at the
    camera's height: where its right / left side planes cut the horizontal plane through
    the centre, so the chain's source (right) and target (left) ends lie on them.

    >>> level = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    >>> k = IntrinsicsModel(width=640, height=480, fx=320, fy=320, cx=319.5, cy=239.5)
    >>> np.round(side_rays(CameraView.from_intrinsics(k, level, np.zeros(3))), 3).tolist()
    [[0.707, 0.707], [-0.707, 0.707]]
    """
    rays = []
    for n in (view.normals[1], view.normals[0]):  # right edge, then left
        direction = np.cross(n, [0.0, 0.0, 1.0])[:2]
        norm = float(np.linalg.norm(direction))
        if norm < 1e-9:  # a side plane lying flat: the camera looks straight up or down
            direction, norm = view.forward, 1.0
        direction = direction / norm
        rays.append(direction if direction @ view.forward >= 0 else -direction)
    return np.array(rays)


def view_angle(views: Sequence[CameraView]) -> float:
    """The horizontal angle (radians) the views see across at their cameras' height,
    summed over the views and at most a full turn.

    >>> level = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    >>> k = IntrinsicsModel(width=640, height=480, fx=320, fy=320, cx=319.5, cy=239.5)
    >>> view = CameraView.from_intrinsics(k, level, np.zeros(3))
    >>> round(float(np.degrees(view_angle([view]))), 1)
    90.0
    """
    total = 0.0
    for view in views:
        right, left = side_rays(view)
        total += float(np.arccos(np.clip(right @ left, -1.0, 1.0)))
    return min(total, 2.0 * np.pi)


def swept_cells(views: Sequence[CameraView], xy: FloatArray, cell: float) -> FloatArray:
    """Centres of the floor-plan cells (grid of size ``cell``, aligned frame) that the
    cameras' rays crossed on their way to the points they hit.

    A full-height wall stands nowhere on such a ray's floor-plan projection, whatever
    height the ray ran at: a frame sees its floor only a few meters out, but it sees the
    space up to its walls empty. Points are binned by bearing per camera (those within its
    wedge); a bin's ray runs to a high quantile of its points' distances, so a stray point
    through a window does not carry it out.

    xy : (M, 2) float64, the frame's points on the floor plan, aligned frame.
    Returns (C, 2) float64, unique cell centres.
    """
    points = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    cells = [np.zeros((0, 2), dtype=np.int64)]
    for view in views:
        d = points[in_any_view([view], points, 0.0)] - view.centre[:2]
        if len(d) == 0:
            continue
        reach = np.hypot(d[:, 0], d[:, 1])
        bins = np.floor(np.arctan2(d[:, 1], d[:, 0]) / _SWEEP_BIN).astype(np.int64)
        order = np.lexsort((reach, bins))
        labels, first, counts = np.unique(bins[order], return_index=True, return_counts=True)
        at = first + np.floor(_SWEEP_QUANTILE * (counts - 1)).astype(np.int64)
        ends = reach[order][at] - _SWEEP_SHORT
        bearing = (labels + 0.5) * _SWEEP_BIN
        steps = np.arange(0.0, float(ends.max(initial=0.0)), cell / 2)
        # (T, B) samples along every bin's ray, kept up to that bin's reach
        keep = steps[:, None] < ends[None, :]
        along = np.stack([np.cos(bearing), np.sin(bearing)], axis=-1)
        samples = view.centre[:2] + steps[:, None, None] * along[None]
        cells.append(np.floor(samples[keep] / cell).astype(np.int64))
    unique, _ = unique_cells(np.vstack(cells))
    centres: FloatArray = ((unique + 0.5) * cell).astype(np.float64)
    return centres
