"""Local layout of an RGB-D frame, or of frames merged into one (paper supplement).

As for a point cloud (:mod:`services.local_layout`) with three changes:

- the optical frame (x right, y down, z forward) is first turned to the camera's level frame
  (z up), so levelling starts from the right up axis; that turn is folded into the reported
  Manhattan rotation, so poses still map the frame's own (optical) points;
- a wall column must show the height its camera saw of it, not the whole floor-to-ceiling
  band (:class:`services.frustum.CameraView`);
- the chain's source and target are the widest pair of keypoints seen from the camera.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from schemas.frames import IntrinsicsModel
from schemas.params import PipelineParams
from services.frustum import (
    CameraView,
    in_any_view,
    side_rays,
    swept_cells,
    view_angle,
    visible_band,
)
from services.geometry import cross, unique_cells
from services.local_layout import FOOTPRINT_CELL, end_boundaries, footprint_cells
from services.manhattan import (
    OrientedCloud,
    estimate_manhattan_frame,
    steep_floor_tilt,
    thin_with_normals,
)
from services.rgbd import OPTICAL_TO_LEVEL, RgbdFrame, backproject
from services.seen_past_corners import without_corners_seen_past
from services.types import ChainVariant, FloatArray, LocalLayout, ManhattanFrame, ProgressFn
from services.view_ranges import range_towards, view_ranges
from services.wall_graph import FRONT_DEPTH, find_wall_chain, side_by_side_depth
from services.wall_lines import (
    MAX_DOORWAY,
    MAX_FURNITURE_DEPTH,
    MAX_OPEN_ABOVE,
    MAX_WALL_THICKNESS,
    WallLine,
    find_wall_lines,
    offset_peaks,
    run_axis,
    wall_line_of,
)

_FLAT_COS = float(np.cos(np.radians(10.0)))  # a normal this close to +z: horizontal surface
_SPACING = 0.03  # m, largest spacing of a frame's points at 4 m (sets the pixel stride)
_FLOOR_BAND = 0.05  # m, points this close to the floor height lie on the floor
_MIN_FLOOR_POINTS = 50
_MIN_HEIGHT, _MAX_HEIGHT = 0.2, 2.5  # m, camera heights over a floor that can be one
_MAX_EXTENSION = 3.0  # m, farthest a chain end is moved out to the frustum's edge
_SIGHT_STEP = 0.05  # m, spacing of the points a chain end's move is checked in sight at
_SIGHT_WIDEN = 2  # view-range bins either side a nearer reading must cover to hide the line
_SIGHT_HIDDEN = 0.3  # m, least stretch of the line hidden that stops a chain end's move
_SIGHT_LEAST = int(np.ceil(_SIGHT_HIDDEN / _SIGHT_STEP))  # that stretch in steps
_ACROSS_NEARER = 0.2  # m, what hides the line stands at least this much nearer along the ray
_ACROSS_SPREAD = 0.1  # m, most its run coordinate varies over that stretch: a surface across
_MIN_TURN = 0.3  # m, least length of a wall the chain's last wall turns onto (a reveal is less)
_ON_LINE = 0.1  # m, a keypoint this close to a wall's line lies on it
_SEED_PLANES = 2  # planes peeled off when looking for the floor's normal
_LEVEL_BIN = 0.02  # m, height histogram bin of the floor search
_UPRIGHT_SIN = 0.2  # a normal this far from horizontal at most: a standing surface
_FACING_COS = 0.9  # a standing surface's normal this close to a wall's normal faces like it
_MIN_OPENING_COVER = 0.25  # least share of the view a wall with an opening fills
_MIN_SURFACE_POINTS = 30  # fewer points than this make no surface (a tenth: no top or side)
_NEAR_CAMERA = 0.3  # m, standing surfaces closer to the camera are not looked at
_COLUMN_DEGREES = 2.0  # bin of the view's columns a surface shows up in

__all__ = [
    "CHAIN_STAGES",
    "ChainTrace",
    "FrameCamera",
    "estimate_frame_layout",
    "estimate_rgbd_layout",
    "frame_points",
    "side_like",
]


# The steps a frame's chain goes through, in order (:func:`estimate_frame_layout`'s
# ``trace``): the wall graph's chain, then furniture fronts and reveals taken out, ends moved
# to the frustum's edges, corners a wall is seen past cut, furniture sides dropped at the
# ends, and a one-wall chain seen through an opening moved onto the room's wall.
CHAIN_STAGES = ("graph", "furniture", "frustum edges", "corners seen past", "end sides", "opening")
ChainTrace = Callable[[str, FloatArray], None]  # (stage, (K, 2) keypoints, aligned frame)


@dataclass(frozen=True)
class FrameCamera:
    """A camera that took (part of) a fragment.

    intrinsics: its pinhole model. pose: (4, 4) its optical frame -> the fragment's local
    frame (identity for a single frame; for merged frames, the anchor frame's optical frame).
    """

    intrinsics: IntrinsicsModel
    pose: FloatArray = field(default_factory=lambda: np.eye(4))


def frame_points(frame: RgbdFrame, params: PipelineParams = PipelineParams()) -> FloatArray:
    """(N, 3) float64 points of a frame for its layout: every k-th pixel in the depth range,
    optical frame, meters; k is at most ``stride`` and keeps neighbouring points at most
    about 3 cm apart at 4 m (a wide-angle or small image is used whole)."""
    k = frame.intrinsics
    step = int(np.clip(min(k.fx, k.fy) * _SPACING / 4.0, 1, params.layout.frame.stride))
    points, _ = backproject(frame, params.layout.frame, step)
    return points


def _unit(v: FloatArray) -> FloatArray:
    norm = float(np.linalg.norm(v))
    return v / norm if norm > 0 else v


def _floor(aligned: FloatArray, normals: FloatArray, params: PipelineParams) -> float:
    """The floor height (aligned frame, camera at 0).

    The lowest horizontal level below the camera with enough upward-facing points, unless
    walls reach further down (then that level is a table or bed top hiding the floor): a
    frame often sees more of a table top than of the floor, and nothing flat lies below the
    floor. Without a level, the floor lies below the walls' foot and, as far as the frame
    tells, at the assumed camera height.
    """
    frame = params.layout.frame
    heights = aligned[normals[:, 2] > _FLAT_COS, 2]
    heights = heights[(heights > -_MAX_HEIGHT) & (heights < -_MIN_HEIGHT)]
    standing = aligned[np.abs(normals[:, 2]) < _UPRIGHT_SIN, 2]
    # The foot of the walls (a low percentile: a few noisy points reach lower).
    foot = float(np.percentile(standing, 0.5)) if len(standing) >= _MIN_FLOOR_POINTS else 0.0
    counts = np.bincount(
        np.floor((heights + _MAX_HEIGHT) / _LEVEL_BIN).astype(np.int64),
        minlength=int(_MAX_HEIGHT / _LEVEL_BIN) + 2,
    )
    # A level's points spread over a bin or two (noise grows with depth squared).
    strong = np.flatnonzero(np.convolve(counts, np.ones(3), mode="same") >= _MIN_FLOOR_POINTS)
    if len(strong):
        guess = (strong[0] + 0.5) * _LEVEL_BIN - _MAX_HEIGHT
        level = float(np.median(heights[np.abs(heights - guess) < _FLOOR_BAND]))
        if level <= foot + _FLOOR_BAND:
            return level
    return min(foot, -frame.camera_height)


def _edge_crossing(
    end: FloatArray, outward: FloatArray, views: Sequence[CameraView], side: int
) -> float | None:
    """How far (m) from ``end`` along ``outward`` the wall leaves every camera's view
    through their right (``side`` 0) or left (1) frustum edge; None when it never does."""
    found = []
    for view in views:
        ray = side_rays(view)[side]
        matrix = np.column_stack([outward, -ray])
        if abs(np.linalg.det(matrix)) < 1e-9:
            continue  # the wall runs along the edge
        reach, along_ray = np.linalg.solve(matrix, view.centre[:2] - end)
        crossing = end + reach * outward
        # The union's edge: not inside another camera's view (merged frames).
        others = [v for v in views if v is not view]
        if reach > 0 and along_ray > 0 and not in_any_view(others, crossing[None], -1.0)[0]:
            found.append(float(reach))
    return min(found) if found else None


def _inward_depth(keypoints: FloatArray, k: int, points: FloatArray) -> FloatArray:
    """How far (m) points lie on the room's side of the chain's wall ``k`` (its line)."""
    direction = _unit(keypoints[k + 1] - keypoints[k])
    left = np.array([-direction[1], direction[0]])  # the interior is on the left
    depth: FloatArray = (points - keypoints[k]) @ left
    return depth


def _shallow(depth: FloatArray) -> bool:
    return bool(len(depth) and np.all(depth > -_ON_LINE) and np.all(depth < MAX_FURNITURE_DEPTH))


def _flatten_furniture(keypoints: FloatArray) -> FloatArray:
    """The chain without shallow steps into the room that come back to the wall they left.

    Seen from one camera a wardrobe or shelf against a wall looks like the wall itself: it
    stands taller than the band the camera sees, and the wall behind it is hidden. A chain
    that leaves a wall, runs less than ``MAX_FURNITURE_DEPTH`` into the room and returns to
    the same line (or ends there) went round such a front; the wall goes straight on. A room's
    own pillar or recess shallower than that is flattened too (a frame cannot tell them).

    keypoints: (K, 2) float64, aligned frame, source to target.
    """
    kp = keypoints.copy()
    changed = True
    while changed and len(kp) >= 4:
        changed = False
        for k in range(len(kp) - 3):
            for m in range(len(kp) - 2, k + 1, -1):
                depth = _inward_depth(kp, k, kp[k + 1 : m + 1])
                back = abs(_inward_depth(kp, k, kp[m + 1 : m + 2])[0]) < _ON_LINE
                if back and _shallow(depth) and _same_travel(kp, k, m):
                    kp = np.vstack([kp[: k + 1], kp[m + 1 :]])
                    changed = True
                    break
            if changed:
                break
    return _flatten_ends(kp)


def _flatten_corner_fronts(keypoints: FloatArray) -> FloatArray:
    """The chain without shallow fronts standing in a room's corner.

    A wardrobe against wall B, next to the corner with wall A, hides that corner: the chain
    runs along A, turns onto the wardrobe's front F (parallel to B, less than
    ``MAX_FURNITURE_DEPTH`` in front of it) and steps back out to B along the wardrobe's
    side G; the room's corner is where A's and B's lines meet. Whether or not G was seen:
    from most stances a wardrobe's side is, and a frame cannot tell a step of the room that
    shallow from a wardrobe (as :func:`_flatten_furniture` assumes along a wall). Checked in
    both walking directions (the same front at the chain's other corner).

    keypoints: (K, 2) float64, aligned frame, source to target.
    """
    kp = keypoints.copy()
    for _ in range(2):  # forwards, then backwards
        k = 0
        while k + 4 < len(kp):
            depth = _inward_depth(kp, k + 3, kp[k + 1 : k + 3])
            if (
                _same_travel(kp, k + 1, k + 3)
                and _same_travel(kp, k, k + 2)
                and np.all((depth > _ON_LINE) & (depth < MAX_FURNITURE_DEPTH))
            ):
                along = _unit(kp[k + 1] - kp[k])
                corner = kp[k] + float((kp[k + 3] - kp[k]) @ along) * along
                kp = np.vstack([kp[: k + 1], corner, kp[k + 4 :]])
            else:
                k += 1
        kp = _reverse_chain(kp)
    return kp


def _same_travel(kp: FloatArray, k: int, m: int) -> bool:
    return bool(_unit(kp[k + 1] - kp[k]) @ _unit(kp[m + 1] - kp[m]) > 0.99)


def _flatten_ends(kp: FloatArray) -> FloatArray:
    """A chain whose last walls step shallowly into the room and end there: the wall it
    left runs on to the end (and the same at the source)."""
    for _ in range(2):  # the target end, then (reversed) the source end
        for k in range(len(kp) - 3, -1, -1):
            depth = _inward_depth(kp, k, kp[k + 2 :])
            if len(depth) and _shallow(depth) and np.any(depth > _ON_LINE):
                direction = _unit(kp[k + 1] - kp[k])
                run = float((kp[-1] - kp[k]) @ direction)
                if run > float((kp[k + 1] - kp[k]) @ direction):
                    kp = np.vstack([kp[: k + 1], kp[k] + run * direction])
                break
        kp = _reverse_chain(kp)
    return kp


_PAST_CORNER_MIN = 0.2  # m, least wall evidence past a turn that says the turn was early
_PAST_CORNER_MAX = 1.0  # m, most (deeper than furniture stands: another wall's evidence)
_MIN_LEAD = 0.1  # m, least stretch of a wall seen before a lone front's end (not a reveal)
_SEGMENT_SLACK = 0.05  # m, a segment ending this close to a keypoint holds it
_MAX_REVEAL = 0.35  # m, longest end wall read as a door's or window's reveal
# m over the floor: a column seen no higher shows no more of a wall than of a cabinet's,
# shelf's or wardrobe's side (tune frames, three cameras: of the short end walls seen no
# higher, 11 were sides and none a wall; from there to 1.6 m, 9 sides and 6 walls)
_JUDGED_HEIGHT = 1.4
# m, longest end wall dropped as a furniture's side a camera saw over (the generator's sofas
# and beds stand up to 1.05 m out from their wall)
_MAX_SEEN_SIDE = 1.1
_SIDE_BAND = 0.15  # m, points this close to an end wall's line are its own (lines stray)
_SEEN_OVER = 0.3  # m, above a column's tallest point: a wall would have shown there
_RAY_WIDTH = 0.05  # m, a point this close to a camera's ray blocked it
_RAY_NEAR, _RAY_FAR = 0.3, 0.2  # m, ray parts not looked at: at the camera, at the wall


def _past_corner_fronts(keypoints: FloatArray, lines: Sequence[WallLine]) -> FloatArray:
    """The chain with a last wall that turned early moved onto the room's corner.

    A wardrobe or shelf standing against wall B next to its corner with wall A hides that
    corner: walking along A the chain turns onto the furniture's front F, in front of B,
    while A's own evidence goes on past the turn (the part of A beside the furniture's side
    is seen). When the chain's last wall is such an F (a left turn, A seen on past it by
    0.2-1 m), the corner is where A's evidence ends and the last wall runs parallel to F
    through it. Checked at both ends (at the source, F is the first wall).
    """
    kp = keypoints.copy()
    if len(kp) < 3:
        return kp
    # (wall A's far end, the corner, F's end), A walked towards the corner: target, source.
    for a, c, e in ((len(kp) - 3, len(kp) - 2, len(kp) - 1), (2, 1, 0)):
        reach = _reach_past_turn(kp, a, c, e, lines)
        if reach > 0.0:
            along = _unit(kp[c] - kp[a])
            kp[c] = kp[c] + reach * along
            kp[e] = kp[e] + reach * along
    return kp


def _reach_past_turn(kp: FloatArray, a: int, c: int, e: int, lines: Sequence[WallLine]) -> float:
    """How far wall A (keypoints ``a`` to the corner ``c``) is seen on past the chain's left
    turn at ``c`` onto the end wall towards ``e``, when that says the turn came early
    (0.2-1 m: a furniture front's depth); else 0."""
    along, turn = _unit(kp[c] - kp[a]), _unit(kp[e] - kp[c])
    left = float(cross(along, turn))
    if (left if e > c else -left) < 0.5:
        return 0.0  # not a left turn in chain order
    line = wall_line_of(lines, *((kp[a], kp[c]) if e > c else (kp[c], kp[a])))
    if line is None:
        return 0.0
    outward = 1 if along[line.axis] > 0 else -1
    reach = line.high_run_beyond(float(kp[c][line.axis]), outward)
    return reach if _PAST_CORNER_MIN <= reach <= _PAST_CORNER_MAX else 0.0


def _with_wall_before_front(keypoints: FloatArray, lines: Sequence[WallLine]) -> FloatArray:
    """A one-wall chain given the stretch of the wall it turned off, when that says the wall
    is a furniture front before the room's corner.

    A wardrobe in a corner can fill a frame's view but for a strip of the wall A beside
    it: the chain is then the wardrobe's front F alone, from A's line on. When a segment of
    A holds the chain's end, goes on at least ``_MIN_LEAD`` before it and A's evidence goes
    on past it behind F (:func:`_reach_past_turn`), the chain gets that stretch of A as its
    first (or last) wall, and :func:`_past_corner_fronts` moves the corner. A reveal or
    wall piece behind the end alone (no segment through the end) adds nothing.
    """
    if len(keypoints) != 2:
        return keypoints
    heading = _unit(keypoints[1] - keypoints[0])
    left = np.array([-heading[1], heading[0]])
    # A walked onto the source (a left turn onto F), or away from the target.
    for end, direction, before, order in ((0, -left, -1, (0, 1, 2)), (1, left, 1, (2, 1, 0))):
        corner = keypoints[end]
        line = wall_line_of(lines, corner, corner + direction)
        if line is None:
            continue
        outward = 1 if direction[line.axis] > 0 else -1
        lead = _segment_run(line, float(corner[line.axis]), before * outward)
        if lead < _MIN_LEAD:
            continue
        point = corner + before * lead * direction
        candidate = np.vstack([point, keypoints]) if end == 0 else np.vstack([keypoints, point])
        if _reach_past_turn(candidate, *order, lines) > 0.0:
            return candidate
    return keypoints


def _segment_run(line: WallLine, run: float, outward: int) -> float:
    """How far (m) a candidate segment of the line through run coordinate ``run`` goes on
    from it in direction ``outward`` (+1 or -1); 0 when no segment holds ``run``."""
    return max(
        (
            float(hi - run if outward > 0 else run - lo)
            for lo, hi in line.segments
            if lo - _SEGMENT_SLACK <= run <= hi + _SEGMENT_SLACK
        ),
        default=0.0,
    )


def _drop_end_reveals(keypoints: FloatArray) -> FloatArray:
    """The chain without end walls that are an opening's reveal.

    Where a frame's view ends in a door or window, the chain can end on the opening's side:
    a wall a few decimeters long (the wall's thickness) turning away from the room (a right
    turn, interior on the left) behind the wall it leaves. A room's own wall that turns away
    at a protruding corner is seen longer than that. Run after the furniture flattening (a
    shelf's front seen past its side makes the same short right turn, and is flattened).
    """
    return _drop_ends(
        keypoints,
        lambda along, end, _: bool(cross(along, end) < 0 and np.linalg.norm(end) < _MAX_REVEAL),
    )


def _drop_end_sides(
    keypoints: FloatArray, views: Sequence[CameraView], points: FloatArray, floor_z: float
) -> FloatArray:
    """The chain without end walls that may be a furniture's side.

    Where a frame's view ends beside a wardrobe, shelf or sofa against a wall, the chain can
    start (or end) on the furniture's side: a short wall that meets the room's wall at a
    convex corner (a left turn, interior on the left), as a room's own corner would. Such
    an end wall is dropped

    - when under ``MAX_FURNITURE_DEPTH`` and no camera saw any of its columns up to
      ``_JUDGED_HEIGHT`` (at a view's bottom corner a camera sees only the lower part of
      what stands there: low down a wall and a side look the same), or
    - when under ``_MAX_SEEN_SIDE``, its points stop under ``_JUDGED_HEIGHT`` and a camera
      facing it saw over it (:func:`_seen_over`): a wall would have shown there.

    A room's corner dropped so loses little: the chain still ends at the corner, and a
    neighbour sees the wall that turns. The wall left must be longer than the one dropped.

    Parameters
    ----------
    keypoints : (K, 2) the chain, interior on its left.
    views : the cameras that saw the fragment, aligned frame.
    points : (N, 3) the fragment's points, aligned frame.
    floor_z : the floor's height, aligned frame.
    """

    def drops(along: FloatArray, end: FloatArray, wall: FloatArray) -> bool:
        if not side_like(along, end, _MAX_SEEN_SIDE):
            return False
        if float(np.linalg.norm(end)) < MAX_FURNITURE_DEPTH and not _seen_high(
            wall, views, floor_z
        ):
            return True
        return _seen_over(wall, views, points, floor_z)

    return _drop_ends(keypoints, drops)


def _drop_ends(
    keypoints: FloatArray, drops: Callable[[FloatArray, FloatArray, FloatArray], bool]
) -> FloatArray:
    """The chain without the end walls ``drops`` picks, target end first. For each end it is
    asked with the wall the end wall meets (``along``, in chain order), the floor-plan step
    from their corner to the chain's free end (``end``: the end wall stands on the room's
    side of ``along`` when it is a left turn) and the end wall's two keypoints (2, 2)."""
    kp = keypoints
    if len(kp) >= 3 and drops(kp[-2] - kp[-3], kp[-1] - kp[-2], kp[-2:]):
        kp = kp[:-1]
    if len(kp) >= 3 and drops(kp[2] - kp[1], kp[0] - kp[1], kp[:2]):
        kp = kp[1:]
    return kp


def side_like(along: FloatArray, end: FloatArray, longest: float) -> bool:
    """Whether an end wall (the floor-plan step ``end`` from its corner to its free end) is
    shorter than ``longest`` and than the wall ``along`` it meets (chain order), and stands
    on the room's side of that wall (its left)."""
    length = float(np.linalg.norm(end))
    return bool(cross(along, end) > 0) and length < min(longest, float(np.linalg.norm(along)))


def _seen_high(wall: FloatArray, views: Sequence[CameraView], floor_z: float) -> bool:
    """Whether some camera saw a column of the wall (2, 2) up to ``_JUDGED_HEIGHT`` over the
    floor."""
    samples = wall[0] + np.linspace(0.1, 0.9, 5)[:, None] * (wall[1] - wall[0])
    _, high = visible_band(views, samples)
    return bool(np.any(high >= floor_z + _JUDGED_HEIGHT))  # NaN (unseen) compares False


def _seen_over(
    wall: FloatArray, views: Sequence[CameraView], points: FloatArray, floor_z: float
) -> bool:
    """Whether a camera facing the wall (2, 2; interior on its left) saw over it where a
    room's wall would have stood: none of its own points (within ``_SIDE_BAND`` of its line,
    its ends left out) reaches ``_JUDGED_HEIGHT`` over the floor, and at one of its columns
    the camera's frustum holds the height ``_SEEN_OVER`` above that column's tallest point,
    on a ray nothing blocked (a wardrobe before the wall hides it as well as its top)."""
    step = wall[1] - wall[0]
    length = float(np.linalg.norm(step))
    if length == 0.0:
        return False
    unit = step / length
    relative = points[:, :2] - wall[0]
    along = relative @ unit / length
    own = np.abs(relative @ np.array([-unit[1], unit[0]])) < _SIDE_BAND
    middle = own & (along >= 0.1) & (along <= 0.9)
    if np.any(points[middle, 2] >= floor_z + _JUDGED_HEIGHT):
        return False
    fractions = np.linspace(0.1, 0.9, 5)
    columns = wall[0] + fractions[:, None] * step
    near = own & (np.abs(along - fractions[:, None]) <= 0.1)  # (5, N) a column's points
    tops = np.max(np.where(near, points[:, 2], floor_z), axis=1, initial=floor_z)
    spots = np.column_stack([columns, tops + _SEEN_OVER])
    for view in views:
        if cross(step, view.centre[:2] - wall[0]) <= 0:
            continue  # behind the wall: it saw the other face, if anything
        low, high = view.band(columns)
        framed = (low <= spots[:, 2]) & (spots[:, 2] <= high)
        if any(_clear_ray(view.centre, spot, points) for spot in spots[framed]):
            return True
    return False


def _clear_ray(start: FloatArray, end: FloatArray, points: FloatArray) -> bool:
    """Whether no point lies within ``_RAY_WIDTH`` of the ray from ``start`` to ``end`` (3,)
    past the camera's own surroundings and short of the end's (the wall's points)."""
    ray = end - start
    length = float(np.linalg.norm(ray))
    unit = ray / length
    relative = points - start
    t = relative @ unit
    between = (t > _RAY_NEAR) & (t < length - _RAY_FAR)
    off = relative[between] - t[between, None] * unit
    return not bool(np.any(np.einsum("ij,ij->i", off, off) < _RAY_WIDTH**2))


def _without_furniture(keypoints: FloatArray, lines: Sequence[WallLine]) -> FloatArray:
    """The chain with the furniture fronts it went round and its ends' reveals taken out.

    Corners a front hid move first (:func:`_past_corner_fronts`), then fronts are flattened
    and reveals dropped; a reveal at an end hides an early turn before it, so the corners
    are looked at again once it is gone.
    """
    kp = _past_corner_fronts(_with_wall_before_front(keypoints, lines), lines)
    kp = _drop_end_reveals(_flatten_furniture(_flatten_corner_fronts(kp)))
    return _past_corner_fronts(kp, lines)


def _reverse_chain(kp: FloatArray) -> FloatArray:
    """The same chain walked backwards with the room on its right; reversing twice is a
    no-op (used to treat the source end like the target end)."""
    flipped: FloatArray = kp[::-1] * np.array([1.0, -1.0])
    return flipped


def _wall_across(
    lines: Sequence[WallLine], line: WallLine, start: float, stop: float
) -> float | None:
    """The run coordinate nearest ``start`` where a seen wall of the other axis meets
    ``line`` between two of its run coordinates (two cells of slack): the wall turns there,
    it does not go on; None when none does. A wall shorter than ``_MIN_TURN`` on both sides
    of the line is a door's or window's reveal."""
    lo, hi = sorted((start, stop))
    reach = 2 * line.cell_size
    found = []
    for other in lines:
        if other.virtual or other.axis == line.axis or not lo - reach < other.offset < hi + reach:
            continue
        spans = other.segments
        meets = (spans[:, 0] - reach <= line.offset) & (spans[:, 1] + reach >= line.offset)
        long = np.maximum(spans[:, 1] - line.offset, line.offset - spans[:, 0]) >= _MIN_TURN
        if np.any(meets & long):
            found.append(other.offset)
    return min(found, key=lambda offset: abs(offset - start)) if found else None


def _to_frustum_edges(
    keypoints: FloatArray,
    lines: Sequence[WallLine],
    views: Sequence[CameraView],
    ranges: FloatArray | None = None,
) -> FloatArray:
    """Chain ends moved out along their walls to where the frustum's edges cut them.

    A frame sees its walls up to its image's edges: where the wall evidence stops short of
    them, furniture, a window or a door hides the rest of a wall that goes on (the next
    frame's chain starts at that edge). The move stops where a seen wall of the other axis
    meets the line on the way (the wall turns there; a door's reveal does not count), and is
    refused where the line would run through more than 2 m of space seen on both sides (the room
    opens up there), the WE-graph's limit for an edge (services.wall_graph), or through any
    stretch its camera saw through higher than a door's top (no lintel: no door either). Nothing
    scanned on the room's side is no reason to stop: a wardrobe hides that strip as well
    (refusing those moves cost 9 points of ACC_local on the frames benchmark). But with one
    camera (its view ``ranges``, :func:`services.view_ranges.view_ranges`) the move stops
    where the line passes behind something seen standing more than a furniture's depth off
    it: whether the wall goes on there, the camera could not tell.

    keypoints: (K, 2) float64, aligned frame, source (right of the camera) to target (left).
    """
    out = keypoints.copy()
    for side, (end, inner) in enumerate(((0, 1), (-1, -2))):
        first, second = sorted((end, inner), key=lambda i: i % len(keypoints))
        line = wall_line_of(lines, keypoints[first], keypoints[second])  # in chain order
        if line is None:
            continue
        outward = _unit(keypoints[end] - keypoints[inner])
        reach = _edge_crossing(keypoints[end], outward, views, side)
        if reach is None or reach > _MAX_EXTENSION:
            continue
        if ranges is not None and len(views) == 1:
            centre = views[0].centre[:2]
            reach = _in_sight(keypoints[end], outward, reach, ranges, centre)
            across = _wall_hiding(keypoints[end], outward, reach, ranges, centre, lines, line)
            reach = reach if across is None else across
        moved = keypoints[end] + reach * outward
        start, stop = float(keypoints[end][line.axis]), float(moved[line.axis])
        turn = _wall_across(lines, line, start, stop)
        if turn is not None:  # the wall turns on the way: its end goes to the corner
            along = max((turn - start) * float(np.sign(outward[line.axis])), 0.0)
            moved = keypoints[end] + along * outward
            stop = float(moved[line.axis])
        seen_open = line.open_above_gap(start, stop) > MAX_OPEN_ABOVE
        if line.crossing_gap(start, stop) <= MAX_DOORWAY and not seen_open:
            out[end] = moved
    return out


def _line_in_view(
    end: FloatArray, outward: FloatArray, along: FloatArray, ranges: FloatArray, centre: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The points ``along`` (m) out from a chain end on its wall's line as its camera (at
    ``centre``, its view ``ranges``) sees them: their (M, 2) offsets from the camera, their
    (M,) distances, and (M,) how far the view saw that way (NaN: nothing seen)."""
    points = end + along[:, None] * outward
    offset = points - centre
    distance = np.hypot(offset[:, 0], offset[:, 1])
    return offset, distance, range_towards(ranges, centre, points, _SIGHT_WIDEN)


def _in_sight(
    end: FloatArray, outward: FloatArray, reach: float, ranges: FloatArray, centre: FloatArray
) -> float:
    """How far (m, at most ``reach``) a chain end can move out along ``outward`` before its
    wall's line passes, for ``_SIGHT_HIDDEN`` or more, behind something its camera (at
    ``centre``) saw standing more than ``MAX_FURNITURE_DEPTH`` off the line (a pole or a
    chair's back hides less)."""
    steps = np.arange(0.0, reach + _SIGHT_STEP, _SIGHT_STEP)
    offset, distance, seen = _line_in_view(end, outward, np.minimum(steps, reach), ranges, centre)
    # How far off the wall's line what the camera saw stands (a wardrobe's side seen at a
    # slant is metres nearer along the ray, a furniture's depth off the line).
    off_line = (distance - seen) * np.abs(offset @ np.array([-outward[1], outward[0]])) / distance
    hidden = off_line > MAX_FURNITURE_DEPTH  # NaN: not hidden
    runs = np.convolve(hidden.astype(np.int64), np.ones(_SIGHT_LEAST, dtype=np.int64), "valid")
    first = np.flatnonzero(runs == _SIGHT_LEAST)
    return float(min(steps[first[0]], reach)) if len(first) else reach


def _wall_hiding(
    end: FloatArray,
    outward: FloatArray,
    reach: float,
    ranges: FloatArray,
    centre: FloatArray,
    lines: Sequence[WallLine],
    line: WallLine,
) -> float | None:
    """How far (m, 0 to ``reach``) a chain end can move out along ``outward`` when its
    wall's line ends up behind a wall across it; None when it does not.

    What hides the last ``_SIGHT_HIDDEN`` of the move from the camera (at ``centre``; its
    view ``ranges``) stands at one run coordinate along the line: a surface across the line
    that goes on as far as the view does, not a furniture front along it, nor the side of
    furniture that a front along the line follows. When a seen wall of the other axis lies
    at that run, the room's wall turns there: a corner whose wall furniture hid near the
    line (its segments stop short of it, so :func:`_wall_across` misses it) still ends the
    move, which :func:`_in_sight` stops only behind what stands a furniture's depth off the
    line.
    """
    # Short of the frustum's edge: the bins there hold the edge of the view.
    steps = np.arange(0.0, reach, _SIGHT_STEP)[-_SIGHT_LEAST:]
    if len(steps) < _SIGHT_LEAST:
        return None
    offset, distance, seen = _line_in_view(end, outward, steps, ranges, centre)
    if not np.all(distance - seen >= _ACROSS_NEARER):  # NaN: nothing seen that way
        return None
    run = (centre + (seen / distance)[:, None] * offset - end) @ outward
    if np.ptp(run) > _ACROSS_SPREAD:
        return None
    at = float(np.median(run))
    coordinate = float(end[line.axis] + at * outward[line.axis])
    walls = [other.offset for other in lines if not other.virtual and other.axis != line.axis]
    if not any(abs(wall - coordinate) <= _ACROSS_SPREAD for wall in walls):
        return None
    return min(max(at, 0.0), reach)


def _wall_around_opening(
    keypoints: FloatArray,
    aligned: FloatArray,
    normals: FloatArray,
    floor_z: float,
    view: CameraView,
) -> FloatArray | None:
    """The frame's wall when its one-wall chain was seen through an opening in it, else None.

    Through a door or a window a camera sees the next room's wall, full height and wider
    than the room's own wall beside or below the opening (a jamb, a pier, a sill), so the
    chain runs along the far wall. The room's wall is then a standing surface facing the
    same way, more than furniture stands (``MAX_FURNITURE_DEPTH``) in front of the far one,
    filling a good share of the view. Furniture that stands free in front of a wall shows
    its top or its sides to the camera, deeper than a wall is thick; a wall's opening shows
    only its reveals and sill. The returned chain runs along that surface from the
    frustum's right edge to its left (the part of the wall the frame looks at).

    keypoints: (2, 2) the chain; aligned, normals: (N, 3) the frame's points, aligned frame.
    """
    axis = run_axis(keypoints[1] - keypoints[0])
    across = 1 - axis
    centre = view.centre[:2]
    side = 1.0 if keypoints[0, across] > centre[across] else -1.0
    far = (keypoints[0, across] - centre[across]) * side
    depth = (aligned[:, across] - centre[across]) * side  # how far out, towards the far wall
    azimuth = np.degrees(np.arctan2(aligned[:, axis] - centre[axis], depth))
    facing = (np.abs(normals[:, 2]) < _UPRIGHT_SIN) & (np.abs(normals[:, across]) > _FACING_COS)
    nearer = facing & (depth > _NEAR_CAMERA) & (depth < far - MAX_FURNITURE_DEPTH)
    if np.count_nonzero(nearer) < _MIN_SURFACE_POINTS:
        return None
    peak = float(offset_peaks(depth[nearer], 0.0)[0])  # the strongest
    offset = float(np.median(depth[nearer & (np.abs(depth - peak) < _ON_LINE)]))
    surface = nearer & (np.abs(depth - offset) < _ON_LINE)
    # The share of the view's columns it shows up in (2-degree bins: a strided frame's
    # points leave some 1-degree bins empty at a meter or two).
    columns = np.unique(np.floor(azimuth[surface] / _COLUMN_DEGREES))
    cover = _COLUMN_DEGREES * len(columns) / np.degrees(view_angle([view]))
    if cover < _MIN_OPENING_COVER:
        return None
    # What lies just behind the surface's front, along it (its ends included): a top or a
    # side.
    lateral = aligned[:, axis]
    reach = lateral[surface]
    behind = (
        (depth > offset + _ON_LINE)
        & (depth < offset + MAX_FURNITURE_DEPTH)
        & (lateral >= reach.min() - _ON_LINE)
        & (lateral <= reach.max() + _ON_LINE)
    )
    top = behind & (normals[:, 2] > _FLAT_COS) & (aligned[:, 2] > floor_z + _MIN_HEIGHT)
    sides = behind & (np.abs(normals[:, axis]) > _FACING_COS)
    for part in (top, sides):
        deep = np.count_nonzero(part) >= _MIN_SURFACE_POINTS // 3 and (
            np.percentile(depth[part], 95) - offset > MAX_WALL_THICKNESS
        )
        if deep:
            return None
    rays = side_rays(view)  # right edge (the source), then left
    if np.any(rays[:, across] * side <= 0):
        return None  # an edge never reaches the surface
    wall: FloatArray = centre + rays * (offset / np.abs(rays[:, across]))[:, None]
    return wall


