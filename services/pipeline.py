"""Orchestrator: the pipeline's stages in order, no I/O.

``estimate_layout`` is the per-fragment stage (one job per fragment in the service);
``place_site`` is the global stage (one job per site): placement, refinement, floorplan,
and the contract's result. ``align_fragments`` runs both on a set of decoded fragments (the
CLI), merging overlapping ones first, and returns the layouts with the result.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from schemas.hints import HintsModel
from schemas.params import PipelineParams, PlacementParams
from schemas.result import (
    AlternativeFragmentModel,
    AlternativeModel,
    FloorplanModel,
    FragmentResultModel,
    LocalLayoutModel,
    ResultModel,
    RoomModel,
)
from services.confidence import (
    Assembly,
    floorplan_diagonal,
    fragment_confidences,
    rank_assemblies,
    same_room,
)
from services.end_walls import END_WALLS, flattened_end_step, without_end_wall
from services.fragments import Fragment, fragment_layout, fragment_points
from services.frame_merge import (
    FrameGroup,
    expand_frame_groups,
    group_frames,
    group_layout,
    station_groups,
)
from services.geometry import is_simple_rectilinear
from services.layout_model import build_polygon
from services.local_layout import estimate_local_layout
from services.open_ends import open_ends
from services.placement import (
    Piece,
    Placement,
    PlacementCandidate,
    SiteHints,
    hint_pairs,
    make_piece,
    open_end_count,
    piece_prior,
    place_pieces,
    rot90,
)
from services.placement.corners import corner_offsets
from services.placement.priors import (
    chain_placement,
    fit_frame,
    wrap_angle,
)
from services.refinement import (
    Refinement,
    prior_anchors,
    refine_translations,
    widest_slide,
)
from services.registration import premerge
from services.rgbd import RgbdFrame
from services.stations import with_station_cost
from services.types import FloatArray, LocalLayout, ParsedFragment, ProgressFn
from services.view_ranges import station_mates
from services.wall_evidence import unexplained_walls

__all__ = [
    "Alignment",
    "ProgressFn",
    "align_clouds",
    "align_fragments",
    "estimate_layout",
    "fragment_pose",
    "place_site",
    "site_pieces",
]


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


@dataclass(frozen=True)
class _Placed:
    """One assembly made concrete: refined translations, poses, floorplan (site frame).

    rectilinear: the floorplan is a simple rectilinear polygon in the search's frame (the
    hints' frame may turn it by any angle, so it is checked before).
    """

    assembly: Assembly | None
    candidate: PlacementCandidate
    refinement: Refinement
    poses: dict[str, FloatArray]
    polygon: FloatArray | None
    rectilinear: bool = True


def site_pieces(
    layouts: Mapping[str, LocalLayout],
    usable: Sequence[str],
    hints: HintsModel | None,
    params: PlacementParams = PlacementParams(),
) -> tuple[dict[str, Piece], SiteHints]:
    """The pieces of fragments ``usable`` as the search takes them, the fixed first one
    first (:func:`_root_first`), each with the frames that share its camera, and the hints
    resolved to them. ``layouts`` snapped (:meth:`LocalLayout.snapped`), as
    :func:`place_site` places them."""
    site_hints = _site_hints(layouts, usable, hints)
    # The search starts from the smallest id, not the first upload: the same fragments give
    # the same answer (and site frame) whatever order they arrived in.
    first = _root_first(sorted(usable), site_hints)
    mates = station_mates({fid: layouts[fid] for fid in first}, params)
    pieces = {
        fid: dataclasses.replace(
            make_piece(fid, layouts[fid]),
            station_mates=tuple(sorted(mates[fid].items())),
            open_ends=open_ends(
                layouts[fid], math.radians(params.open_end_angle), params.open_end_least_view
            ),
        )
        for fid in first
    }
    return pieces, site_hints


def _site_hints(
    layouts: Mapping[str, LocalLayout], usable: Sequence[str], hints: HintsModel | None
) -> SiteHints:
    if hints is None:
        return SiteHints()
    priors = {
        fid: piece_prior(layouts[fid], prior)
        for fid, prior in hints.fragments.items()
        if fid in usable
    }
    return SiteHints(priors, hint_pairs(hints.neighbours, hints.order))


def _root_first(usable: list[str], hints: SiteHints) -> list[str]:
    """The fixed first piece: with priors, the most certain one (the site frame then
    follows the hints' frame most closely); else the first fragment."""
    if not hints.priors:
        return usable
    root = min(hints.priors, key=lambda fid: (hints.priors[fid].source_sigma, fid))
    return [root, *(fid for fid in usable if fid != root)]


def _concrete(
    layouts: Mapping[str, LocalLayout],
    pieces: Mapping[str, Piece],
    cand: PlacementCandidate,
    translations: FloatArray,
    params: PipelineParams,
    measured: Mapping[tuple[str, str], float],
    hints: SiteHints,
    assembly: Assembly | None = None,
) -> _Placed:
    """Refine an assembly's translations and build its poses and floorplan (``measured``:
    the overlaps the placement measured, ``Placement.measured``; the hints' prior poses
    anchor the refinement)."""
    ordered = [pieces[fid] for fid in cand.order]
    if cand.missing == 0:
        anchors = prior_anchors(hints, cand, translations)
        refined = refine_translations(
            ordered, cand.rotations, translations, params.placement, measured, anchors, cand.shared
        )
    else:
        # An open chain is already joined end to end; there is no loop to refine.
        refined = Refinement(translations, "skipped: open chain", 0.0, 0.0)
    poses = _poses(layouts, cand, refined.translations)
    polygon = None
    if (
        cand.missing == 0
        and len(ordered) >= 2
        and _gap(ordered, cand, translations) <= _gap_limit(ordered, cand, params)
        and not refined.status.startswith("fallback")
        and refined.violation_after <= params.placement.closure_tolerance
    ):
        polygon = build_polygon(ordered, cand.rotations, refined.translations, cand.shared)
    rectilinear = polygon is not None and is_simple_rectilinear(polygon)
    return _Placed(assembly, cand, refined, poses, polygon, rectilinear)


def _trusted_sigmas(
    hints: SiteHints,
    placement: Placement,
    pieces: Mapping[str, Piece],
    params: PipelineParams,
) -> dict[str, float]:
    """The position sigma of each prior the best assembly's refinement kept, by piece id.
    The refinement drops a stray prior (``Refinement.strays``), so it pins nothing: counted
    in the room's slack, a room would close on priors its floorplan did not use."""
    best = placement.best
    anchors = prior_anchors(hints, best, placement.translations)
    if not anchors or best.missing:
        return hints.prior_sigmas()  # fewer than two priors, or no loop to refine
    ordered = [pieces[fid] for fid in best.order]
    refined = refine_translations(
        ordered,
        best.rotations,
        placement.translations,
        params.placement,
        placement.measured,
        anchors,
        best.shared,
    )
    return {
        fid: anchor.sigma
        for fid, anchor, stray in zip(best.order, anchors, refined.strays, strict=True)
        if anchor is not None and not stray
    }


def _poses(
    layouts: Mapping[str, LocalLayout], cand: PlacementCandidate, translations: FloatArray
) -> dict[str, FloatArray]:
    """Each fragment's pose in the site frame: its rotation and its source's position."""
    return {
        fid: fragment_pose(layouts[fid], rotation, translations[k])
        for k, (fid, rotation) in enumerate(zip(cand.order, cand.rotations, strict=True))
    }


def _gap(ordered: Sequence[Piece], cand: PlacementCandidate, translations: FloatArray) -> float:
    """Manhattan length of the gap left at the loop's end before refinement, m (from the
    first piece's first corner back along the last piece's last wall where the loop closes
    at a shared corner)."""
    last = ordered[-1].keypoints
    end = translations[-1] + rot90(cand.rotations[-1]) @ last[-1]
    start = translations[0]
    if cand.shared and cand.shared[0]:
        end = end - rot90(cand.rotations[-1]) @ (last[-1] - last[-2])
        start = start + corner_offsets(ordered, cand.rotations, cand.shared)[0]
    return float(np.abs(end - start).sum())


def _gap_limit(ordered: Sequence[Piece], cand: PlacementCandidate, params: PipelineParams) -> float:
    """Largest gap a loop may leave and still count as closed: a share of its wall length
    (at least 1 m), plus what each straight junction may hide along its wall (the
    neighbours' overlap or gap, unseen wall at a door) and each open end (the wall the view
    lost, :mod:`services.open_ends`)."""
    placement = params.placement
    loop_length = sum(p.length for p in ordered)
    straight = len(ordered) - int(cand.features.get("turns", 0.0))
    base = max(1.0, placement.max_closure_share * loop_length)
    opened = open_end_count(ordered)
    return base + placement.straight_junction_slack * straight + placement.open_end_sigma * opened


def _to_hints_frame(
    placed: _Placed, hints: SiteHints, layouts: Mapping[str, LocalLayout]
) -> _Placed:
    """The assembly moved into the hints' frame (fitted to the prior poses)."""
    rotations = dict(zip(placed.candidate.order, placed.candidate.rotations, strict=True))
    sources = {fid: chain_placement(layouts[fid], pose)[1] for fid, pose in placed.poses.items()}
    yaw, shift = fit_frame(hints.priors, rotations, sources)
    transform = np.eye(4)
    transform[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    transform[:2, 3] = shift
    poses = {fid: transform @ pose for fid, pose in placed.poses.items()}
    polygon = None
    if placed.polygon is not None:
        polygon = placed.polygon @ transform[:2, :2].T + transform[:2, 3]
    return dataclasses.replace(placed, poses=poses, polygon=polygon)


def _prior_misses(
    placed: _Placed, hints: SiteHints, layouts: Mapping[str, LocalLayout]
) -> dict[str, tuple[float, float]]:
    """Per placed fragment with a prior pose: how far its chain's source lies from the
    prior's (m) and its yaw from the prior's (radians, absolute), ``placed`` in the hints'
    frame."""
    out = {}
    for fid, prior in hints.priors.items():
        if fid in placed.poses:
            yaw, source = chain_placement(layouts[fid], placed.poses[fid])
            distance = float(np.linalg.norm(source - prior.source))
            out[fid] = (distance, abs(wrap_angle(yaw - prior.yaw)))
    return out


def _contradicted_hints(
    placed: _Placed, hints: SiteHints, layouts: Mapping[str, LocalLayout]
) -> list[dict[str, Any]]:
    """Hints the chosen assembly disagrees with by more than three standard deviations."""
    out: list[dict[str, Any]] = [
        {"kind": "order" if pair.directed else "neighbours", "fragments": [pair.a, pair.b]}
        for pair in placed.candidate.violated_pairs
    ]
    for fid, (distance, yaw_error) in _prior_misses(placed, hints, layouts).items():
        prior = hints.priors[fid]
        if distance > 3 * prior.source_sigma or yaw_error > 3 * prior.sigma_yaw:
            out.append(
                {
                    "kind": "pose",
                    "fragments": [fid],
                    "distance_m": round(distance, 3),
                    "yaw_error_deg": round(float(np.degrees(yaw_error)), 2),
                }
            )
    return out


def _rooms(polygon: FloatArray | None, height: float | None) -> FloorplanModel:
    if polygon is None:
        return FloorplanModel()
    room = RoomModel(id="room_0", polygon=polygon.tolist(), floor_z=0.0, ceiling_z=height)
    return FloorplanModel(rooms=[room])


def _alternative(placed: _Placed, height: float | None) -> AlternativeModel:
    assert placed.assembly is not None
    return AlternativeModel(
        probability=placed.assembly.probability,
        fragments=[
            AlternativeFragmentModel(id=fid, pose=placed.poses[fid].tolist(), loop_index=k)
            for k, fid in enumerate(placed.candidate.order)
        ],
        floorplan=_rooms(placed.polygon, height),
    )


def _diagnostics(
    placement: Placement,
    main: _Placed,
    assemblies: Sequence[Assembly],
    contradicted: list[dict[str, Any]],
) -> dict[str, Any]:
    best = main.candidate
    refined = main.refinement
    return {
        "energy": {"total": best.energy, **best.features},
        "assemblies": [
            {
                "probability": a.probability,
                "energy": a.candidate.energy,
                "placements": a.members,
                "order": list(a.candidate.order),
                "rotations": list(a.candidate.rotations),
            }
            for a in assemblies
        ],
        "search": {"nodes": placement.nodes_searched, "exhaustive": placement.exhaustive},
        "refinement": {
            "status": refined.status,
            "violation_before": refined.violation_before,
            "violation_after": refined.violation_after,
            # Frames whose cameras were taken as one station and made to coincide.
            "stations": [[best.order[i], best.order[k]] for i, k in refined.stations],
        },
        "hints_contradicted": contradicted,
    }


def _choose(
    layouts: Mapping[str, LocalLayout],
    pieces: Mapping[str, Piece],
    placement: Placement,
    params: PipelineParams,
    hints: SiteHints,
    sigmas: Mapping[str, float],
) -> tuple[_Placed, list[_Placed], list[Assembly]]:
    """The main assembly and the alternatives worth reporting, made concrete (``sigmas``:
    the trusted priors' position sigmas, :func:`_trusted_sigmas`)."""
    piece_list = list(pieces.values())
    assemblies = (
        rank_assemblies(piece_list, placement, params.placement, sigmas) if placement.closed else []
    )
    if not assemblies:
        main = _concrete(
            layouts,
            pieces,
            placement.best,
            placement.translations,
            params,
            placement.measured,
            hints,
        )
        return main, [], []
    concrete = [
        _concrete(
            layouts, pieces, a.candidate, a.translations, params, placement.measured, hints, a
        )
        for a in assemblies[: params.placement.max_alternatives + 1]
    ]
    closing = [c for c in concrete if c.polygon is not None]
    if not closing:
        return concrete[0], [], assemblies
    return closing[0], closing[1:], assemblies


def _check_walls(
    main: _Placed, layouts: Mapping[str, LocalLayout], params: PipelineParams
) -> tuple[_Placed, dict[str, float]]:
    """The main room with its confidence capped when the scans show walls inside it that
    its floorplan misses (:func:`services.wall_evidence.unexplained_walls`), and those
    meters per fragment (empty when under the limit)."""
    if main.polygon is None or main.assembly is None:
        return main, {}
    meters = unexplained_walls(main.polygon, layouts, main.poses, params.layout.cell_size)
    placement = params.placement
    if sum(meters.values()) < placement.unexplained_wall_limit - 1e-9:
        return main, {}
    capped = _capped(main, placement.unexplained_wall_confidence)
    return capped, {k: round(v, 2) for k, v in meters.items()}


def _check_refinement(main: _Placed, params: PipelineParams) -> _Placed:
    """The main room with its confidence capped when its refinement had to drop the
    junction inequalities: the walls the scans measured do not fit this loop (overlaps
    longer than the walls, pieces pushed through each other), a sign of a wrong assembly
    however likely its energy made it."""
    if main.assembly is None or not main.refinement.status.startswith("relaxed"):
        return main
    return _capped(main, params.placement.relaxed_refinement_confidence)


def _check_search(
    main: _Placed, placement: Placement, hints: SiteHints, params: PipelineParams
) -> tuple[_Placed, bool]:
    """The main room with its confidence capped when the search ran out of nodes without
    prior poses to lead it (what it kept is not every serious rival: its best few may be
    near-copies of one room, so the room is not one to say closed), and whether it was."""
    if main.assembly is None or placement.exhaustive or hints.priors:
        return main, False
    return _capped(main, params.placement.truncated_search_confidence), True


def _check_hints(
    main: _Placed, hints: SiteHints, layouts: Mapping[str, LocalLayout], params: PipelineParams
) -> tuple[_Placed, list[str]]:
    """The main room with its confidence capped when it misses two or more prior poses by
    more than honest priors would, and those fragments (empty when not capped).

    A prior missed by k of its standard deviations in position happens exp(-k^2 / 2) of the
    time (two axes), in yaw erfc(k / sqrt 2); a miss is implausible when that, times the
    number of priors, is under ``implausible_hints_odds``. One such prior is a fleet's
    mistake as likely as the room's (a robot whose localisation jumped), and the scans win.
    Two or more, each off its own way, say the room is wrong: the search weighs a
    contradicted prior only so much (a hint is not obeyed blindly), so a wrong room can win
    on the scans' other terms."""
    if main.assembly is None or len(hints.priors) < 2:
        return main, []
    chances = {}
    for fid, (distance, yaw_error) in _prior_misses(
        _to_hints_frame(main, hints, layouts), hints, layouts
    ).items():
        position = distance / hints.priors[fid].source_sigma
        turn = yaw_error / hints.priors[fid].sigma_yaw
        chances[fid] = min(math.exp(-0.5 * position**2), math.erfc(turn / math.sqrt(2.0)))
    odds = params.placement.implausible_hints_odds / max(len(chances), 1)
    implausible = sorted(fid for fid, chance in chances.items() if chance < odds)
    if len(implausible) < 2:
        return main, []
    return _capped(main, params.placement.contradicted_hints_confidence), implausible


def _check_conflict(main: _Placed, params: PipelineParams) -> tuple[_Placed, float]:
    """The main room with its confidence capped when ``conflict_wall_limit`` or more of its
    walls run through space another scan saw empty, and those meters (0 when under the
    limit). The energy weighs the conflict against the other terms, and a room can still
    win by them; but a room said closed must not contradict what the scans saw."""
    meters = float(main.candidate.features.get("conflict", 0.0))
    if main.assembly is None or meters < params.placement.conflict_wall_limit - 1e-9:
        return main, 0.0
    return _capped(main, params.placement.conflict_confidence), round(meters, 2)


def _doubts(
    main: _Placed,
    status: str,
    unexplained: dict[str, float],
    conflicting: float,
    slid: int,
    cut_short: bool,
    implausible: Sequence[str] = (),
) -> dict[str, Any]:
    """The diagnostics that say why a room that closes is not said closed (only those that
    apply)."""
    doubts: dict[str, Any] = {}
    if status == "open" and main.polygon is not None:
        doubts["unconfirmed_room"] = True  # a loop closed, but not one to vouch for
    if unexplained:
        doubts["unexplained_walls"] = unexplained  # walls seen inside it, off its floorplan
    if conflicting:
        doubts["conflicting_walls"] = conflicting  # its walls cross space scans saw empty
    if slid:
        doubts["slid_alternatives"] = slid  # the runners-up are this room resized
    if cut_short:
        doubts["search_cut_short"] = True  # rivals may lie beyond the search's budget
    if implausible:
        # Honest priors miss the room by as much this rarely: it is wrong, or they all are.
        doubts["hints_implausible"] = list(implausible)
    if main.polygon is not None and not main.rectilinear:
        doubts["floorplan_not_rectilinear"] = True
    return doubts


def _doubted(assembly: Assembly, chosen: Assembly | None, main: Assembly) -> Assembly:
    """An assembly found, as the doubt caps left the main room ``main`` (which was
    ``chosen`` before them): the main itself as capped, any other at most as probable."""
    if assembly is chosen:
        return main
    return dataclasses.replace(assembly, probability=min(assembly.probability, main.probability))


def _capped(main: _Placed, most: float) -> _Placed:
    """The main room with its probability at most ``most``."""
    assert main.assembly is not None
    sure = min(main.assembly.probability, most)
    return dataclasses.replace(main, assembly=dataclasses.replace(main.assembly, probability=sure))


_SLIDE_SIGMAS = 2.0  # how far a slid runner-up moves, in the slide's standard deviations


def _slid_rooms(
    main: _Placed,
    layouts: Mapping[str, LocalLayout],
    pieces: Mapping[str, Piece],
    params: PipelineParams,
    measured: Mapping[tuple[str, str], float],
    prior_sigmas: Mapping[str, float],
) -> list[_Placed]:
    """The runners-up of a lone closed room we doubt: the same assembly with its pieces slid
    ``_SLIDE_SIGMAS`` standard deviations either way along the direction the junctions pin
    down least (``widest_slide``), each taking half of the doubt (at most the main room's
    own probability). The pieces close into one room only, but where its size is a guess
    the room may be that much longer or shorter, or a fragment elsewhere along its wall:
    "not sure, here are the candidates". None when a slide that far moves neither the room
    nor any fragment by what tells two rooms apart (the doubt is elsewhere), or leaves no
    simple rectilinear floorplan."""
    if main.assembly is None or main.polygon is None or not main.rectilinear:
        return []
    cand = main.candidate
    ordered = [pieces[fid] for fid in cand.order]
    move = widest_slide(
        ordered, cand.rotations, params.placement, measured, prior_sigmas, cand.shared
    )
    sure = main.assembly.probability
    doubt = min((1.0 - sure) / 2.0, sure)  # never likelier than the main room
    share = params.placement.same_room_share
    # A piece sliding along its own wall moves its fragment, not the floorplan: a runner-up
    # for the fleet all the same.
    reach = share * floorplan_diagonal(main.polygon)
    moved = float(np.abs(_SLIDE_SIGMAS * move).sum(axis=1).max()) > reach
    out = []
    for sign in (1.0, -1.0):
        translations = main.refinement.translations + sign * _SLIDE_SIGMAS * move
        polygon = build_polygon(ordered, cand.rotations, translations, cand.shared)
        if not is_simple_rectilinear(polygon) or (
            same_room(polygon, main.polygon, share) and not moved
        ):
            continue
        poses = _poses(layouts, cand, translations)
        assembly = dataclasses.replace(
            main.assembly, members=1, share=0.0, probability=doubt, polygon=polygon
        )
        refined = dataclasses.replace(
            main.refinement, translations=translations, status="slid along its loosest direction"
        )
        out.append(_Placed(assembly, cand, refined, poses, polygon))
    return out


def _reported(
    alternatives: Sequence[_Placed], status: str, params: PipelineParams
) -> list[_Placed]:
    """The alternatives a result shows: those not too improbable, at most a few; an
    ambiguous result always shows its runner-up, however improbable."""
    placement = params.placement
    kept = [
        alt
        for alt in alternatives
        if alt.assembly is not None
        and alt.assembly.probability >= placement.min_alternative_probability
    ]
    if status == "ambiguous" and not kept:
        kept = list(alternatives[:1])
    return kept[: placement.max_alternatives] if status != "open" else []


def _status(
    main: _Placed,
    alternatives: Sequence[_Placed],
    n_usable: int,
    n_all: int,
    params: PipelineParams,
) -> tuple[str, float]:
    """The result's status and confidence (see the contract, section 3)."""
    if main.polygon is None or main.assembly is None:
        return "open", 0.0
    confidence = main.assembly.probability
    if n_usable < n_all:  # the room of the usable fragments, a guess without the others
        return "open", confidence
    # A floorplan with a wall askew or crossing another was joined from chains that miss
    # a corner or do not fit: however likely the assembly, it is no room to act on unseen.
    if confidence >= params.placement.closed_confidence and main.rectilinear:
        return "closed", confidence
    # Unsure, with the runners-up to show; a lone assembly we doubt is no room to act on.
    return ("ambiguous" if alternatives else "open"), confidence


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
    hints : optional fleet knowledge: prior poses, known neighbours, known order. With prior
        poses the result is in the hints' frame.
    """
    report = progress or (lambda stage, fraction: None)
    # The search breaks near-ties on the layouts' last bits, which differ between machines.
    layouts = {fid: lay.snapped() for fid, lay in layouts.items()}
    usable = [fid for fid, lay in layouts.items() if lay.ok]
    report("placement", 0.1)
    layouts, (pieces, site_hints, placement) = _without_furniture_sides(
        layouts, usable, hints, params, report
    )
    fragments = {
        fid: FragmentResultModel(
            id=fid,
            placed=False,
            local_layout=LocalLayoutModel(keypoints=lay.keypoints_local().tolist()),
        )
        for fid, lay in layouts.items()
    }
    if placement is None:
        report("done", 1.0)
        return ResultModel(
            status="failed",
            fragments=list(fragments.values()),
            diagnostics={"reason": "no fragment shows a wall"},
        )
    report("refinement", 0.7)
    sigmas = _trusted_sigmas(site_hints, placement, pieces, params)
    main, alternatives, assemblies = _choose(layouts, pieces, placement, params, site_hints, sigmas)
    chosen = main.assembly
    main, unexplained = _check_walls(_check_refinement(main, params), layouts, params)
    main, conflicting = _check_conflict(main, params)
    main, cut_short = _check_search(main, placement, site_hints, params)
    main, implausible = _check_hints(main, site_hints, layouts, params)
    if main.assembly is not None:
        # The checks doubt the main room on what its floorplan shows, which its runners-up
        # were not put to: none is reported likelier (the main fields hold the most
        # probable room). Putting them to the checks and ranking again was tried: it swapped
        # a right room, doubted for a relaxed refinement, for a wrong one.
        alternatives = [_capped(room, main.assembly.probability) for room in alternatives]
        # Likewise every assembly found, which the fragments' confidences sum: a doubted
        # room's fragments are no surer than the room, and no rival reads likelier.
        assemblies = [_doubted(a, chosen, main.assembly) for a in assemblies]
    slid = 0
    doubted = main.assembly is not None and (
        main.assembly.probability < params.placement.closed_confidence
    )
    if doubted and not alternatives:
        alternatives = _slid_rooms(main, layouts, pieces, params, placement.measured, sigmas)
        slid = len(alternatives)
    if site_hints.priors:
        main = _to_hints_frame(main, site_hints, layouts)
        alternatives = [_to_hints_frame(alt, site_hints, layouts) for alt in alternatives]
    status, confidence = _status(main, alternatives, len(usable), len(layouts), params)
    alternatives = _reported(alternatives, status, params)
    sure: dict[str, float] = {}
    if main.polygon is not None and main.assembly is not None:  # a room, vouched for or not
        share = params.placement.same_room_share
        sure = fragment_confidences(main.assembly, assemblies, share)
    for index, fid in enumerate(main.candidate.order):
        fragments[fid].placed = True
        fragments[fid].pose = main.poses[fid].tolist()
        fragments[fid].loop_index = index
        fragments[fid].confidence = sure.get(fid)
    height = _room_height([layouts[fid] for fid in usable])
    contradicted = _contradicted_hints(main, site_hints, layouts)
    diagnostics = _diagnostics(placement, main, assemblies, contradicted)
    # What the chains rest on: frames and thin clouds lower the confidence (its maps per kind).
    kinds = [layouts[fid].evidence for fid in usable]
    diagnostics["evidence"] = {kind: kinds.count(kind) for kind in sorted(set(kinds))}
    diagnostics.update(
        _doubts(main, status, unexplained, conflicting, slid, cut_short, implausible)
    )
    report("done", 1.0)
    return ResultModel(
        status=status,
        confidence=confidence,
        fragments=list(fragments.values()),
        # A loop that closed but is doubted with no runner-up to show is "open" (the
        # contract's "ambiguous" needs one): its floorplan is the best guess, as its poses
        # are, and its confidence says how far to trust it.
        floorplan=_rooms(main.polygon, height),
        alternatives=[_alternative(alt, height) for alt in alternatives],
        diagnostics=diagnostics,
    )


_PlacedSite = tuple[dict[str, Piece], SiteHints, Placement | None]


def _placed_site(
    layouts: Mapping[str, LocalLayout],
    usable: Sequence[str],
    hints: HintsModel | None,
    params: PipelineParams,
) -> _PlacedSite:
    """The site's pieces, resolved hints, and placement (its kept assemblies ranked with
    their stations term); None when no piece has a wall."""
    pieces, site_hints = site_pieces(layouts, usable, hints, params.placement)
    placement = place_pieces(list(pieces.values()), params.placement, site_hints)
    if placement is not None:
        placement = with_station_cost(
            placement, list(pieces.values()), params.placement, site_hints
        )
    return pieces, site_hints, placement


def _without_furniture_sides(
    layouts: Mapping[str, LocalLayout],
    usable: Sequence[str],
    hints: HintsModel | None,
    params: PipelineParams,
    report: ProgressFn,
) -> tuple[dict[str, LocalLayout], _PlacedSite]:
    """The layouts and the site placed (:func:`_placed_site`), with each frame's chain
    replaced by its runner-up (:attr:`LocalLayout.runner_up`) where the site then closes
    with an energy lower by ``runner_up_prior``, and each frame chain's
    short convex end wall dropped, or its end step round furniture in a corner flattened,
    where the site then closes with an energy lower by ``end_wall_prior``
    (:mod:`services.end_walls`), one end at a time, fragments in id order; a loop that
    closes beats one that does not."""
    kept = dict(layouts)
    placed = _placed_site(kept, usable, hints, params)
    least_view = params.placement.end_wall_least_view
    trims = (
        functools.partial(without_end_wall, longest=params.placement.end_wall_trial),
        functools.partial(flattened_end_step, deepest=params.placement.end_step_depth),
    )
    for k, fid in enumerate(sorted(usable)):
        runner_up = kept[fid].with_runner_up()
        if runner_up is not None and params.placement.runner_up_prior < math.inf:
            trial = {**kept, fid: runner_up}
            tried = _placed_site(trial, usable, hints, params)
            if _closes_better(tried[2], placed[2], params.placement.runner_up_prior):
                kept, placed = trial, tried
        for end, trim in itertools.product(END_WALLS, trims):
            variant = trim(kept[fid], end, least_view=least_view)
            if variant is None:
                continue
            trial = {**kept, fid: variant}
            tried = _placed_site(trial, usable, hints, params)
            if _closes_better(tried[2], placed[2], params.placement.end_wall_prior):
                kept, placed = trial, tried
            report("placement", 0.1 + 0.5 * (k + 1) / len(usable))
    return kept, placed


def _closes_better(tried: Placement | None, current: Placement | None, prior: float) -> bool:
    """Whether ``tried`` closes the room and ``current`` does not, or closes it at an
    energy lower by more than ``prior``."""
    if tried is None or not tried.closed:
        return False
    if current is None or not current.closed:
        return True
    return tried.best.energy + prior < current.best.energy


@dataclass(frozen=True)
class Alignment:
    """What one alignment produced.

    layouts: local layout per fragment id (per merged group's anchor where fragments were
    merged first); result: the contract's result, one entry per input fragment.
    """

    layouts: dict[str, LocalLayout]
    result: ResultModel


def align_fragments(
    fragments: Mapping[str, Fragment],
    params: PipelineParams = PipelineParams(),
    progress: ProgressFn | None = None,
    hints: HintsModel | None = None,
    premerge_overlapping: bool = False,
) -> Alignment:
    """The whole pipeline on decoded fragments (the CLI's ``align``): local layouts, then
    the global placement.

    Overlapping RGB-D frames are merged first by ORB matching; with ``premerge_overlapping``
    and no RGB-D frame, overlapping clouds are merged first by FPFH registration (paper
    section 3). Either way every input fragment gets its own entry (``merged_into`` names
    its group's anchor) and pose (the group's pose composed with its motion).

    Parameters
    ----------
    fragments : id -> decoded cloud or RGB-D frame; the result keeps this order.
    params : algorithm parameters.
    progress : optional callback ``(stage, fraction)``, the only channel for timing the
        stages: ``"pre-merge"`` or ``"frame groups"`` (0.0) when there is something to
        merge, ``"local layout {id}"`` before each layout (the share of layouts done), then
        the stages of :func:`place_site` (``"placement"``, ``"refinement"``, ``"done"``).
        Each stage lasts until the next one is reported; ``"done"`` ends the run.
    hints : optional fleet knowledge (see :func:`place_site`).
    premerge_overlapping : run the FPFH pre-merge of clouds first.
    """
    report = progress or _silent
    if premerge_overlapping and not any(isinstance(f, RgbdFrame) for f in fragments.values()):
        clouds = {fid: fragment_points(f, params) for fid, f in fragments.items()}
        return _premerged_alignment(clouds, params, report, hints)
    groups = _frame_groups(fragments, params, report)
    layouts = _local_layouts(fragments, groups, params, report)
    if params.layout.frame.merge_stations:
        groups, layouts = _with_stations_merged(fragments, groups, layouts, params)
    result = place_site(layouts, params, report, hints=hints)
    if any(len(group.transforms) > 1 for group in groups):
        result = expand_frame_groups(result, groups, list(fragments))
    return Alignment(layouts, result)


def align_clouds(
    clouds: Mapping[str, FloatArray],
    params: PipelineParams = PipelineParams(),
    progress: ProgressFn | None = None,
    premerge_overlapping: bool = False,
    hints: HintsModel | None = None,
) -> ResultModel:
    """The result of :func:`align_fragments` on in-memory clouds.

    Parameters
    ----------
    clouds : id -> (N, 3) float64, fragment-local points, meters.
    params : algorithm parameters.
    progress : optional callback ``(stage, fraction)`` (see :func:`align_fragments`).
    premerge_overlapping : run the FPFH pre-merge first.
    hints : optional fleet knowledge (see :func:`place_site`).
    """
    fragments = {fid: ParsedFragment(points, "memory") for fid, points in clouds.items()}
    return align_fragments(fragments, params, progress, hints, premerge_overlapping).result


def _silent(stage: str, fraction: float) -> None:
    """The progress callback of a caller that asked for none."""


def _rgbd_frames(fragments: Mapping[str, Fragment]) -> dict[str, RgbdFrame]:
    """The fragments that are RGB-D frames, by id."""
    return {fid: f for fid, f in fragments.items() if isinstance(f, RgbdFrame)}


def _frame_groups(
    fragments: Mapping[str, Fragment], params: PipelineParams, report: ProgressFn
) -> list[FrameGroup]:
    """Overlapping RGB-D frames merged by ORB matching (groups of one for the rest)."""
    frames = _rgbd_frames(fragments)
    if len(frames) < 2:
        return [FrameGroup(fid, {fid: np.eye(4)}) for fid in frames]
    report("frame groups", 0.0)
    return group_frames(frames, params.layout.frame)


def _local_layouts(
    fragments: Mapping[str, Fragment],
    groups: Sequence[FrameGroup],
    params: PipelineParams,
    report: ProgressFn,
) -> dict[str, LocalLayout]:
    """A layout per fragment, a merged group's (from all its frames) under its anchor's id."""
    members = {fid for group in groups for fid in group.transforms}
    anchors = {group.anchor_id: group for group in groups}
    frames = _rgbd_frames(fragments)
    todo = [fid for fid in fragments if fid not in members or fid in anchors]
    layouts: dict[str, LocalLayout] = {}
    for index, fid in enumerate(todo):
        report(f"local layout {fid}", index / len(todo))
        if fid in anchors:
            layouts[fid] = group_layout(anchors[fid], frames, params)
        else:
            layouts[fid] = fragment_layout(fragments[fid], params)
    return layouts


def _with_stations_merged(
    fragments: Mapping[str, Fragment],
    groups: Sequence[FrameGroup],
    layouts: Mapping[str, LocalLayout],
    params: PipelineParams,
) -> tuple[list[FrameGroup], dict[str, LocalLayout]]:
    """The frame groups and layouts with the single frames of one station merged
    (:func:`services.frame_merge.station_groups`) and laid out as one fragment under their
    first frame's id; a group whose layout finds no chain stays apart."""
    singles = {
        group.anchor_id: layouts[group.anchor_id]
        for group in groups
        if len(group.transforms) == 1 and layouts[group.anchor_id].ok
    }
    if len(singles) < 2:
        return list(groups), dict(layouts)
    frames = _rgbd_frames(fragments)
    merged: dict[str, FrameGroup] = {}
    out = dict(layouts)
    for station in station_groups(singles, params.placement):
        if len(station.transforms) < 2:
            continue
        layout = group_layout(station, frames, params)
        if layout.ok:
            merged[station.anchor_id] = station
            for fid in station.transforms:
                del out[fid]
            out[station.anchor_id] = layout
    members = {fid for station in merged.values() for fid in station.transforms}
    kept = [group for group in groups if group.anchor_id not in members]
    return kept + list(merged.values()), out


def _premerged_alignment(
    clouds: Mapping[str, FloatArray],
    params: PipelineParams,
    report: ProgressFn,
    hints: HintsModel | None,
) -> Alignment:
    """Clouds whose FPFH registration has more than the configured share of inliers merged
    first, then laid out and placed as one fragment per group."""
    groups: dict[str, dict[str, FloatArray]] = {fid: {fid: np.eye(4)} for fid in clouds}
    merged: Mapping[str, FloatArray] = clouds
    if len(clouds) > 1:
        report("pre-merge", 0.0)
        premerged = premerge(clouds, params.registration)
        groups = {g.anchor_id: dict(g.transforms) for g in premerged.groups}
        merged = {g.anchor_id: g.points for g in premerged.groups}
    layouts = {}
    for index, (gid, points) in enumerate(merged.items()):
        report(f"local layout {gid}", index / max(len(merged), 1))
        layouts[gid] = estimate_layout(points, params)
    placed = place_site(layouts, params, report, hints=hints)
    return Alignment(layouts, _expand_groups(placed, groups, list(clouds)))


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
