"""Outside RGB-D frame rooms seen with the project's own layouts: which frames' chains stray
from the room's outline, which way, and whether their room came out wrong.

The scenes are :func:`bench.outside.run.frame_jobs`' (the same names and seeds as the
``jigsaw align`` runs of ``bench.outside.run frames``; a folder that run filled is read as
it is, scenes missing are made). Each frame is laid out on its own (as the CLI lays out a
frame no other merged with) and its chain put on the floor plan with the frame's true pose.
The outside renderer keeps no chain per frame, so a chain is judged by how far it strays
from the room's outline (:func:`chain_strays`): ``beyond`` the room (through a door or a
window, an end run on past a corner) or ``within`` it (a step cut across, a front taken for
the wall); wrong past ``WRONG`` metres either way. A chain cut short along the outline
passes: this finds the chains that lead a room astray, not every chain a scorer would fail.
Each wrong chain is also followed through the layout's steps
(:data:`services.frame_layout.CHAIN_STAGES`): the first step whose chain strays past
``WRONG`` made it wrong (:func:`stage_table`; the wall graph's own chain, or a rule after it).
Another table (:func:`overlap_table`) puts each right chain on the outline's perimeter
(:func:`chain_span`) and sets apart, per number of stations, the rooms whose neighbouring
stretches overlap by more than :data:`BIG_OVERLAP` at a junction of their loop. A last one
(:func:`unseen_table`) sets apart, of the rooms whose every chain is right, those whose
chains leave more than :data:`BIG_UNSEEN` of the outline unseen between two of them.

    .venv/bin/python -m bench.outside.frame_chains --out DIR [--per-camera 20] [--seed 8]
        [--list] [--workers 2]

``--out``: the folder of a ``bench.outside.run frames`` draw (its ``score.json`` files say
which rooms came out right; scenes not run there are made, and counted as unscored).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench.outside.clouds import boundary_project, perimeter_cum
from bench.outside.run import Job, frame_jobs
from bench.outside.score import true_fragments
from bench.scoring import chain_samples
from cli.frames import read_frame_dir
from schemas.params import PipelineParams
from services.frame_layout import CHAIN_STAGES, estimate_rgbd_layout
from services.geometry import distance_to_polygon, points_in_polygon
from services.model_export import to_site
from services.rgbd import RgbdFrame
from services.types import FloatArray, LocalLayout

__all__ = [
    "BIG_OVERLAP",
    "BIG_UNSEEN",
    "WRONG",
    "FrameChain",
    "chain_span",
    "chain_strays",
    "chain_table",
    "junction_overlaps",
    "main",
    "overlap_table",
    "room_chains",
    "stage_table",
    "unseen_stretches",
    "unseen_table",
]

WRONG = 0.3  # m: a chain straying farther from the outline is wrong
# m: neighbours overlapping more than this at a junction are more than the brief's world
# (up to 0.5 m) and the placement's junction model expect
BIG_OVERLAP = 0.6
# m: wall left unseen between neighbouring frames' chains beyond this is more than the
# placement's junction model expects (about 0 +- 0.3 m either side of a hidden corner)
BIG_UNSEEN = 0.6
_SAMPLES = 40  # points per wall the strays are measured at


@dataclass(frozen=True)
class FrameChain:
    """One frame's chain against its room: ``beyond`` / ``within`` (m, see
    :func:`chain_strays`; inf for a frame with no chain); ``room_right``: its room's main
    result was right (ACC_global) in the draw's score, None when not scored."""

    room: str
    camera: str
    frame: str
    beyond: float
    within: float
    room_right: bool | None
    # The stretch of the outline's perimeter the chain covers (m from the outline's first
    # vertex, start <= end; :func:`chain_span`), None for a wrong chain or none; the room's
    # stations and perimeter.
    span: tuple[float, float] | None = None
    stations: int = 0
    perimeter: float = 0.0
    # A wrong chain: the first of the layout's steps (CHAIN_STAGES) whose chain strayed so,
    # "no chain" without one; None for a right chain.
    stage: str | None = None

    @property
    def wrong(self) -> bool:
        """The chain strays farther than :data:`WRONG` from the outline."""
        return max(self.beyond, self.within) > WRONG


