"""Benchmark of the global stage (paper section 4, Tables 1 and 3): ACC_global, pose errors,
layout error, room IoU and time of placement + refinement on paper-like scenes; the FPFH
chaining baseline on the same scenes; the ablation of the three energy terms; the time of
16-fragment scenes; paper-like scenes cut on room corners.

Run ``python bench/global_placement.py`` (``--quick`` for a small run, ``--scenes N``).
Scenes are :meth:`SceneSpec.paper` with fixed seeds. Local layouts are computed once per scene
and reused by every placement configuration. Pose errors come from
:func:`services.evaluation.pose_errors` after the robust site -> world alignment
(:func:`~services.evaluation.align_to_ground_truth`), translation measured at each fragment's
true centroid in percent of the room diagonal, for ours and for the baseline alike.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from rich import box
from rich.console import Console
from rich.table import Table

from schemas.params import PipelineParams, PlacementParams, RegistrationParams
from services.evaluation import (
    SceneReport,
    align_to_ground_truth,
    evaluate_result,
    pose_errors,
)
from services.pipeline import estimate_layout, place_site
from services.synthetic import SceneSpec, SyntheticScene, generate_scene, ground_truth_json
from services.types import FloatArray, LocalLayout

__all__ = ["SceneRun", "main"]

SEED_BASE, BIG_SEED_BASE, CORNER_SEED_BASE = 60_000, 70_000, 91_000
ABLATIONS = {
    "w/o closure term": PlacementParams(use_closure=False),
    "w/o complexity term": PlacementParams(use_complexity=False),
    "w/o boundary similarity term": PlacementParams(use_boundary=False),
    "full terms": PlacementParams(),
}
PAPER_ABLATION = {  # paper Table 3, ACC_global %
    "w/o closure term": 22.8,
    "w/o complexity term": 67.5,
    "w/o boundary similarity term": 80.2,
    "full terms": 85.1,
}
PAPER_POSE = {"FPFH": (40.05, 29.12), "ours": (8.79, 9.15)}  # paper Table 1: deg, %


def big_spec() -> SceneSpec:
    """16 fragments on big 16-corner rooms (long edges may hold two fragments)."""
    return dataclasses.replace(
        SceneSpec.paper(),
        n_fragments_range=(16, 16),
        n_corners_range=(16, 16),
        size_range=((14.0, 16.0), (18.0, 20.0)),
        straight_fragments=True,
    )


def corner_spec() -> SceneSpec:
    """Paper-like scenes whose cuts fall on room corners where they can (junctions turn)."""
    return dataclasses.replace(SceneSpec.paper(), corner_cut_share=1.0)


@dataclass
class SceneRun:
    """Everything measured on one scene."""

    seed: int
    n_fragments: int
    status: str
    report: SceneReport
    seconds_layout: float
    seconds_global: float  # placement + refinement, wall clock
    cpu_global: float  # the same, process CPU time (robust to a busy machine)
    ablation: dict[str, bool] = field(default_factory=dict)
    baseline: dict[str, tuple[float, float]] | None = None  # id -> (deg, % diag)
    baseline_seconds: float = math.nan

    def ours(self) -> dict[str, tuple[float, float]]:
        """Fragment id -> (rotation deg, translation % diag) of our placed fragments."""
        return {i: (e.rotation_deg, e.translation_pct) for i, e in self.report.pose_errors.items()}


def _place(
    layouts: Mapping[str, LocalLayout], placement: PlacementParams, truth: dict[str, Any]
) -> tuple[str, SceneReport, tuple[float, float]]:
    start, cpu_start = time.perf_counter(), time.process_time()
    result = place_site(layouts, PipelineParams(placement=placement))
    seconds = (time.perf_counter() - start, time.process_time() - cpu_start)
    return result.status, evaluate_result(result.model_dump(mode="json"), truth), seconds


def _baseline(
    scene: SyntheticScene, register: Callable[..., dict[str, FloatArray]], voxel: float
) -> tuple[dict[str, tuple[float, float]], float]:
    start = time.perf_counter()
    clouds = {f.id: f.points for f in scene.fragments}
    poses = register(clouds, RegistrationParams(voxel_size=voxel))
    seconds = time.perf_counter() - start
    true = {f.id: f.pose for f in scene.fragments}
    refs = {f.id: f.centroid_local for f in scene.fragments}
    alignment = align_to_ground_truth(poses, true, refs)
    errors = pose_errors(poses, true, alignment, scene.diagonal, refs)
    return {i: (e.rotation_deg, e.translation_pct) for i, e in errors.items()}, seconds


def run_scene(
    spec: SceneSpec,
    seed: int,
    ablation: bool,
    baseline: Callable[..., dict[str, FloatArray]] | None,
    voxel: float,
) -> SceneRun:
    """Layouts once, then the full placement, the ablations and optionally the baseline."""
    scene = generate_scene(spec, seed)
    truth = ground_truth_json(scene)
    start = time.perf_counter()
    layouts = {f.id: estimate_layout(f.points) for f in scene.fragments}
    seconds_layout = time.perf_counter() - start
    status, report, seconds = _place(layouts, PlacementParams(), truth)
    run = SceneRun(seed, len(scene.fragments), status, report, seconds_layout, *seconds)
    if ablation:
        for name, params in ABLATIONS.items():
            scored = report if params == PlacementParams() else _place(layouts, params, truth)[1]
            run.ablation[name] = scored.global_correct
    if baseline is not None:
        run.baseline, run.baseline_seconds = _baseline(scene, baseline, voxel)
    return run


def _pct(values: list[bool]) -> str:
    return f"{100 * np.mean(values):.1f}" if values else "-"


def _stat(values: list[float], how: Callable[[list[float]], Any] = np.mean) -> str:
    finite = [v for v in values if math.isfinite(v)]
    return f"{float(how(finite)):.2f}" if finite else "-"


def summary_table(runs: list[SceneRun], title: str) -> Table:
    """Paper-style numbers over scenes (pose errors over placed fragments)."""
    table = Table(title=title, title_justify="left", box=box.SIMPLE, show_header=False)
    table.add_column("metric")
    table.add_column("value", justify="right")
    fragments = [e for r in runs for e in r.ours().values()]
    n_fragments = sum(r.n_fragments for r in runs)
    layout = [r.report.layout_error_pct for r in runs if r.report.layout_error_pct]
    rows = [
        ("scenes / fragments", f"{len(runs)} / {n_fragments}"),
        ("status closed / open / failed (%)", _statuses(runs)),
        ("ACC_global (%)", _pct([r.report.global_correct for r in runs])),
        ("ACC_local (%)", _pct([c for r in runs for c in r.report.local_correct.values()])),
        ("fragments placed (%)", f"{100 * len(fragments) / max(n_fragments, 1):.1f}"),
        ("rotation error mean / median (deg)", _mean_median([e[0] for e in fragments])),
        ("translation error mean / median (% diag)", _mean_median([e[1] for e in fragments])),
        ("layout error mean (% diag), closed rooms", _stat([m for m, _ in layout])),
        ("layout error max (% diag), mean over rooms", _stat([m for _, m in layout])),
        ("room IoU mean, closed rooms", _stat([r.report.iou for r in runs if r.report.iou])),
        ("local layouts: s per scene (mean)", _stat([r.seconds_layout for r in runs])),
        ("placement + refinement: s per scene mean / max", _mean_max(runs)),
        ("  the same in CPU s", _mean_max(runs, cpu=True)),
    ]
    for name, value in rows:
        table.add_row(name, value)
    return table


def _statuses(runs: list[SceneRun]) -> str:
    shares = [100 * np.mean([r.status == s for r in runs]) for s in ("closed", "open", "failed")]
    return " / ".join(f"{v:.0f}" for v in shares)


def _mean_median(values: list[float]) -> str:
    return f"{_stat(values)} / {_stat(values, np.median)}"


def _mean_max(runs: list[SceneRun], cpu: bool = False) -> str:
    seconds = [r.cpu_global if cpu else r.seconds_global for r in runs]
    return f"{_stat(seconds)} / {_stat(seconds, max)}"


def baseline_table(runs: list[SceneRun], voxel: float) -> Table:
    """Ours vs the FPFH chaining baseline on the same scenes (paper Table 1)."""
    table = Table(
        title=f"Pose error vs FPFH baseline (voxel {voxel} m; {len(runs)} scenes)",
        title_justify="left",
        box=box.SIMPLE,
    )
    for header in ("method", "rotation mean (deg)", "rotation median (deg)"):
        table.add_column(header, justify="right")
    for header in ("translation mean (%)", "translation median (%)", "fragments", "paper (deg/%)"):
        table.add_column(header, justify="right")
    ours = [e for r in runs for e in r.ours().values()]
    base = [e for r in runs for e in (r.baseline or {}).values()]
    total = sum(r.n_fragments for r in runs)
    for name, errors in (("FPFH", base), ("ours", ours)):
        table.add_row(
            name,
            _stat([e[0] for e in errors]),
            _stat([e[0] for e in errors], np.median),
            _stat([e[1] for e in errors]),
            _stat([e[1] for e in errors], np.median),
            f"{len(errors)}/{total}",
            "{:.2f} / {:.2f}".format(*PAPER_POSE[name]),
        )
    ratio = [_ratio(base, ours, k, how) for k in (0, 1) for how in (np.mean, np.median)]
    table.add_row("FPFH / ours", *ratio, "", f"{40.05 / 8.79:.1f} / {29.12 / 9.15:.1f}")
    seconds = [r.baseline_seconds for r in runs]
    table.caption = f"FPFH time per scene: {_stat(seconds)} s mean (all pairs + chaining)"
    return table


def _ratio(
    base: list[tuple[float, float]],
    ours: list[tuple[float, float]],
    k: int,
    how: Callable[[list[float]], Any],
) -> str:
    a = [e[k] for e in base if math.isfinite(e[k])]
    b = [e[k] for e in ours if math.isfinite(e[k])]
    if not a or not b or float(how(b)) == 0.0:
        return "-"
    return f"{float(how(a)) / float(how(b)):.1f}x"


def ablation_table(runs: list[SceneRun]) -> Table:
    """ACC_global with each energy term switched off (paper Table 3)."""
    table = Table(title="Ablation (paper Table 3)", title_justify="left", box=box.SIMPLE)
    for header in ("configuration", "ACC_global (%)", "paper (%)"):
        table.add_column(header, justify="left" if header == "configuration" else "right")
    for name in ABLATIONS:
        correct = [r.ablation[name] for r in runs if name in r.ablation]
        table.add_row(name, _pct(correct), f"{PAPER_ABLATION[name]:.1f}")
    return table


def big_table(runs: list[SceneRun]) -> Table:
    """Time and outcome of 16-fragment scenes."""
    table = Table(title="16-fragment scenes", title_justify="left", box=box.SIMPLE)
    headers = ("seed", "fragments", "status", "correct", "local layouts (s)")
    for header in (*headers, "placement + refinement (s)", "CPU (s)"):
        table.add_column(header, justify="right")
    for r in runs:
        table.add_row(
            str(r.seed),
            str(r.n_fragments),
            r.status,
            "yes" if r.report.global_correct else "no",
            f"{r.seconds_layout:.1f}",
            f"{r.seconds_global:.1f}",
            f"{r.cpu_global:.1f}",
        )
    return table


def _registration() -> Callable[..., dict[str, FloatArray]] | None:
    try:
        from services.registration import chain_baseline
    except ImportError as exc:
        print(f"FPFH baseline skipped: services.registration unavailable ({exc})")
        return None
    return chain_baseline


def _arguments(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--quick", action="store_true", help="6 scenes, 1 baseline, 1 big")
    parser.add_argument("--scenes", type=int, help="paper-like scenes (default 40, quick 6)")
    parser.add_argument(
        "--baseline-scenes", type=int, help="scenes also run through FPFH (default 8, quick 1)"
    )
    parser.add_argument("--baseline-voxel", type=float, default=0.1, help="FPFH voxel, m")
    parser.add_argument("--big-scenes", type=int, help="16-fragment scenes (default 2, quick 1)")
    parser.add_argument(
        "--corner-scenes", type=int, help="scenes cut on corners (default 10, quick 2)"
    )
    parser.add_argument("--no-ablation", action="store_true", help="skip Table 3")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print its tables; returns the exit code."""
    args = _arguments(argv)
    n_scenes = args.scenes if args.scenes is not None else (6 if args.quick else 40)
    n_base = args.baseline_scenes if args.baseline_scenes is not None else (1 if args.quick else 8)
    n_big = args.big_scenes if args.big_scenes is not None else (1 if args.quick else 2)
    n_corner = args.corner_scenes if args.corner_scenes is not None else (2 if args.quick else 10)
    console = Console(width=None if sys.stdout.isatty() else 120)
    register = _registration() if n_base > 0 else None
    started = time.perf_counter()
    runs = []
    for k in range(n_scenes):
        method = register if k < n_base else None
        run = run_scene(
            SceneSpec.paper(), SEED_BASE + k, not args.no_ablation, method, args.baseline_voxel
        )
        runs.append(run)
        state = "correct" if run.report.global_correct else "wrong"
        console.log(f"scene {run.seed}: {run.n_fragments} fragments, {run.status}, {state}")
    console.print(summary_table(runs, f"Paper-like scenes (seeds {SEED_BASE}+)"))
    if register is not None:
        compared = [r for r in runs if r.baseline is not None]
        console.print(baseline_table(compared, args.baseline_voxel))
    if not args.no_ablation:
        console.print(ablation_table(runs))
    corner = [
        run_scene(corner_spec(), CORNER_SEED_BASE + k, False, None, 0.0) for k in range(n_corner)
    ]
    if corner:
        console.print(summary_table(corner, f"Cuts on corners (seeds {CORNER_SEED_BASE}+)"))
    big = [run_scene(big_spec(), BIG_SEED_BASE + k, False, None, 0.0) for k in range(n_big)]
    if big:
        console.print(big_table(big))
    console.print(f"total {(time.perf_counter() - started) / 60:.1f} min")
    return 0


if __name__ == "__main__":
    sys.exit(main())
