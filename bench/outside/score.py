"""One scene's result scored against its truth, for cloud and frame scenes alike.

The truth's polygon is brought into the result's site frame through an anchor fragment f,
``T = pose_est[f] @ inv(pose_true[f])`` (world to site), every placed fragment tried as the
anchor and the best kept (right first, then strict, then the smallest polygon error, then
the smallest mean translation error). For that anchor:

- ``poly_err``: mean of (true corner to nearest estimated corner) and (estimated to nearest
  true), over the truth's bounding-box diagonal;
- ``acc``: ``poly_err < 5 %``, the paper's ACC_global;
- ``acc_strict``: ``acc`` and as many corners as the truth;
- ``yaw_err`` (degrees) and ``trans_err`` (% of the diagonal) of each placed fragment: the
  yaw of the rotation from its true pose (in the site) to its estimated one, and the
  horizontal distance between its reference point placed both ways (a cloud fragment's
  centroid, a frame's camera centre);
- ``right``: ``acc_strict`` and every fragment placed within 10 degrees and 10 %.

``top3``: the main room or one of the first two alternatives is right. No I/O here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from bench.outside.clouds import FloatArray

__all__ = [
    "POSE_DEG",
    "POSE_PCT",
    "corner_distance",
    "evaluate_assembly",
    "main_polygon",
    "score_result",
    "true_fragments",
    "truth_result",
]

POSE_DEG = 10.0  # a fragment's largest yaw error, degrees ...
POSE_PCT = 10.0  # ... and translation error, % of the diagonal, in a right assembly
ACC = 0.05  # ACC_global's threshold, share of the diagonal


def true_fragments(truth: Mapping[str, Any]) -> dict[str, tuple[FloatArray, FloatArray]]:
    """Id to (true pose, 4x4 fragment-local to world; reference point, (3,) local) of a
    cloud scene's ``fragments`` (the centroid) or a frame scene's ``frames`` (the camera)."""
    if "fragments" in truth:
        return {
            f["id"]: (np.asarray(f["pose"], float), np.asarray(f["centroid_local"], float))
            for f in truth["fragments"]
        }
    return {k: (np.asarray(v["pose"], float), np.zeros(3)) for k, v in truth["frames"].items()}


def corner_distance(A: Any, B: Any) -> float:
    """Mean of the nearest-corner distances both ways between two corner sets (inf if one is
    empty).

    >>> corner_distance([[0, 0], [1, 0]], [[0, 0]])
    0.25
    >>> corner_distance([], [[0, 0]])
    inf
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    if len(A) == 0 or len(B) == 0:
        return float("inf")
    D = np.linalg.norm(A[:, None, :] - B[None, :, :], axis=2)
    return float(0.5 * (D.min(1).mean() + D.min(0).mean()))


def _area(p: Any) -> float:
    p = np.asarray(p, float)
    return abs(0.5 * float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])))


def main_polygon(floorplan: Mapping[str, Any] | None) -> tuple[FloatArray | None, int]:
    """The largest room polygon of a result's floorplan (None if there is none), and the
    number of rooms."""
    rooms = (floorplan or {}).get("rooms") or []
    polys = [r.get("polygon") for r in rooms if r.get("polygon")]
    if not polys:
        return None, len(rooms)
    return np.asarray(max(polys, key=_area), float), len(rooms)


def _yaw_deg(R: FloatArray) -> float:
    return abs(math.degrees(math.atan2(R[1, 0], R[0, 0])))


def _anchored(
    truth: Mapping[str, Any], poses: Mapping[str, FloatArray], polygon: FloatArray | None, a: str
) -> dict[str, Any]:
    """The scores of an assembly with fragment ``a`` as the anchor."""
    frags = true_fragments(truth)
    Pt = np.asarray(truth["polygon"], float)
    diag = float(np.linalg.norm(Pt.max(0) - Pt.min(0)))
    T = poses[a] @ np.linalg.inv(frags[a][0])  # world to site
    perr = float("inf")
    if polygon is not None and len(polygon):
        Q = np.column_stack([Pt, np.zeros(len(Pt)), np.ones(len(Pt))]) @ T.T
        perr = corner_distance(Q[:, :2], polygon) / diag
    yaw_err, trans_err = {}, {}
    for g, Pe in poses.items():
        Pw = T @ frags[g][0]
        yaw_err[g] = _yaw_deg(Pe[:3, :3] @ Pw[:3, :3].T)
        c = np.append(frags[g][1], 1.0)
        trans_err[g] = 100.0 * float(np.linalg.norm((Pe @ c)[:2] - (Pw @ c)[:2])) / diag
    n_est = 0 if polygon is None else len(polygon)
    acc = perr < ACC
    strict = acc and n_est == len(Pt)
    good = [g for g in poses if yaw_err[g] < POSE_DEG and trans_err[g] < POSE_PCT]
    poses_ok = len(good) == len(frags)
    return dict(
        anchor=a, poly_err=perr, acc=bool(acc), acc_strict=bool(strict), poses_ok=poses_ok,
        right=bool(strict and poses_ok), n_corners_est=n_est, n_corners_true=len(Pt),
        yaw_err=yaw_err, trans_err=trans_err, consistent=len(good),
    )  # fmt: skip