def chain_strays(chain: FloatArray, polygon: FloatArray) -> tuple[float, float]:
    """How far (m) a floor-plan chain (K, 2) strays from a room's outline (V, 2): the most
    outside the room and the most inside it, over points along its walls.

    >>> square = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
    >>> chain_strays(np.array([[1.0, 0.0], [4.0, 0.0], [4.0, 5.0]]), square)
    (1.0, 0.0)
    >>> chain_strays(np.array([[1.0, 0.5], [3.0, 0.5]]), square)
    (0.0, 0.5)
    """
    points = chain_samples(chain, _SAMPLES)
    distance = distance_to_polygon(points, polygon)
    inside = points_in_polygon(points, polygon)
    return float(distance[~inside].max(initial=0.0)), float(distance[inside].max(initial=0.0))


def chain_span(chain: FloatArray, polygon: FloatArray) -> tuple[float, float]:
    """The stretch of the outline's perimeter a chain lying on it covers: meters from the
    outline's first vertex to where it starts (``[0, perimeter)``) and ends (start or more;
    past the perimeter where it runs across the first vertex). The chain is taken to cover
    less than half the perimeter.

    >>> square = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
    >>> chain_span(np.array([[1.0, 0.0], [4.0, 0.0], [4.0, 2.0]]), square)
    (1.0, 6.0)
    >>> chain_span(np.array([[0.0, 1.0], [0.0, 0.0], [2.0, 0.0]]), square)
    (15.0, 18.0)
    """
    cum, _ = perimeter_cum(polygon)
    perimeter = float(cum[-1])
    _, position = boundary_project(chain_samples(chain, _SAMPLES), polygon, cum)
    turned = np.unwrap(position * (2.0 * np.pi / perimeter)) * (perimeter / (2.0 * np.pi))
    start = float(turned.min()) % perimeter
    return round(start, 9), round(start + float(turned.max() - turned.min()), 9)


def junction_overlaps(spans: Sequence[tuple[float, float]], perimeter: float) -> list[float]:
    """Per junction of the loop the spans make (in the order of their starts), how far a
    span runs on past the next one's start: positive an overlap, negative a gap (m).

    >>> junction_overlaps([(0.0, 5.0), (4.5, 9.0), (9.3, 16.4)], 16.0)
    [0.5, -0.3, 0.4]
    """
    ordered = sorted(spans)
    starts = [start for start, _ in ordered[1:]] + [ordered[0][0] + perimeter]
    return [round(end - start, 9) for (_, end), start in zip(ordered, starts, strict=True)]


def unseen_stretches(spans: Sequence[tuple[float, float]], perimeter: float) -> list[float]:
    """Lengths (m) of the outline's stretches no span covers, largest first (none when the
    spans cover the whole loop). Spans as :func:`chain_span` gives them.

    >>> unseen_stretches([(9.3, 16.4), (0.0, 5.0), (4.5, 9.0)], 16.0)
    [0.3]
    >>> unseen_stretches([(0.0, 6.0), (3.0, 5.0), (8.0, 15.0)], 16.0)
    [2.0, 1.0]
    """
    if not spans:
        return [perimeter]
    ordered = sorted(spans)
    reach = ordered[0][1]
    holes = []
    for start, end in ordered[1:]:
        if start > reach:
            holes.append(start - reach)
        reach = max(reach, end)
    wrap = ordered[0][0] + perimeter - reach  # from the last reach round to the first start
    if wrap > 0:
        holes.append(wrap)
    return sorted((round(h, 9) for h in holes), reverse=True)


