"""Scoring helpers shared by the placement benchmarks: the true assembly of a scene, a
candidate assembly as a result, a result's alternatives as results of their own, the map of
the confidence's logit fitted for one kind of evidence, and a chain's error in the floor
plan."""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from schemas.params import PipelineParams, PlacementParams
from services.evaluation import keypoint_error
from services.geometry import distance_to_chain
from services.layout_model import build_polygon
from services.pipeline import fragment_pose
from services.placement import Piece, PlacementCandidate, translations_of
from services.placement.priors import chain_placement
from services.refinement import refine_translations
from services.types import FloatArray, LocalLayout

__all__ = [
    "add_params_option",
    "alternative_results",
    "candidate_result",
    "chain_error_in_plan",
    "chain_on_truth",
    "chain_samples",
    "fit_logistic",
    "fit_logit_map",
    "fit_logit_shift",
    "main_room_verdict",
    "params_with",
    "share_interval",
    "true_assembly",
]


def true_assembly(
    truth: Mapping[str, Any], layouts: Mapping[str, LocalLayout], ids: Sequence[str]
) -> tuple[list[str], list[int]]:
    """Loop order (starting at ``ids[0]``) and quarter turns (relative to ``ids[0]``) of
    the ground truth, for the pieces made of ``layouts[ids]``."""
    frags = {f["id"]: f for f in truth["fragments"]}

    def yaw(fid: str) -> float:
        return chain_placement(layouts[fid], np.asarray(frags[fid]["pose"]))[0]

    first = yaw(ids[0])
    turns = {fid: round((yaw(fid) - first) / (math.pi / 2)) % 4 for fid in ids}
    loop = sorted(ids, key=lambda fid: frags[fid]["loop_index"])
    k = loop.index(ids[0])
    order = loop[k:] + loop[:k]
    return order, [turns[fid] for fid in order]


def candidate_result(
    cand: PlacementCandidate,
    pieces: Sequence[Piece],
    layouts: Mapping[str, LocalLayout],
    params: PlacementParams = PlacementParams(),
) -> dict[str, Any]:
    """A candidate as a result JSON (poses and floorplan after refinement, as the pipeline
    would report it), for :func:`services.evaluation.evaluate_result`."""
    by_id = {p.id: p for p in pieces}
    chains = [by_id[fid] for fid in cand.order]
    translations = translations_of(pieces, cand)
    refined = refine_translations(chains, cand.rotations, translations, params, shared=cand.shared)
    if refined.status == "solved" or refined.status.startswith("relaxed"):
        translations = refined.translations
    fragments = [
        {
            "id": fid,
            "placed": True,
            "pose": fragment_pose(layouts[fid], rotation, translations[k]).tolist(),
            "local_layout": {"keypoints": layouts[fid].keypoints_local().tolist()},
        }
        for k, (fid, rotation) in enumerate(zip(cand.order, cand.rotations, strict=True))
    ]
    polygon = build_polygon(chains, cand.rotations, translations, cand.shared)
    return {
        "fragments": fragments,
        "floorplan": {"rooms": [{"id": "r", "polygon": polygon.tolist()}]},
    }


