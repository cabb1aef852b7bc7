"""Outside point-cloud rooms seen with the project's own tools: which chains are wrong in the
floor plan, and why wrong rooms are wrong.

The scenes are :func:`bench.outside.run.cloud_jobs`' (rooms and cuts the project's generator
never made; the same names and seeds as the ``jigsaw align`` runs of ``bench.outside.run``).
Each fragment is laid out on its own and its truth is put in the project's ground-truth form
(:func:`cached_scene`: the stretch of outline its arc covers as its true chain), so:

* the chain table counts the fragments whose chain is wrong in plan
  (:func:`bench.scoring.chain_error_in_plan`, 5 % of the fragment's diagonal), split by what
  lies near their arc's ends (a door, a window, neither: openings at a cut are where chains
  leave their room), with two stricter tests: both ends right, and the whole shape right
  (:func:`shape_error_in_plan`: a chain that cuts across a bay or drops a notch between
  right ends); ``--list`` prints each wrong chain (``--by ends`` or ``--by shape``);
* ``--cues`` prints :func:`bench.placement_trust.cue_table`: how well each junction cue
  tells true neighbours from false ones here (AUC), and
  :func:`bench.placement_trust.evidence_table`: the structure evidence's likelihood ratio
  per bin;
* ``--anatomy`` places every room (:func:`services.pipeline.place_site`, the CLI's
  placement without its refinement of the result files) and prints
  :mod:`bench.failure_anatomy`'s tables: per bucket, why the wrong rooms are wrong.

    .venv/bin/python -m bench.outside.chains --seed 12 [--per-bucket 20] [--real 40]
        [--anatomy] [--cues] [--list [--by ends|shape]] [--workers 2]

Seeds 9 and below were used while building the layout rules; judge changes on later ones.
"""

from __future__ import annotations

import argparse
import multiprocessing
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import numpy as np
from rich.console import Console

from bench.failure_anatomy import anatomy_of, cause_table, term_table
from bench.outside.clouds import generate, perimeter_cum
from bench.outside.run import Job, cloud_jobs
from bench.placement_trust import STRUCTURE_CUE, cue_scores, cue_table, evidence_table
from bench.room_shapes import DEFAULT_PATH
from bench.scoring import chain_error_in_plan
from bench.world_scenes import CachedScene
from schemas.params import PipelineParams
from services.geometry import distance_to_chain
from services.local_layout import estimate_local_layout
from services.model_export import to_site
from services.parsing_ply import read_ply_xyz
from services.types import FloatArray

_END_REACH = 1.0  # m along the outline: an opening this close to an arc end is "near it"
_MAX_POINTS = 10**8
_SHAPE_SPACING = 0.02  # m between the points the shape test samples along a chain
ChainTest = Literal["paper", "ends", "shape"]


def outline_stretch(polygon: FloatArray, start: float, length: float) -> FloatArray:
    """(K, 2) the outline from perimeter parameter ``start`` (m) on for ``length`` m, CCW:
    both ends and every corner between (the project's true-chain convention)."""
    cum, _ = perimeter_cum(polygon)
    perimeter = float(cum[-1])

    def point(t: float) -> FloatArray:
        t %= perimeter
        i = min(int(np.searchsorted(cum, t, side="right")) - 1, len(polygon) - 1)
        a, b = polygon[i], polygon[(i + 1) % len(polygon)]
        span = float(cum[i + 1] - cum[i])
        return a + (b - a) * ((t - cum[i]) / span if span > 0 else 0.0)

    corners = [
        polygon[i]
        for lap in (0.0, perimeter)
        for i in range(len(polygon))
        if start < cum[i] + lap < start + length
    ]
    return np.array([point(start), *corners, point(start + length)])


def near_end(truth: dict[str, Any], start: float, length: float) -> str:
    """What an arc holds within :data:`_END_REACH` of either end: "door" before "window",
    else "none"."""
    cum, _ = perimeter_cum(np.asarray(truth["polygon"], dtype=np.float64))
    perimeter = float(cum[-1])

    def gap(t: float, end: float) -> float:
        return abs((t - end + perimeter / 2) % perimeter - perimeter / 2)

    found = {
        str(opening["type"])
        for opening in truth["openings"]
        for end in (start, start + length)
        if min(
            gap(cum[opening["edge"]] + opening["u0"], end),
            gap(cum[opening["edge"]] + opening["u1"], end),
        )
        < _END_REACH
    }
    return "door" if "door" in found else "window" if "window" in found else "none"