def room_chains(
    folder: Path, camera: str, params: PipelineParams = PipelineParams()
) -> list[FrameChain]:
    """Every frame of the scene in ``folder`` (``truth.json``, ``frames/``) laid out alone
    and judged against the room's outline."""
    truth = json.loads((folder / "truth.json").read_text())
    polygon = np.asarray(truth["polygon"], dtype=np.float64)
    score = folder / "score.json"
    right = json.loads(score.read_text())["main"]["acc"] if score.exists() else None
    stations = len(truth.get("stations", []))
    perimeter = float(perimeter_cum(polygon)[0][-1])
    out = []
    for fid, (pose, _) in sorted(true_fragments(truth).items()):
        layout, stages = _traced_layout(read_frame_dir(folder / "frames" / fid, params), params)
        span, stage = None, None
        if layout.ok:
            chain = to_site(layout.keypoints_local(), pose)[:, :2]
            beyond, within = chain_strays(chain, polygon)
            if max(beyond, within) <= WRONG:
                span = chain_span(chain, polygon)
            else:
                stage = _first_wrong(layout, stages, pose, polygon)
        else:
            beyond = within = float("inf")
            stage = "no chain"
        out.append(
            FrameChain(
                folder.name, camera, fid, beyond, within, right, span, stations, perimeter, stage
            )
        )
    return out


def _traced_layout(
    frame: RgbdFrame, params: PipelineParams
) -> tuple[LocalLayout, list[tuple[str, FloatArray]]]:
    """A frame's layout and its chain after each layout step (aligned frame)."""
    stages: list[tuple[str, FloatArray]] = []
    layout = estimate_rgbd_layout(frame, params, trace=lambda *step: stages.append(step))
    return layout, stages


def _first_wrong(
    layout: LocalLayout,
    stages: Sequence[tuple[str, FloatArray]],
    pose: FloatArray,
    polygon: FloatArray,
) -> str:
    """The first layout step whose chain (aligned frame, as traced) strays farther than
    :data:`WRONG` from the outline, the frame placed with its true ``pose``."""
    for stage, keypoints in stages:
        if len(keypoints) < 2:
            return stage
        chain = to_site(layout.floor_points_local(keypoints), pose)[:, :2]
        if max(chain_strays(chain, polygon)) > WRONG:
            return stage
    return stages[-1][0]  # the final chain strays; the last step's is that chain


def stage_table(rows: Sequence[FrameChain]) -> str:
    """Per camera: the wrong chains by the layout step that made them wrong
    (:data:`services.frame_layout.CHAIN_STAGES`; "no chain" for frames without one)."""
    columns = [*CHAIN_STAGES, "no chain"]
    lines = [
        "| camera | wrong chains | " + " | ".join(columns) + " |",
        "|---|---|" + "---|" * len(columns),
    ]
    cameras = sorted({r.camera for r in rows})
    for camera in [*cameras, "all"]:
        wrong = [r for r in rows if r.wrong and camera in ("all", r.camera)]
        counts = [sum(r.stage == column for r in wrong) for column in columns]
        lines.append(f"| {camera} | {len(wrong)} | " + " | ".join(map(str, counts)) + " |")
    return "\n".join(lines)


def chain_table(rows: Sequence[FrameChain]) -> str:
    """Per camera: frames, wrong chains (beyond / within the room), rooms with a wrong
    chain, and how many of the rooms that came out wrong have one."""
    lines = [
        "| camera | frames | wrong chains | beyond | within | rooms with one "
        "| wrong rooms with one |",
        "|---|---|---|---|---|---|---|",
    ]
    by_camera: dict[str, list[FrameChain]] = defaultdict(list)
    for row in rows:
        by_camera[row.camera].append(row)
    for camera in [*sorted(by_camera), "all"]:
        group = rows if camera == "all" else by_camera[camera]
        wrong = [r for r in group if r.wrong]
        rooms = {r.room for r in group}
        strayed = {r.room for r in wrong}
        failed = {r.room for r in group if r.room_right is False}
        lines.append(
            f"| {camera} | {len(group)} | {len(wrong)} | "
            f"{sum(r.beyond >= r.within for r in wrong)} | "
            f"{sum(r.beyond < r.within for r in wrong)} | {len(strayed)} of {len(rooms)} | "
            f"{len(failed & strayed)} of {len(failed)} |"
        )
    return "\n".join(lines)


def overlap_table(rows: Sequence[FrameChain]) -> str:
    """Per number of stations: rooms, rooms right, and how the rooms fare whose frames
    overlap by more than :data:`BIG_OVERLAP` at a junction of the loop their right chains
    make (:func:`junction_overlaps`) against the others."""
    header = f"| stations | rooms | right | overlap > {BIG_OVERLAP} m at a junction"
    lines = [f"{header} | right of those | right of the others | median largest overlap, m |"]
    rooms: dict[int, list[tuple[float, bool | None]]] = defaultdict(list)
    for frames in _by_room(rows):
        spans = [f.span for f in frames if f.span is not None]
        largest = max(junction_overlaps(spans, frames[0].perimeter)) if spans else 0.0
        rooms[frames[0].stations].append((largest, frames[0].room_right))
    return "\n".join(lines + _station_rows(rooms, BIG_OVERLAP))


