"""Benchmark of trustworthy placement (issue 10), per fragment-count bucket.

On scenes as hard as the world (``bench/world_scenes.py``: random room shapes cut into
2-16 fragments, and real room outlines cut into 2-8; the "test" split, never used for
fitting), it reports per bucket: ACC_global (paper), how many results said "closed" and
the share of those that are right, "ambiguous" and "open" counts, whether the truth is in
the top 3 (main result or its first two alternatives), ACC_local, pose and layout errors,
and the time of placement + refinement. Then: a reliability table (confidence bins vs share
right), how well each junction cue separates true from false neighbours (AUC, and the
structure evidence's likelihood ratio per bin), the
ablation of each energy term per bucket, and the gain from hints (prior poses of 1.5 m and
20 degrees drawn around the truth: alone, and with the layouts).

Run ``python -m bench.placement_trust`` (``--quick`` for a small run). Layouts are cached in
``out/bench-cache`` (``--cache``); the first run builds them (about 20 minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import math
import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich import box
from rich.console import Console
from rich.table import Table

from bench.scoring import (
    add_params_option,
    alternative_results,
    params_with,
    share_interval,
)
from bench.world_scenes import (
    BUCKETS,
    DEFAULT_CACHE,
    CachedScene,
    bucket_groups,
    bucket_of,
    build_sets,
    load_set,
    scene_jobs,
)
from schemas.hints import FragmentPrior, HintsModel
from schemas.params import PipelineParams, PlacementParams
from services.evaluation import evaluate_result, pose_errors
from services.pipeline import place_site
from services.placement import make_piece
from services.placement.evidence import boundary_mismatch, end_voxels, register_ends
from services.placement.pieces import SAMPLE_SPACING, Piece

__all__ = [
    "STRUCTURE_CUE",
    "Outcome",
    "cue_scores",
    "cue_table",
    "evidence_table",
    "main",
    "overlap_table",
]

ABLATIONS = {
    "full": {},
    "w/o structure": {"use_structure": False},
    "w/o boundary (paper E_b)": {"use_boundary": False},
    "w/o free space": {"use_free_space": False},
    "w/o closure": {"use_closure": False},
    "w/o complexity": {"use_complexity": False},
    "w/o floor outside": {"use_outside": False},
}
CONFIDENCE_BINS = (0.0, 0.3, 0.5, 0.7, 0.8, 0.9, 0.95, 0.98, 1.0001)


@dataclass(frozen=True)
class Outcome:
    """One scene's result, scored."""

    name: str
    seed: int
    n: int
    status: str
    confidence: float
    correct: bool
    top3: bool
    local: list[bool]
    pose: list[tuple[float, float]]  # (rotation deg, translation % diag) per placed fragment
    layout_error: float | None
    seconds: float
    # (the fragment's own confidence, its pose right relative to the loop's first fragment)
    fragments: list[tuple[float, bool]] = dataclasses.field(default_factory=list)

    @property
    def bucket(self) -> str:
        """The scene's fragment-count bucket, e.g. "6-8"."""
        return bucket_of(self.n)


def fragment_checks(result: dict[str, Any], truth: dict[str, Any]) -> list[tuple[float, bool]]:
    """Each fragment's confidence and whether its pose is right relative to the loop's
    first fragment (within 10 degrees, its centroid within 5 % of the diagonal): what a
    robot acting on its own pose in the result's frame needs."""
    placed = [
        f
        for f in result["fragments"]
        if f.get("confidence") is not None and f.get("pose") is not None
    ]
    if not placed:
        return []
    true = {f["id"]: np.asarray(f["pose"], dtype=np.float64) for f in truth["fragments"]}
    refs = {f["id"]: np.asarray(f["centroid_local"]) for f in truth["fragments"]}
    root = min(placed, key=lambda f: f["loop_index"])
    # Carry the result's frame onto the truth's through the first fragment alone.
    through_root = true[root["id"]] @ np.linalg.inv(np.asarray(root["pose"]))
    estimated = {f["id"]: np.asarray(f["pose"], dtype=np.float64) for f in placed}
    errors = pose_errors(estimated, true, through_root, float(truth["diagonal"]), refs)
    out = []
    for fragment in placed:
        error = errors[fragment["id"]]
        right = error.rotation_deg < 10.0 and error.translation_pct < 5.0
        out.append((float(fragment["confidence"]), right))
    return out