def _view_top(cameras: Sequence[FrameCamera], rotation: FloatArray) -> float:
    """How high the top of the view reaches at its middle column, radians above level: the
    highest of ``cameras`` (``rotation``: the fragment's local -> aligned)."""
    tops = []
    for camera in cameras:
        k = camera.intrinsics
        ray = rotation @ camera.pose[:3, :3] @ np.array([0.0, (-0.5 - k.cy) / k.fy, 1.0])
        tops.append(float(np.arcsin(np.clip(ray[2] / np.linalg.norm(ray), -1.0, 1.0))))
    return max(tops)


def estimate_frame_layout(
    points: FloatArray,
    cameras: Sequence[FrameCamera],
    params: PipelineParams = PipelineParams(),
    progress: ProgressFn | None = None,
    trace: ChainTrace | None = None,
) -> LocalLayout:
    """Estimate the wall chain seen by one or more RGB-D cameras.

    Parameters
    ----------
    points : (N, 3) float64, the fragment's local frame (the optical frame of its first
        camera), meters, finite.
    cameras : the cameras that saw them (at least one), posed in the local frame.
    params : all algorithm parameters (Manhattan and layout sections are used).
    progress : optional callback ``(stage, fraction)``.
    trace : optional callback ``(stage, keypoints)`` called with the chain after each of
        :data:`CHAIN_STAGES` it goes through (aligned frame; none without a chain): how
        benchmarks tell which step made a chain wrong.

    Returns
    -------
    LocalLayout
        As :func:`services.local_layout.estimate_local_layout`; ``frame.rotation`` maps the
        local (optical) frame to the aligned one.
    """
    if not cameras:
        raise ValueError("a frame layout needs at least one camera")
    report = progress or (lambda stage, fraction: None)
    report("manhattan", 0.0)
    cloud = thin_with_normals(
        points @ OPTICAL_TO_LEVEL.T, params.manhattan, params.layout.frame.max_voxels
    )
    level = OPTICAL_TO_LEVEL
    steep = steep_floor_tilt(cloud, params.manhattan, params.layout.frame.max_pitch_deg)
    if steep is not None:  # a camera looking steeply down: level it on the floor first
        level = steep @ OPTICAL_TO_LEVEL
        cloud = OrientedCloud(cloud.points @ steep.T, cloud.normals @ steep.T, cloud.spacing)
    # The level frame's up is within the camera's pitch and roll of the truth (well inside
    # the tilt limit), so the plane search that only seeds it can stop at the first planes.
    seed_search = {"max_planes": min(params.manhattan.max_planes, _SEED_PLANES)}
    # The camera's x axis is about horizontal: cameras pitch, they seldom roll.
    levelled = estimate_manhattan_frame(
        cloud, params.manhattan.model_copy(update=seed_search), level_axis=level[:, 0]
    )
    aligned = cloud.points @ levelled.rotation.T
    normals = cloud.normals @ levelled.rotation.T
    frame = ManhattanFrame(
        rotation=levelled.rotation @ level,
        floor_z=_floor(aligned, normals, params),
        ceiling_z=levelled.ceiling_z,
        n_planes=levelled.n_planes,
        wall_support=levelled.wall_support,
    )
    views = [
        CameraView.from_intrinsics(
            camera.intrinsics,
            frame.rotation @ camera.pose[:3, :3],
            frame.rotation @ camera.pose[:3, 3],
        )
        for camera in cameras
    ]
    report("walls", 0.4)
    lines = find_wall_lines(aligned, normals, frame.floor_z, frame.ceiling_z, params.layout, views)
    report("chain", 0.7)
    chain = find_wall_chain(lines, params.layout, views)
    # What the frame saw empty: the cells holding its points and those its rays crossed.
    seen = np.vstack([footprint_cells(aligned), swept_cells(views, aligned[:, :2], FOOTPRINT_CELL)])
    cells, _ = unique_cells(np.floor(seen / FOOTPRINT_CELL).astype(np.int64))
    footprint: FloatArray = ((cells + 0.5) * FOOTPRINT_CELL).astype(np.float64)
    across = view_angle(views)
    top = _view_top(cameras, frame.rotation)
    centres = np.array([view.centre[:2] for view in views], dtype=np.float64)
    # Merged frames have no one point their ranges are seen from.
    ranges = (
        view_ranges(aligned, centres[0], frame.floor_z, frame.ceiling_z)
        if len(views) == 1
        else np.zeros((0, 2))
    )
    if chain is None or len(chain.keypoints) < 2:
        report("done", 1.0)
        return LocalLayout(
            keypoints=np.zeros((0, 2)),
            frame=frame,
            footprint=footprint,
            evidence="frame",
            view_angle=across,
            view_top=top,
            cameras=centres,
            view_ranges=ranges,
        )
    note = trace or (lambda stage, keypoints: None)
    finish = functools.partial(
        _finished_chain,
        lines=lines,
        views=views,
        ranges=ranges,
        aligned=aligned,
        normals=normals,
        floor_z=frame.floor_z,
    )
    kp = finish(chain.keypoints, note)
    band, depth = params.layout.end_region_beyond, params.layout.end_region_depth
    runner_up = None
    if chain.runner_up is not None and len(chain.runner_up) >= 2:
        other = finish(chain.runner_up, lambda stage, keypoints: None)
        # Only a chain that differs from the chain by a front at most (or by its ends)
        # is offered: one cutting across a notch or an alcove the chain follows closed
        # rooms better on held-out frames and was wrong there.
        if (
            len(other) >= 2
            and not np.array_equal(other, kp)
            and side_by_side_depth(kp, other) <= FRONT_DEPTH
        ):
            runner_up = ChainVariant(other, *end_boundaries(aligned, other, band, depth))
    source_boundary, target_boundary = end_boundaries(aligned, kp, band, depth)
    report("done", 1.0)
    return LocalLayout(
        keypoints=kp,
        frame=frame,
        source_boundary=source_boundary,
        target_boundary=target_boundary,
        footprint=footprint,
        evidence="frame",
        view_angle=across,
        view_top=top,
        cameras=centres,
        view_ranges=ranges,
        runner_up=runner_up,
    )


