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

from bench.outside.run import Job, frame_jobs
from bench.outside.score import true_fragments
from cli.frames import read_frame_dir
from schemas.params import PipelineParams
from services.fragments import fragment_layout
from services.geometry import distance_to_polygon, points_in_polygon
from services.model_export import to_site
from services.types import FloatArray

__all__ = ["WRONG", "FrameChain", "chain_strays", "chain_table", "main", "room_chains"]

WRONG = 0.3  # m: a chain straying farther from the outline is wrong
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
    t = np.linspace(0.0, 1.0, _SAMPLES)[None, :, None]
    steps = (chain[1:] - chain[:-1])[:, None, :]
    points = (chain[:-1, None, :] + t * steps).reshape(-1, 2)
    distance = distance_to_polygon(points, polygon)
    inside = points_in_polygon(points, polygon)
    return float(distance[~inside].max(initial=0.0)), float(distance[inside].max(initial=0.0))


def room_chains(
    folder: Path, camera: str, params: PipelineParams = PipelineParams()
) -> list[FrameChain]:
    """Every frame of the scene in ``folder`` (``truth.json``, ``frames/``) laid out alone
    and judged against the room's outline."""
    truth = json.loads((folder / "truth.json").read_text())
    polygon = np.asarray(truth["polygon"], dtype=np.float64)
    score = folder / "score.json"
    right = json.loads(score.read_text())["main"]["acc"] if score.exists() else None
    out = []
    for fid, (pose, _) in sorted(true_fragments(truth).items()):
        layout = fragment_layout(read_frame_dir(folder / "frames" / fid, params), params)
        if layout.ok:
            chain = to_site(layout.keypoints_local(), pose)[:, :2]
            beyond, within = chain_strays(chain, polygon)
        else:
            beyond = within = float("inf")
        out.append(FrameChain(folder.name, camera, fid, beyond, within, right))
    return out


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
                    f"({verdict[r.room_right]})"
                )
    print(chain_table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