def cached_scene(job: Job, folder: Path, params: PipelineParams = PipelineParams()) -> CachedScene:
    """The outside scene of ``job`` generated into ``folder``, its fragments laid out, its
    truth in the project's ground-truth form (``fragments`` with ``keypoints_local``,
    ``diagonal`` (XY, world), ``loop_index``; ``diagonal``; ``room.polygon``); each fragment
    also carries ``near_end`` (:func:`near_end`)."""
    truth = generate(job.seed, job.kind, job.n, folder)
    polygon = np.asarray(truth["polygon"], dtype=np.float64)
    started = time.process_time()
    layouts, fragments = {}, []
    for loop_index, fragment in enumerate(truth["fragments"]):  # written in CCW order
        points = read_ply_xyz((folder / f"{fragment['id']}.ply").read_bytes(), _MAX_POINTS)
        layouts[fragment["id"]] = estimate_local_layout(points, params)
        pose = np.asarray(fragment["pose"], dtype=np.float64)
        start, length = (float(v) for v in fragment["arc"])
        chain = outline_stretch(polygon, start, length)
        on_floor = np.column_stack([chain, np.zeros(len(chain))])
        world_xy = to_site(points, pose)[:, :2]
        fragments.append(
            {
                **fragment,
                "keypoints_local": (on_floor - pose[:3, 3]) @ pose[:3, :3],
                "diagonal": float(np.linalg.norm(world_xy.max(0) - world_xy.min(0))),
                "loop_index": loop_index,
                "near_end": near_end(truth, start, length),
            }
        )
    seconds = time.process_time() - started
    project_truth = {
        "seed": job.seed,
        "fragments": fragments,
        "diagonal": truth["diag"],
        "room": {"polygon": truth["polygon"]},
    }
    return CachedScene(_set_name(job), project_truth, layouts, seconds)


def _set_name(job: Job) -> str:
    return "outside real" if job.kind == "real" else "outside synthetic"


def _build(job: Job) -> CachedScene:
    with tempfile.TemporaryDirectory() as tmp:
        return cached_scene(job, Path(tmp))


def end_error_in_plan(estimated_local: Any, fragment: dict[str, Any]) -> float:
    """The farther of a chain's two ends from the true chain's, m, in plan (inf for an
    empty chain). The paper's mean keypoint error forgives a chain that drops a whole wall
    at one end among many corners; this does not."""
    if len(estimated_local) == 0:
        return float("inf")
    pose = np.asarray(fragment["pose"], dtype=np.float64)
    estimate = to_site(np.asarray(estimated_local, dtype=np.float64), pose)[:, :2]
    truth = to_site(np.asarray(fragment["keypoints_local"]), pose)[:, :2]
    return float(np.linalg.norm(estimate[[0, -1]] - truth[[0, -1]], axis=1).max())


def shape_error_in_plan(estimated_local: Any, fragment: dict[str, Any]) -> float:
    """The farthest either chain strays from the other, m, in plan (the Hausdorff distance
    of the two polylines; inf for an empty chain). A chain that cuts across a bay or drops
    a notch between right ends passes the paper's test and the ends' test, not this one."""
    if len(estimated_local) < 2:
        return float("inf")
    pose = np.asarray(fragment["pose"], dtype=np.float64)
    estimate = to_site(np.asarray(estimated_local, dtype=np.float64), pose)[:, :2]
    truth = to_site(np.asarray(fragment["keypoints_local"]), pose)[:, :2]
    return float(
        max(
            distance_to_chain(_sampled(estimate), truth).max(),
            distance_to_chain(_sampled(truth), estimate).max(),
        )
    )


def _sampled(chain: FloatArray) -> FloatArray:
    """Points every ``_SHAPE_SPACING`` (or closer) along a polyline, its corners included."""
    steps = np.linalg.norm(np.diff(chain, axis=0), axis=1)
    along = np.concatenate([[0.0], np.cumsum(steps)])
    at = np.union1d(np.arange(0.0, along[-1], _SHAPE_SPACING), along)
    return np.column_stack([np.interp(at, along, chain[:, k]) for k in range(2)])


_MEASURES: dict[ChainTest, Callable[[Any, dict[str, Any]], float]] = {
    "paper": chain_error_in_plan,
    "ends": end_error_in_plan,
    "shape": shape_error_in_plan,
}