def run_scene(
    scene: CachedScene, params: PipelineParams, hints: HintsModel | None = None
) -> Outcome:
    """Place one scene and score the result and its alternatives against the truth."""
    start = time.perf_counter()
    result = place_site(scene.layouts, params, hints=hints).model_dump(mode="json")
    seconds = time.perf_counter() - start
    report = evaluate_result(result, scene.truth)
    alternatives = [
        evaluate_result(r, scene.truth).global_correct for r in alternative_results(result)
    ]
    return Outcome(
        name=scene.name,
        seed=scene.seed,
        n=scene.n_fragments,
        status=result["status"],
        confidence=float(result["confidence"]),
        correct=report.global_correct,
        top3=report.global_correct or any(alternatives[:2]),
        local=list(report.local_correct.values()),
        pose=[(e.rotation_deg, e.translation_pct) for e in report.pose_errors.values()],
        layout_error=report.layout_error_pct[0] if report.layout_error_pct else None,
        seconds=seconds,
        fragments=fragment_checks(result, scene.truth),
    )


def _pct(values: Iterable[bool]) -> str:
    items = list(values)
    return f"{100 * np.mean(items):.1f}" if items else "-"


def _pct_interval(values: Iterable[bool]) -> str:
    """The share right, % with its 95 % interval: "52.4 (32-72)"."""
    items = list(values)
    if not items:
        return "-"
    lo, hi = share_interval(sum(items), len(items))
    return f"{_pct(items)} ({100 * lo:.0f}-{100 * hi:.0f})"


def _mean_median(values: Sequence[float]) -> str:
    finite = [v for v in values if math.isfinite(v)]
    return f"{np.mean(finite):.2f} / {np.median(finite):.2f}" if finite else "-"


def bucket_table(outcomes: Sequence[Outcome], title: str) -> Table:
    """The main table: one row per set and bucket."""
    headers = [
        "set / fragments", "scenes", "ACC_global % (95 % interval)",
        "closed: right % (95 % interval)",
        "ambiguous", "open",
        "top-3 %", "ACC_local %", "rot. err mean/med deg", "transl. err mean/med %",
        "layout err %", "conf. mean", "time med / max s",
    ]  # fmt: skip
    table = _table(title, headers, 1)
    for label, rows in bucket_groups(outcomes, totals=True):
        closed = [o for o in rows if o.status == "closed"]
        layout = [o.layout_error for o in rows if o.layout_error is not None]
        seconds = [o.seconds for o in rows]
        table.add_row(
            label,
            str(len(rows)),
            _pct_interval(o.correct for o in rows),
            f"{len(closed)}: {_pct_interval(o.correct for o in closed)}",
            str(sum(o.status == "ambiguous" for o in rows)),
            str(sum(o.status == "open" for o in rows)),
            _pct(o.top3 for o in rows),
            _pct(c for o in rows for c in o.local),
            _mean_median([e[0] for o in rows for e in o.pose]),
            _mean_median([e[1] for o in rows for e in o.pose]),
            f"{np.mean(layout):.2f}" if layout else "-",
            f"{np.mean([o.confidence for o in rows]):.2f}",
            f"{np.median(seconds):.2f} / {max(seconds):.2f}",
        )
    return table


def _bin_label(lo: float, hi: float) -> str:
    """A confidence bin as text: [lo, hi), the last one closed."""
    return f"[{lo:.2f}, {min(hi, 1.0):.2f}{']' if hi > 1 else ')'}"


def _table(title: str, headers: Sequence[str], left: int = 0) -> Table:
    """A table of the benchmark's style: its first ``left`` columns left-aligned, the
    others (numbers) right-aligned."""
    table = Table(title=title, title_justify="left", box=box.SIMPLE)
    for k, header in enumerate(headers):
        table.add_column(header, justify="left" if k < left else "right")
    return table