def evaluate_assembly(
    truth: Mapping[str, Any], poses: Mapping[str, Any], polygon: FloatArray | None
) -> dict[str, Any]:
    """An assembly scored through its best anchor (see the module's docstring).

    Parameters
    ----------
    truth : mapping
        A scene's ``truth.json``.
    poses : mapping
        Fragment id to its estimated pose (4x4, fragment-local to site) or None (not placed).
    polygon : (K, 2) array or None
        The estimated main room, site frame, meters.

    Returns
    -------
    dict
        ``anchor``, ``poly_err``, ``acc``, ``acc_strict``, ``poses_ok``, ``right``, corner
        counts, ``yaw_err`` and ``trans_err`` (id to error), ``max_consistent`` (the most
        fragments within 10 degrees and 10 % for one anchor).
    """
    ids = true_fragments(truth)
    placed = {k: np.asarray(p, float) for k, p in poses.items() if p is not None and k in ids}
    recs = [_anchored(truth, placed, polygon, a) for a in ids if a in placed]
    if not recs:
        return dict(
            anchor=None, poly_err=float("inf"), acc=False, acc_strict=False, poses_ok=False,
            right=False, n_corners_est=0 if polygon is None else len(polygon),
            n_corners_true=len(truth["polygon"]), yaw_err={}, trans_err={}, max_consistent=0,
        )  # fmt: skip

    def key(r: dict[str, Any]) -> tuple[bool, bool, float, float]:
        return (
            not r["right"],
            not r["acc_strict"],
            r["poly_err"],
            np.mean([*r["trans_err"].values()]),
        )

    best = min(recs, key=key)
    best["max_consistent"] = max(r.pop("consistent") for r in recs)
    return best


def _poses(fragments: list[dict[str, Any]]) -> dict[str, Any]:
    """Id to pose of a result's (or an alternative's) placed fragments."""
    return {f["id"]: f.get("pose") for f in fragments if f.get("placed", True) and f.get("pose")}


def score_result(truth: Mapping[str, Any], result: Mapping[str, Any] | None) -> dict[str, Any]:
    """A result (the CLI's JSON; None when there is none) scored against the truth:
    ``status``, ``confidence``, ``main`` (:func:`evaluate_assembly` of the main room),
    ``alts`` (the first two alternatives), ``top3``, ``placed`` and ``n_alternatives``."""
    if result is None:
        none = evaluate_assembly(truth, {}, None)
        return dict(status="none", confidence=None, main=none, alts=[], top3=False, placed=0,
                    n_alternatives=0)  # fmt: skip
    poses = _poses(result.get("fragments") or [])
    main = evaluate_assembly(truth, poses, main_polygon(result.get("floorplan"))[0])
    alternatives = result.get("alternatives") or []
    alts = []
    for a in alternatives[:2]:
        polygon = main_polygon(a.get("floorplan"))[0]
        alts.append(dict(evaluate_assembly(truth, _poses(a.get("fragments") or []), polygon),
                         probability=a.get("probability")))  # fmt: skip
    return dict(
        status=result.get("status"), confidence=result.get("confidence"), main=main, alts=alts,
        top3=bool(main["right"] or any(a["right"] for a in alts)), placed=len(poses),
        n_alternatives=len(alternatives), n_rooms=main_polygon(result.get("floorplan"))[1],
    )  # fmt: skip


def truth_result(truth: Mapping[str, Any], site: Any = None) -> dict[str, Any]:
    """The truth written as a result (schema 2, status closed) in a site frame (``site``:
    4x4 world to site, identity by default): what a perfect run would give."""
    S = np.eye(4) if site is None else np.asarray(site, float)
    P = np.asarray(truth["polygon"], float)
    Q = np.column_stack([P, np.zeros(len(P)), np.ones(len(P))]) @ S.T
    fragments = [
        dict(id=k, placed=True, pose=(S @ pose).tolist(), loop_index=i,
             local_layout=dict(keypoints=[]))
        for i, (k, (pose, _)) in enumerate(true_fragments(truth).items())
    ]  # fmt: skip
    return dict(
        schema_version=2, status="closed", confidence=1.0, fragments=fragments,
        floorplan=dict(rooms=[dict(id="room_0", polygon=Q[:, :2].tolist())]), alternatives=[],
    )  # fmt: skip