def wrong_chains(
    scene: CachedScene, test: ChainTest = "paper"
) -> list[tuple[dict[str, Any], float]]:
    """(truth fragment, plan error in m) of each fragment whose chain is wrong in plan (5 %
    of its diagonal): by the paper's mean keypoint error, by :func:`end_error_in_plan`
    (``"ends"``) or by :func:`shape_error_in_plan` (``"shape"``)."""
    wrong = []
    for fragment in scene.truth["fragments"]:
        layout = scene.layouts[fragment["id"]]
        estimated = layout.keypoints_local() if layout.ok else np.zeros((0, 3))
        error = _MEASURES[test](estimated, fragment)
        if error >= 0.05 * fragment["diagonal"]:
            wrong.append((fragment, error))
    return wrong


def chain_table(scenes: list[CachedScene]) -> str:
    """Fragments, those whose chain is right in plan, and the shares whose ends and whose
    whole shape are right too, by what lies near their arc's ends."""
    total: Counter[str] = Counter()
    wrong: dict[ChainTest, Counter[str]] = {test: Counter() for test in _MEASURES}
    for scene in scenes:
        total.update(f["near_end"] for f in scene.truth["fragments"])
        for test, counts in wrong.items():
            counts.update(f["near_end"] for f, _ in wrong_chains(scene, test))
    lines = [
        f"{'near an end':<12} {'fragments':>9} {'right':>6} {'share':>7} {'ends right':>11}"
        f" {'shape right':>12}"
    ]
    for group in (*("door", "window", "none"), "all"):
        n = total.total() if group == "all" else total[group]
        bad, ends, shape = (
            counts.total() if group == "all" else counts[group] for counts in wrong.values()
        )
        if n:
            lines.append(
                f"{group:<12} {n:>9} {n - bad:>6} {(n - bad) / n:>7.1%} {(n - ends) / n:>11.1%}"
                f" {(n - shape) / n:>12.1%}"
            )
    return "\n".join(lines)


def describe_wrong(scene: CachedScene, test: ChainTest = "paper") -> list[str]:
    """Three lines per wrong chain of a scene (by ``test``: see :func:`wrong_chains`): its
    name and error, the true and the estimated chain in world x, y."""
    lines = []
    for fragment, error in wrong_chains(scene, test):
        pose = np.asarray(fragment["pose"], dtype=np.float64)
        layout = scene.layouts[fragment["id"]]
        estimate = to_site(layout.keypoints_local(), pose)[:, :2] if layout.ok else np.zeros((0, 2))
        truth = to_site(np.asarray(fragment["keypoints_local"]), pose)[:, :2]
        lines += [
            f"{scene.seed} {fragment['id']} ({fragment['near_end']}): error {error:.2f} m "
            f"(wrong from {0.05 * fragment['diagonal']:.2f} m)",
            f"  truth    {np.round(truth, 2).tolist()}",
            f"  estimate {np.round(estimate, 2).tolist()}",
        ]
    return lines


def main(argv: list[str] | None = None) -> int:
    """Build the scenes of one draw, print the chain table (and the anatomy); exit code."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--seed", type=int, default=12, help="seed shift (10 and up: held out)")
    parser.add_argument("--per-bucket", type=int, default=20, help="synthetic rooms per bucket")
    parser.add_argument("--real", type=int, default=40, help="rooms of real outlines")
    parser.add_argument("--workers", type=int, default=2, help="processes building scenes")
    parser.add_argument("--anatomy", action="store_true", help="place the rooms: why wrong")
    parser.add_argument("--cues", action="store_true", help="junction cues' AUC")
    parser.add_argument("--list", action="store_true", help="print every wrong chain")
    parser.add_argument(
        "--by", choices=list(_MEASURES), default="paper", help="list: the test a chain fails"
    )
    args = parser.parse_args(argv)
    console = Console(width=160)
    jobs = cloud_jobs(args.per_bucket, args.real if DEFAULT_PATH.exists() else 0, args.seed)
    with multiprocessing.get_context("fork").Pool(args.workers) as pool:
        scenes = pool.map(_build, jobs, chunksize=1)
    if args.list:
        for scene in scenes:
            for line in describe_wrong(scene, args.by):
                console.print(line, highlight=False)
    console.print(chain_table(scenes), highlight=False)
    if args.cues:
        scores = cue_scores(scenes, PipelineParams().placement)
        console.print(cue_table(scores))
        console.print(evidence_table(*scores[STRUCTURE_CUE]))
    if args.anatomy:
        params = PipelineParams()
        with multiprocessing.get_context("fork").Pool(args.workers) as pool:
            rows = pool.starmap(anatomy_of, [(scene, params) for scene in scenes], chunksize=1)
        console.print(cause_table(rows))
        console.print(term_table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