def reliability_table(outcomes: Sequence[Outcome], of: str = "") -> Table:
    """Confidence bins against the share of right main results (calibration); ``of`` names
    the results in the title when they are not the benchmark's plain ones (priors)."""
    table = _table(
        f"Reliability{f' ({of})' if of else ''}: confidence vs share right",
        ("confidence", "results", "mean confidence", "right %", "said closed"),
    )
    confidence = np.array([o.confidence for o in outcomes])
    right = np.array([o.correct for o in outcomes])
    for lo, hi in itertools.pairwise(CONFIDENCE_BINS):
        inside = (confidence >= lo) & (confidence < hi)
        if not inside.any():
            continue
        closed = sum(o.status == "closed" for o, m in zip(outcomes, inside, strict=True) if m)
        table.add_row(
            _bin_label(lo, hi),
            str(int(inside.sum())),
            f"{confidence[inside].mean():.3f}",
            f"{100 * right[inside].mean():.1f}",
            str(closed),
        )
    brier = float(np.mean((confidence - right) ** 2)) if len(right) else math.nan
    table.caption = f"Brier score {brier:.3f} over {len(right)} results"
    return table


def fragment_reliability_table(outcomes: Sequence[Outcome]) -> Table:
    """Each fragment's own confidence against the share of fragments placed right."""
    table = _table(
        "Per-fragment reliability: a fragment's confidence vs its pose right",
        ("confidence", "fragments", "in ambiguous results", "right %"),
    )
    checks = [(c, r, o.status) for o in outcomes for c, r in o.fragments]
    confidence = np.array([c for c, _, _ in checks])
    right = np.array([r for _, r, _ in checks])
    ambiguous = np.array([s == "ambiguous" for _, _, s in checks])
    for lo, hi in itertools.pairwise(CONFIDENCE_BINS):
        inside = (confidence >= lo) & (confidence < hi)
        if not inside.any():
            continue
        table.add_row(
            _bin_label(lo, hi),
            str(int(inside.sum())),
            str(int((inside & ambiguous).sum())),
            f"{100 * right[inside].mean():.1f}",
        )
    return table