def unseen_table(rows: Sequence[FrameChain]) -> str:
    """Per number of stations, over the rooms whose every chain is right: how the rooms fare
    whose chains leave more than :data:`BIG_UNSEEN` of the outline unseen at a junction of
    their loop (:func:`unseen_stretches`: a view stopping short of a far wall, corners
    included) against the others."""
    header = "| stations | rooms, every chain right | right | "
    header += f"unseen > {BIG_UNSEEN} m at a junction"
    lines = [f"{header} | right of those | right of the others | median largest unseen, m |"]
    rooms: dict[int, list[tuple[float, bool | None]]] = defaultdict(list)
    for frames in _by_room(rows):
        if all(f.span is not None for f in frames):
            spans = [f.span for f in frames if f.span is not None]
            holes = unseen_stretches(spans, frames[0].perimeter)
            rooms[frames[0].stations].append((max(holes, default=0.0), frames[0].room_right))
    return "\n".join(lines + _station_rows(rooms, BIG_UNSEEN))


def _by_room(rows: Sequence[FrameChain]) -> list[list[FrameChain]]:
    """The rows grouped by room, in the order rooms first appear."""
    by_room: dict[str, list[FrameChain]] = defaultdict(list)
    for row in rows:
        by_room[row.room].append(row)
    return list(by_room.values())


def _station_rows(rooms: dict[int, list[tuple[float, bool | None]]], limit: float) -> list[str]:
    """A table's rows per number of stations: rooms, right, those whose largest figure is
    over ``limit`` and how many of them and of the others are right, the median figure.
    ``rooms``: per station count, each room's (largest figure, came out right)."""
    lines = ["|---|---|---|---|---|---|---|"]
    for stations in sorted(rooms):
        group = rooms[stations]
        big = [right for largest, right in group if largest > limit]
        rest = [right for largest, right in group if largest <= limit]
        lines.append(
            f"| {stations} | {len(group)} | {sum(r is True for _, r in group)} | {len(big)} | "
            f"{sum(r is True for r in big)} of {len(big)} | "
            f"{sum(r is True for r in rest)} of {len(rest)} | "
            f"{float(np.median([largest for largest, _ in group])):.2f} |"
        )
    return lines


def _judge(args: tuple[Job, Path]) -> list[FrameChain]:
    job, out = args
    folder = out / job.name
    if not (folder / "truth.json").exists():
        from bench.outside import frames  # open3d: imported in the workers only

        frames.make_scene(folder, job.seed, job.camera, job.kind)
    return room_chains(folder, job.camera)


def main(argv: list[str] | None = None) -> int:
    """Judge the chains of one draw's frame rooms and print the table; exit code."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="the draw's scenes' folder")
    parser.add_argument("--per-camera", type=int, default=20, help="rooms per camera")
    parser.add_argument("--seed", type=int, default=0, help="seed shift, as the draw's")
    parser.add_argument("--workers", type=int, default=2, help="processes")
    parser.add_argument("--list", action="store_true", help="print every wrong chain")
    args = parser.parse_args(argv)
    jobs = [(job, args.out) for job in frame_jobs(args.per_camera, args.seed)]
    with multiprocessing.get_context("fork").Pool(args.workers) as pool:
        rows = [row for room in pool.map(_judge, jobs, chunksize=1) for row in room]
    if args.list:
        for r in rows:
            if r.wrong:
                verdict = {True: "room right", False: "room wrong", None: "not scored"}
                print(
                    f"{r.room} {r.frame}: beyond {r.beyond:.2f} m, within {r.within:.2f} m "
                    f"({verdict[r.room_right]}; wrong from: {r.stage})"
                )
    print(chain_table(rows))
    print()
    print(stage_table(rows))
    print()
    print(overlap_table(rows))
    print()
    print(unseen_table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