def _finished_chain(
    keypoints: FloatArray,
    note: ChainTrace,
    lines: Sequence[WallLine],
    views: Sequence[CameraView],
    ranges: FloatArray,
    aligned: FloatArray,
    normals: FloatArray,
    floor_z: float,
) -> FloatArray:
    """The wall graph's chain through the frame's later steps (:data:`CHAIN_STAGES`),
    ``note`` called after each."""
    note("graph", keypoints)
    kp = _without_furniture(keypoints, lines)
    note("furniture", kp)
    kp = _to_frustum_edges(kp, lines, views, ranges)
    note("frustum edges", kp)
    kp = without_corners_seen_past(kp, lines)
    note("corners seen past", kp)
    # An end wall's length is known once it reaches the view's edge.
    kp = _drop_end_sides(kp, views, aligned, floor_z)
    note("end sides", kp)
    if len(kp) == 2 and len(views) == 1:
        around = _wall_around_opening(kp, aligned, normals, floor_z, views[0])
        kp = kp if around is None else around
    note("opening", kp)
    return kp


def estimate_rgbd_layout(
    frame: RgbdFrame,
    params: PipelineParams = PipelineParams(),
    progress: ProgressFn | None = None,
    trace: ChainTrace | None = None,
) -> LocalLayout:
    """Local layout of one RGB-D frame (its local frame is its optical frame; ``trace`` as
    :func:`estimate_frame_layout` takes it)."""
    return estimate_frame_layout(
        frame_points(frame, params), [FrameCamera(frame.intrinsics)], params, progress, trace
    )