def _auc(positive: Sequence[float], negative: Sequence[float]) -> float:
    """Probability that a true pair scores above a false one (ties count half)."""
    if not positive or not negative:
        return math.nan
    values = np.concatenate([positive, negative])
    order = values.argsort(kind="mergesort")
    ranks = np.empty(len(values))
    ranks[order] = np.arange(1, len(values) + 1)
    for value in np.unique(values):  # average ranks of ties
        tied = values == value
        ranks[tied] = ranks[tied].mean()
    n_pos, n_neg = len(positive), len(negative)
    return float((ranks[:n_pos].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def _conflict(a: Piece, b: Piece) -> float:
    """Meters of wall through the other's seen space with b after a at a straight junction."""
    rotation = (a.directions[-1] - b.directions[0]) % 4
    end = a.keypoints[-1]
    samples_b = b.rotated[rotation][2] + end
    hits = a.rotated_free[0].hits(samples_b) + b.rotated_free[rotation].hits(a.rotated[0][2] - end)
    return hits * SAMPLE_SPACING


STRUCTURE_CUE = "structure (end regions registered)"
CueScores = dict[str, tuple[list[float], list[float]]]  # cue: (true pairs', false pairs')
# Bins of the structure evidence (the energy's structure score, negated): none, then up to
# full. The first holds exactly 0 (no agreement beyond chance).
_EVIDENCE_BINS = ((0.0, 0.0), (0.0, 0.3), (0.3, 0.6), (0.6, 0.9), (0.9, 1.0))


def cue_scores(scenes: Iterable[CachedScene], params: PlacementParams) -> CueScores:
    """Each junction cue's score of every ordered pair of pieces (b follows a), split into
    true neighbours and false ones; higher means "more likely neighbours"."""
    cues: CueScores = {
        STRUCTURE_CUE: ([], []),
        "boundary mismatch (paper E_b)": ([], []),
        "free-space conflict": ([], []),
    }
    for scene in scenes:
        pieces = {fid: make_piece(fid, lay) for fid, lay in scene.layouts.items() if lay.ok}
        loop = sorted(scene.truth["fragments"], key=lambda f: f["loop_index"])
        ids = [f["id"] for f in loop]
        true_pairs = set(zip(ids, ids[1:] + ids[:1], strict=True))
        targets = {fid: end_voxels(p, "target") for fid, p in pieces.items()}
        sources = {fid: end_voxels(p, "source") for fid, p in pieces.items()}
        for a in pieces:
            for b in pieces:
                if a == b:
                    continue
                side = 0 if (a, b) in true_pairs else 1
                scores = (
                    -register_ends(targets[a], sources[b]).score,
                    -boundary_mismatch(pieces[a], pieces[b], params),
                    -_conflict(pieces[a], pieces[b]),
                )
                for values, score in zip(cues.values(), scores, strict=True):
                    values[side].append(score)
    return cues


def cue_table(scores: CueScores) -> Table:
    """AUC of each junction cue (:func:`cue_scores`) for telling true neighbours from false
    ones."""
    table = _table(
        "Junction cues: true vs false neighbours", ("cue", "AUC", "true pairs", "false pairs"), 1
    )
    for name, (positive, negative) in scores.items():
        table.add_row(
            name, f"{_auc(positive, negative):.3f}", str(len(positive)), str(len(negative))
        )
    return table


def evidence_table(positive: Sequence[float], negative: Sequence[float]) -> Table:
    """The structure evidence's log likelihood ratio per bin: the log of the share of true
    pairs in the bin over the share of false pairs. What the energy's structure term should
    follow, bin by bin, on any set of scenes (an AUC hides where a cue errs).

    >>> table = evidence_table([0.0, 1.0, 1.0, 1.0], [0.0, 0.0, 0.0, 1.0])
    >>> list(table.columns[3].cells)[0], list(table.columns[3].cells)[-1]
    ('-1.10', '+1.10')
    """
    true, false = np.asarray(positive, dtype=np.float64), np.asarray(negative, dtype=np.float64)
    table = _table(
        "Structure evidence per bin",
        ("evidence", "true pairs", "false pairs", "log LR"),
    )
    for lo, hi in _EVIDENCE_BINS:
        if hi == lo:
            label = f"{lo:.1f}"
            n_true, n_false = int(np.sum(true == lo)), int(np.sum(false == lo))
        else:
            label = f"({lo:.1f}, {hi:.1f}]"
            n_true = int(np.sum((true > lo) & (true <= hi)))
            n_false = int(np.sum((false > lo) & (false <= hi)))
        ratio = "-"
        if n_true and n_false:
            ratio = f"{math.log((n_true / len(true)) / (n_false / len(false))):+.2f}"
        table.add_row(label, str(n_true), str(n_false), ratio)
    return table


def _true_displacement(scene: CachedScene, a: str, b: str) -> float:
    """How far b's chain source lies past a's chain target along their shared wall, in the
    true placement (negative: the chains overlap), m."""
    poses = {f["id"]: np.asarray(f["pose"]) for f in scene.truth["fragments"]}

    def world(fid: str, index: int) -> np.ndarray:
        keypoint = scene.layouts[fid].keypoints_local()[index]
        return (poses[fid][:3, :3] @ keypoint + poses[fid][:3, 3])[:2]

    target, before = world(a, -1), world(a, -2)
    travel = (target - before) / max(float(np.linalg.norm(target - before)), 1e-9)
    return float(travel @ (world(b, 0) - target))


def overlap_table(scenes: Iterable[CachedScene]) -> Table:
    """How well the end regions' structure measures the overlap at straight junctions (the
    refinement and the closure term take it as measured): share of true and false pairs
    with a measurement, and its error against the true displacement of the chain ends."""
    errors: list[float] = []
    true_straight = false_pairs = false_measured = 0
    for scene in scenes:
        pieces = {fid: make_piece(fid, lay) for fid, lay in scene.layouts.items() if lay.ok}
        straight = {
            (j["from"], j["to"])
            for j in scene.truth.get("junctions", [])
            if j["turn"] == 0 and {j["from"], j["to"]} <= pieces.keys()
        }
        for a, b in itertools.permutations(pieces, 2):
            match = register_ends(end_voxels(pieces[a], "target"), end_voxels(pieces[b], "source"))
            if (a, b) in straight:
                true_straight += 1
                if match.measured_shift is not None:
                    errors.append(abs(match.measured_shift - _true_displacement(scene, a, b)))
            else:
                false_pairs += 1
                false_measured += match.measured_shift is not None
    table = _table(
        "Overlaps measured by the end regions' structure",
        ("pairs", "count", "measured %", "error median m", "within 0.15 m %"),
        1,
    )
    err = np.asarray(errors)
    table.add_row(
        "true straight junctions",
        str(true_straight),
        f"{100 * len(err) / max(true_straight, 1):.1f}",
        f"{np.median(err):.3f}" if len(err) else "-",
        _pct(err < 0.15),
    )
    table.add_row(
        "false pairs",
        str(false_pairs),
        f"{100 * false_measured / max(false_pairs, 1):.1f}",
        "-",
        "-",
    )
    return table


def ablation_table(scenes: Sequence[CachedScene]) -> Table:
    """ACC_global per bucket with each energy term switched off."""
    labels = sorted({bucket_of(s.n_fragments) for s in scenes}, key=lambda b: int(b.split("-")[0]))
    table = _table("Ablation: ACC_global % per bucket", ("configuration", *labels, "all"), 1)
    for name, change in ABLATIONS.items():
        params = PipelineParams(placement=PlacementParams(**change))
        outcomes = [run_scene(s, params) for s in scenes]
        row = [_pct(o.correct for o in outcomes if o.bucket == label) for label in labels]
        table.add_row(name, *row, _pct(o.correct for o in outcomes))
    return table


def noisy_priors(scene: CachedScene, sigma_xy: float, sigma_yaw_deg: float) -> HintsModel:
    """Prior poses drawn around the true ones (the hints' frame is the world frame): each
    turned about its centroid by N(0, sigma_yaw) and moved by N(0, sigma_xy) per axis."""
    rng = np.random.default_rng(scene.seed)
    fragments = {}
    for truth in scene.truth["fragments"]:
        pose = np.asarray(truth["pose"], dtype=np.float64)
        centre = pose[:3, :3] @ np.asarray(truth["centroid_local"]) + pose[:3, 3]
        angle = math.radians(rng.normal(0.0, sigma_yaw_deg))
        turn = np.eye(4)
        turn[:2, :2] = [[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]]
        turn[:2, 3] = centre[:2] - turn[:2, :2] @ centre[:2] + rng.normal(0.0, sigma_xy, 2)
        prior = FragmentPrior(
            pose=(turn @ pose).tolist(), sigma_xy=sigma_xy, sigma_yaw_deg=sigma_yaw_deg
        )
        fragments[truth["id"]] = prior
    return HintsModel(fragments=fragments)


def hints_table(
    scenes: Sequence[CachedScene],
    sigma_xy: float,
    sigma_yaw: float,
    rooms: str = "random rooms",
    params: PipelineParams = PipelineParams(),
    record: list[Outcome] | None = None,
) -> Table:
    """Priors alone against priors with the layouts, per bucket; each scene's outcome with
    priors is appended to ``record`` when given."""
    title = (
        f"Hints ({rooms}): prior poses of {sigma_xy} m and {sigma_yaw} deg, alone and with "
        "the layouts"
    )
    headers = (
        "fragments",
        "scenes",
        "priors alone: rot. deg / transl. %",
        "with layouts: ACC_global %",
        "closed (right %)",
        "rot. err mean deg",
        "transl. err mean %",
        "time med s",
    )
    table = _table(title, headers)
    rows: dict[str, list[tuple[Outcome, list[tuple[float, float]]]]] = {}
    for scene in scenes:
        hints = noisy_priors(scene, sigma_xy, sigma_yaw)
        alone = _prior_errors(scene, hints)
        outcome = run_scene(scene, params, hints)
        rows.setdefault(outcome.bucket, []).append((outcome, alone))
        if record is not None:
            record.append(outcome)
    for label in sorted(rows, key=lambda b: int(b.split("-")[0])):
        pairs = rows[label]
        outcomes = [o for o, _ in pairs]
        alone = [e for _, errors in pairs for e in errors]
        closed = [o for o in outcomes if o.status == "closed"]
        table.add_row(
            label,
            str(len(outcomes)),
            f"{np.mean([e[0] for e in alone]):.1f} / {np.mean([e[1] for e in alone]):.1f}",
            _pct(o.correct for o in outcomes),
            f"{len(closed)} ({_pct(o.correct for o in closed)})",
            f"{np.mean([e[0] for o in outcomes for e in o.pose]):.2f}",
            f"{np.mean([e[1] for o in outcomes for e in o.pose]):.2f}",
            f"{np.median([o.seconds for o in outcomes]):.2f}",
        )
    return table


def _prior_errors(scene: CachedScene, hints: HintsModel) -> list[tuple[float, float]]:
    """Pose errors of the priors themselves (their frame is the world frame)."""
    truth = {f["id"]: np.asarray(f["pose"], dtype=np.float64) for f in scene.truth["fragments"]}
    refs = {f["id"]: np.asarray(f["centroid_local"]) for f in scene.truth["fragments"]}
    priors = {fid: np.asarray(p.pose) for fid, p in hints.fragments.items()}
    errors = pose_errors(priors, truth, np.eye(4), float(scene.truth["diagonal"]), refs)
    return [(e.rotation_deg, e.translation_pct) for e in errors.values()]


def _arguments(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="4 scenes per bucket, 8 real")
    parser.add_argument("--per-bucket", type=int, default=30, help="random rooms per bucket")
    parser.add_argument("--real", type=int, default=200, help="real room shapes (2-8 fragments)")
    parser.add_argument("--split", choices=("test", "tune"), default="test")
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--workers", type=int, default=2, help="processes building layouts")
    parser.add_argument("--ablation-per-bucket", type=int, default=10, help="0 to skip")
    parser.add_argument("--hints-per-bucket", type=int, default=10, help="0 to skip")
    parser.add_argument(
        "--hints-real", type=int, default=0, help="real rooms in a hints table of their own"
    )
    parser.add_argument(
        "--hints-sigma",
        type=float,
        nargs=2,
        default=(1.5, 20.0),
        metavar=("M", "DEG"),
        help="the priors' standard deviations",
    )
    parser.add_argument("--cues-scenes", type=int, default=60, help="0 to skip the AUC table")
    parser.add_argument("--dump", type=Path, help="write every scene's outcome to this JSON")
    parser.add_argument(
        "--dump-hints", type=Path, help="write every scene's outcome with priors to this JSON"
    )
    add_params_option(parser)
    return parser.parse_args(argv)


def _subset(scenes: Sequence[CachedScene], per_bucket: int) -> list[CachedScene]:
    out: list[CachedScene] = []
    for lo, hi in BUCKETS:
        out += [s for s in scenes if s.name.endswith("_syn") and lo <= s.n_fragments <= hi][
            :per_bucket
        ]
    return out


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print its tables; returns the exit code."""
    args = _arguments(argv)
    per_bucket, real = (4, 8) if args.quick else (args.per_bucket, args.real)
    console = Console(width=None if sys.stdout.isatty() else 160)
    started = time.perf_counter()
    jobs = scene_jobs(args.split, per_bucket, real, args.cache)
    build_sets(jobs, args.workers, lambda line: console.log(f"layouts {line}"))
    scenes = list(load_set(jobs))
    params = params_with(args.set)
    outcomes = []
    for scene in scenes:
        outcome = run_scene(scene, params)
        outcomes.append(outcome)
        console.log(
            f"{scene.name} {scene.seed}: {scene.n_fragments} fragments, {outcome.status} "
            f"({outcome.confidence:.2f}), {'right' if outcome.correct else 'wrong'}, "
            f"{outcome.seconds:.2f} s"
        )
    if args.dump:
        args.dump.write_text(json.dumps([dataclasses.asdict(o) for o in outcomes]))
    console.print(bucket_table(outcomes, f"Placement on '{args.split}' scenes (world preset)"))
    console.print(reliability_table(outcomes))
    console.print(fragment_reliability_table(outcomes))
    if args.cues_scenes:
        scores = cue_scores(scenes[: args.cues_scenes], PlacementParams())
        console.print(cue_table(scores))
        console.print(evidence_table(*scores[STRUCTURE_CUE]))
        console.print(overlap_table(scenes[: args.cues_scenes]))
    if args.ablation_per_bucket:
        console.print(ablation_table(_subset(scenes, args.ablation_per_bucket)))
    sigma_xy, sigma_yaw = args.hints_sigma
    with_priors: list[Outcome] = []
    if args.hints_per_bucket:
        hinted = _subset(scenes, args.hints_per_bucket)
        console.print(hints_table(hinted, sigma_xy, sigma_yaw, params=params, record=with_priors))
    if args.hints_real:
        real_rooms = [s for s in scenes if s.name.endswith("_real")][: args.hints_real]
        rooms = "real room shapes"
        console.print(hints_table(real_rooms, sigma_xy, sigma_yaw, rooms, params, with_priors))
    if with_priors:
        priors = f"with priors of {sigma_xy} m and {sigma_yaw} deg"
        console.print(reliability_table(with_priors, priors))
    if args.dump_hints:
        args.dump_hints.write_text(json.dumps([dataclasses.asdict(o) for o in with_priors]))
    console.print(f"total {(time.perf_counter() - started) / 60:.1f} min")
    return 0


if __name__ == "__main__":
    sys.exit(main())