def alternative_results(result: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Each alternative of a result JSON as a result of its own (local layouts kept)."""
    out = []
    for alternative in result.get("alternatives", []):
        poses = {f["id"]: f["pose"] for f in alternative["fragments"]}
        fragments = [
            {**f, "pose": poses.get(f["id"]), "placed": f["id"] in poses}
            for f in result["fragments"]
        ]
        out.append({"fragments": fragments, "floorplan": alternative["floorplan"]})
    return out


def main_room_verdict(result: Mapping[str, Any], reported_right: bool) -> tuple[float, bool] | None:
    """(confidence, right) of a result's main room, None when its loop did not close.

    What a confidence map is fitted on: every result with a main room, whatever its status
    (a lone room the confidence doubts is reported 'open' with its floorplan).
    ``reported_right``: the result's own verdict (``evaluate_result``).
    """
    if result["status"] == "failed" or not result.get("floorplan", {}).get("rooms"):
        return None
    return float(result["confidence"]), reported_right


def fit_logit_map(
    confidences: Sequence[float],
    right: Sequence[bool],
    closed: float,
    extra: Sequence[float] | None = None,
) -> tuple[tuple[float, ...], str]:
    """A map (bias, slope) of the confidence's logit for one kind of evidence
    (``PlacementParams.frame_calibration``, ``thin_cloud_calibration``): logistic regression
    of the main rooms' verdicts on the logits of their confidences, computed with the map off
    (:func:`main_room_verdict`). With ``extra`` (one value per room, e.g. the frames' view
    angle beyond the kinect's) the map is (bias, slope, per unit of it). Returns it and a
    line on what it does to those rooms at the ``closed`` threshold."""
    conf = np.clip(np.asarray(confidences, dtype=np.float64), 1e-9, 1 - 1e-9)
    logit = np.log(conf / (1 - conf))
    ok = np.asarray(right, dtype=bool)
    columns = [np.ones_like(logit), logit]
    if extra is not None:
        columns.append(np.asarray(extra, dtype=np.float64))
    inputs = np.column_stack(columns)
    coefficients = fit_logistic(inputs, ok)
    mapped = 1.0 / (1.0 + np.exp(-(inputs @ coefficients)))
    summary = (
        f"{len(ok)} main rooms, {int(ok.sum())} right; at >= {closed}: before "
        f"{int((conf >= closed).sum())} closed ({int(ok[conf >= closed].sum())} right), after "
        f"{int((mapped >= closed).sum())} ({int(ok[mapped >= closed].sum())} right); Brier "
        f"{float(np.mean((conf - ok) ** 2)):.3f} -> {float(np.mean((mapped - ok) ** 2)):.3f}"
    )
    return tuple(round(float(c), 3) for c in coefficients), summary


def fit_logit_shift(
    confidences: Sequence[float], right: Sequence[bool], extra: Sequence[float]
) -> tuple[float, str]:
    """The slope (at most 0) by which ``extra`` (one value per room, 0 where the map was
    fitted) moves the confidence's logit, the rest of the map kept: the most likely of
    logit + slope * extra for the rooms' verdicts. Returns it and a line on the rooms with
    some ``extra`` (their mean confidence and share right, Brier before and after).

    >>> slope, _ = fit_logit_shift([0.8] * 4, [True, False, False, False], [1.0] * 4)
    >>> round(slope, 3)  # logit(0.25) - logit(0.8) = -2.4849
    -2.485
    """
    conf = np.clip(np.asarray(confidences, dtype=np.float64), 1e-9, 1 - 1e-9)
    logit = np.log(conf / (1 - conf))
    ok = np.asarray(right, dtype=np.float64)
    more = np.asarray(extra, dtype=np.float64)

    def loss(slope: float) -> float:
        z = logit + slope * more
        return float(np.sum(np.logaddexp(0.0, z) - ok * z))

    slope = float(
        minimize_scalar(loss, bounds=(-30.0, 0.0), method="bounded", options={"xatol": 1e-8}).x
    )
    moved = more > 0
    after = 1.0 / (1.0 + np.exp(-(logit + slope * more)))
    summary = (
        f"{int(moved.sum())} of {len(ok)} main rooms beyond the fitted: mean confidence "
        f"{conf[moved].mean():.2f} -> {after[moved].mean():.2f}, right {ok[moved].mean():.2f}; "
        f"Brier {float(np.mean((conf[moved] - ok[moved]) ** 2)):.3f} -> "
        f"{float(np.mean((after[moved] - ok[moved]) ** 2)):.3f}"
        if moved.any()
        else f"none of {len(ok)} main rooms beyond the fitted"
    )
    return slope, summary


def fit_logistic(inputs: np.ndarray, right: np.ndarray, ridge: float = 0.1) -> np.ndarray:
    """Coefficients of P(right) = sigmoid(c . inputs), maximum likelihood with a ridge
    (the bias is not penalised)."""
    penalty = np.ones(inputs.shape[1])
    penalty[0] = 0.0

    def loss(c: np.ndarray) -> tuple[float, np.ndarray]:
        z = inputs @ c
        p = 1.0 / (1.0 + np.exp(-z))
        nll = float(np.sum(np.logaddexp(0.0, z) - right * z)) + ridge * float(penalty @ c**2)
        return nll, inputs.T @ (p - right) + 2 * ridge * penalty * c

    start = np.zeros(inputs.shape[1])
    start[1] = 1.0
    return np.asarray(minimize(loss, start, jac=True, method="L-BFGS-B").x)


def share_interval(right: int, total: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval (95 % for z = 1.96) of a share right, ``right`` of ``total``:
    what the benchmark's 20-30 scenes per bucket can and cannot tell apart.

    >>> [round(x, 3) for x in share_interval(11, 21)]
    [0.324, 0.717]
    """
    if total == 0:
        return 0.0, 1.0
    share, scale = right / total, z * z / total
    centre = (share + scale / 2) / (1 + scale)
    half = z * math.sqrt(share * (1 - share) / total + scale / (4 * total)) / (1 + scale)
    return max(0.0, centre - half), min(1.0, centre + half)


def params_with(settings: Iterable[str]) -> PipelineParams:
    """The default parameters with ``SECTION.FIELD=VALUE`` settings applied (VALUE as JSON,
    or else a string; a nested section is spelled out, ``layout.frame.min_inliers``),
    validated: how a benchmark measures a change without editing code.

    >>> params_with(["placement.weight_outside=0"]).placement.weight_outside
    0.0
    >>> params_with(["layout.frame.min_inliers=50"]).layout.frame.min_inliers
    50
    """
    data = PipelineParams().model_dump()
    for setting in settings:
        key, _, raw = setting.partition("=")
        *path, name = key.split(".")
        if not path:
            raise ValueError(f"{key!r}: no parameter section")
        section = data
        for k, part in enumerate(path):
            if not isinstance(section.get(part), dict):
                raise ValueError(f"no parameter section {'.'.join(path[: k + 1])!r}")
            section = section[part]
        if name not in section:
            raise ValueError(f"{'.'.join(path)}: no parameter [{name!r}]")
        try:
            section[name] = json.loads(raw)
        except json.JSONDecodeError:
            section[name] = raw
    return PipelineParams.model_validate(data)


def add_params_option(parser: argparse.ArgumentParser) -> None:
    """A benchmark's ``--set SECTION.FIELD=VALUE`` option (repeatable), read by
    :func:`params_with`."""
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.FIELD=VALUE",
        help="an algorithm parameter other than its default, e.g. placement.use_outside=false",
    )


def chain_samples(chain: FloatArray, per_wall: int) -> FloatArray:
    """(S, 2) points along a (K, 2) chain's walls, ``per_wall`` evenly from each wall's
    start to its end (both included).

    >>> chain_samples(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0]]), 3).tolist()
    [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [2.0, 0.0], [2.0, 0.5], [2.0, 1.0]]
    """
    share = np.linspace(0.0, 1.0, per_wall)[None, :, None]
    points: FloatArray = chain[:-1, None, :] + share * (chain[1:] - chain[:-1])[:, None, :]
    return points.reshape(-1, 2)


def chain_on_truth(
    estimated_local: Any, fragment: Mapping[str, Any], tolerance: float = 0.15
) -> bool:
    """Whether a fragment's chain (K >= 2) lies on its true chain in the floor plan: every
    point of its walls within ``tolerance`` m of the true walls (seen from above, world
    frame). Such a chain may miss part of its stretch (a piece seen past a protruding corner
    left out) but places no wall where there is none.

    estimated_local: (K, 3) fragment-local keypoints; fragment: its ground truth JSON
    (``pose`` local -> world, ``keypoints_local``).
    """
    est = np.asarray(estimated_local, dtype=np.float64).reshape(-1, 3)
    if len(est) < 2:
        return False
    pose = np.asarray(fragment["pose"], dtype=np.float64)
    true_local = np.asarray(fragment["keypoints_local"], dtype=np.float64).reshape(-1, 3)
    plan, true = ((k @ pose[:3, :3].T + pose[:3, 3])[:, :2] for k in (est, true_local))
    return bool(np.all(distance_to_chain(chain_samples(plan, 21), true) <= tolerance))


def chain_error_in_plan(estimated_local: Any, fragment: Mapping[str, Any]) -> float:
    """Mean keypoint error (m, :func:`services.evaluation.keypoint_error`) of a fragment's
    chain against its truth, both seen along the fragment's true up axis: the floor plan's
    error, whatever floor height each was put at; inf for an empty chain.

    estimated_local: (K, 3) fragment-local keypoints; fragment: its ground truth JSON
    (``pose`` local -> world, ``keypoints_local``).
    """
    up = np.asarray(fragment["pose"], dtype=np.float64)[2, :3]  # world z in local axes
    flat = np.eye(3) - np.outer(up, up)
    est = np.asarray(estimated_local, dtype=np.float64).reshape(-1, 3)
    true = np.asarray(fragment["keypoints_local"], dtype=np.float64)
    return keypoint_error(est @ flat, true @ flat)
