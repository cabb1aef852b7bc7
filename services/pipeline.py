"""Orchestrator: the pipeline's stages in order, no I/O.

``estimate_layout`` is the per-fragment stage (one job per fragment in the service);
``place_site`` is the global stage (one job per site): placement, refinement, floorplan,
and the contract's result.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from schemas.hints import HintsModel
from schemas.params import PipelineParams
from schemas.result import (
    FloorplanModel,
    FragmentResultModel,
    LocalLayoutModel,
    ResultModel,
    RoomModel,
)
from services.layout_model import build_polygon
from services.local_layout import estimate_local_layout
from services.placement import Placement, make_piece, place_pieces, rot90
from services.refinement import Refinement, refine_translations
from services.registration import premerge
from services.types import FloatArray, LocalLayout, ProgressFn

__all__ = ["ProgressFn", "align_clouds", "estimate_layout", "fragment_pose", "place_site"]


def estimate_layout(
    points: FloatArray,
    params: PipelineParams = PipelineParams(),
    progress: ProgressFn | None = None,
) -> LocalLayout:
    """Local layout of one fragment; see :func:`services.local_layout.estimate_local_layout`."""
    return estimate_local_layout(points, params, progress)


def fragment_pose(layout: LocalLayout, rotation: int, source_site: FloatArray) -> FloatArray:
    """4x4 pose mapping fragment-local points to the site frame.

    The Manhattan alignment (tilt included), then ``rotation`` quarter turns about z, then
    the translation that puts the chain's source at ``source_site`` and the floor at z = 0.
    """
    spin = np.eye(3)
    spin[:2, :2] = rot90(rotation)
    pose = np.eye(4)
    pose[:3, :3] = spin @ layout.frame.rotation
    pose[:2, 3] = source_site - rot90(rotation) @ layout.keypoints[0]
    pose[2, 3] = -layout.frame.floor_z
    return pose


def _room_height(layouts: Sequence[LocalLayout]) -> float | None:
    heights = [
        lay.frame.ceiling_z - lay.frame.floor_z
        for lay in layouts
        if lay.frame.ceiling_z is not None
    ]
    return float(np.median(heights)) if heights else None


def _diagnostics(
    placement: Placement, refinement_status: str, gaps: tuple[float, float]
) -> dict[str, Any]:
    best = placement.best
    return {
        "energy": {
            "total": best.energy,
            "complexity": best.complexity,
            "closure": best.closure,
            "boundary": best.boundary,
        },
        "energy_margin": (
            placement.alternatives[0].energy - best.energy if placement.alternatives else None
        ),
        "alternatives": [
            {"energy": alt.energy, "order": list(alt.order), "rotations": list(alt.rotations)}
            for alt in placement.alternatives
        ],
        "search": {"nodes": placement.nodes_searched, "exhaustive": placement.exhaustive},
        "refinement": {
            "status": refinement_status,
            "violation_before": gaps[0],
            "violation_after": gaps[1],
        },
    }


def place_site(
    layouts: Mapping[str, LocalLayout],
    params: PipelineParams = PipelineParams(),
    progress: ProgressFn | None = None,
    hints: HintsModel | None = None,
) -> ResultModel:
    """Place every fragment of a site and build the contract's result.

    Parameters
    ----------
    layouts : local layout per fragment id; fragments keep this order in the result.
    params : algorithm parameters (placement section used here).
    progress : optional callback ``(stage, fraction)``.
    hints : optional fleet knowledge: prior poses, known neighbours, known order.
    """
    report = progress or (lambda stage, fraction: None)
    fragments = {
        fid: FragmentResultModel(
            id=fid,
            placed=False,
            local_layout=LocalLayoutModel(keypoints=lay.keypoints_local().tolist()),
        )
        for fid, lay in layouts.items()
    }
    usable = [fid for fid, lay in layouts.items() if lay.ok]
    report("placement", 0.1)
    pieces = {fid: make_piece(fid, layouts[fid]) for fid in usable}
    order_hint = hints.order if hints else None
    neighbours = hints.neighbours if hints else ()
    placement = place_pieces(list(pieces.values()), params.placement, order_hint, neighbours)
    if placement is None:
        report("done", 1.0)
        return ResultModel(
            status="failed",
            fragments=list(fragments.values()),
            diagnostics={"reason": "no fragment shows a wall"},
        )
    report("refinement", 0.7)
    best = placement.best
    ordered = [pieces[fid] for fid in best.order]
    if placement.closed:
        refined = refine_translations(ordered, best.rotations, placement.translations)
    else:
        # An open chain is already joined end to end; there is no loop to refine.
        refined = Refinement(placement.translations, "skipped: open chain", 0.0, 0.0)
    translations = refined.translations
    for index, (fid, rotation) in enumerate(zip(best.order, best.rotations, strict=True)):
        pose = fragment_pose(layouts[fid], rotation, translations[index])
        fragments[fid].placed = True
        fragments[fid].pose = pose.tolist()
        fragments[fid].loop_index = index
    loop_length = sum(float(np.abs(np.diff(p.keypoints, axis=0)).sum()) for p in ordered)
    gap_limit = max(1.0, params.placement.max_closure_share * loop_length)
    closed = (
        placement.closed
        and best.closure <= gap_limit
        and len(best.order) == len(layouts)
        and len(usable) >= 2
        and refined.status == "solved"
        and refined.violation_after <= params.placement.closure_tolerance
    )
    rooms = []
    if closed:
        polygon = build_polygon(ordered, best.rotations, translations)
        height = _room_height([layouts[fid] for fid in usable])
        rooms.append(
            RoomModel(id="room_0", polygon=polygon.tolist(), floor_z=0.0, ceiling_z=height)
        )
    report("done", 1.0)
    return ResultModel(
        status="closed" if closed else "open",
        fragments=list(fragments.values()),
        floorplan=FloorplanModel(rooms=rooms),
        diagnostics=_diagnostics(
            placement, refined.status, (refined.violation_before, refined.violation_after)
        ),
    )


def align_clouds(
    clouds: Mapping[str, FloatArray],
    params: PipelineParams = PipelineParams(),
    progress: ProgressFn | None = None,
    premerge_overlapping: bool = False,
    hints: HintsModel | None = None,
) -> ResultModel:
    """The whole pipeline on in-memory fragments (the CLI's ``align``).

    With ``premerge_overlapping``, fragments whose FPFH registration has more than the
    configured share of inliers are first merged (paper section 3); every input fragment
    still gets its own pose (the group's pose composed with its registration).

    Parameters
    ----------
    clouds : id -> (N, 3) float64, fragment-local points, meters.
    params : algorithm parameters.
    progress : optional callback ``(stage, fraction)``.
    premerge_overlapping : run the FPFH pre-merge first.
    hints : optional fleet knowledge (see :func:`place_site`).
    """
    report = progress or (lambda stage, fraction: None)
    groups: dict[str, dict[str, FloatArray]] = {fid: {fid: np.eye(4)} for fid in clouds}
    merged: Mapping[str, FloatArray] = clouds
    if premerge_overlapping and len(clouds) > 1:
        report("pre-merge", 0.0)
        result = premerge(clouds, params.registration)
        groups = {g.anchor_id: dict(g.transforms) for g in result.groups}
        merged = {g.anchor_id: g.points for g in result.groups}
    layouts = {}
    for index, (gid, points) in enumerate(merged.items()):
        report(f"local layout {gid}", index / max(len(merged), 1))
        layouts[gid] = estimate_layout(points, params)
    report("placement", 0.9)
    placed = place_site(layouts, params, hints=hints)
    return _expand_groups(placed, groups, list(clouds))


def _expand_groups(
    result: ResultModel, groups: Mapping[str, Mapping[str, FloatArray]], order: Sequence[str]
) -> ResultModel:
    """One result entry per input fragment: members inherit their group's placement."""
    by_group = {f.id: f for f in result.fragments}
    fragments = {}
    for gid, members in groups.items():
        entry = by_group[gid]
        for fid, to_anchor in members.items():
            back = np.linalg.inv(to_anchor)
            keypoints = np.asarray(entry.local_layout.keypoints, dtype=np.float64).reshape(-1, 3)
            local = keypoints @ back[:3, :3].T + back[:3, 3]
            pose = None if entry.pose is None else (np.asarray(entry.pose) @ to_anchor).tolist()
            fragments[fid] = entry.model_copy(
                update={
                    "id": fid,
                    "pose": pose,
                    "local_layout": LocalLayoutModel(keypoints=local.tolist()),
                    "merged_into": gid if fid != gid else None,
                }
            )
    closed = result.status == "closed" and all(f.placed for f in fragments.values())
    return result.model_copy(
        update={
            "status": "closed" if closed else result.status,
            "fragments": [fragments[fid] for fid in order],
        }
    )
