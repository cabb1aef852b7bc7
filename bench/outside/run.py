"""Generate the outside scenes, run ``jigsaw align`` on each, score them, print the tables.

    .venv/bin/python -m bench.outside.run clouds --per-bucket 40 --real 120 --out DIR
    .venv/bin/python -m bench.outside.run frames --per-camera 80 --out DIR

``clouds``: ``--per-bucket`` synthetic rooms (the six kinds in turn) per bucket of 2-3, 4-5,
6-8, 9-12 and 13-16 fragments, and ``--real`` rooms of real outlines with 2-8 fragments.
``frames``: ``--per-camera`` rooms per camera (kinect, realsense, wide), half of them real
outlines. ``--seed`` shifts every scene's seed (0: the seeds the originals used). Each scene
is written to ``DIR/<name>/`` with its ``result.json``, ``stderr.txt`` and ``score.json``;
a scene already scored there is reused, not run again. Two processes at most; the CLI runs
with one thread (``OMP_NUM_THREADS=1``). The tables also go to ``DIR/report.md`` and the
scores to ``DIR/scores.jsonl``. Real outlines are skipped, with a message, when the shapes
file is missing.

``--in-process`` runs ``jigsaw align`` in the worker (:func:`cli.pipeline.run_align`, about
five times faster without a process per scene; its times are not the CLI's) and accepts
``--set SECTION.FIELD=VALUE`` to try parameters; ``--rerun`` aligns scenes already scored
again (their generated files are kept), to compare settings on the same scenes.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import itertools
import json
import multiprocessing
import os
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bench.outside import clouds
from bench.outside.score import score_result
from bench.room_shapes import DEFAULT_PATH
from bench.scoring import add_params_option, params_with

__all__ = ["cloud_jobs", "frame_jobs", "main", "run_job"]

BUCKETS = [(2, 3), (4, 5), (6, 8), (9, 12), (13, 16)]
CAM_SEED = {"kinect": 10000, "realsense": 20000, "wide": 30000}
# Per block of 12 frame rooms: half synthetic (rect 2, L 2, U 1, T 1), half real outlines.
BLOCK = ["rect", "L", "real", "U", "real", "rect", "T", "real", "L", "real", "real", "real"]
SEED_SHIFT = 100_000  # --seed S adds S times this to every scene's seed
Score = dict[str, Any]


@dataclass(frozen=True)
class Job:
    """One scene: its folder's name, seed, room kind, bucket, and fragment count (clouds) or
    camera (frames)."""

    name: str
    source: str
    seed: int
    kind: str
    bucket: str
    n: int = 0
    camera: str = ""


def cloud_jobs(per_bucket: int, n_real: int, seed: int = 0) -> list[Job]:
    """The cloud scenes: ``per_bucket`` synthetic per bucket, ``n_real`` real (2-8 fragments)."""
    if per_bucket > 100:
        raise ValueError("at most 100 scenes per bucket (their seeds would overlap)")
    jobs = []
    for b, (lo, hi) in enumerate(BUCKETS):
        for i in range(per_bucket):
            s = SEED_SHIFT * seed + 10000 + 100 * b + i
            n = int(np.random.default_rng(s).integers(lo, hi + 1))
            kind = clouds.SYN_KINDS[i % len(clouds.SYN_KINDS)]
            jobs.append(Job(f"syn_{kind}_n{n:02d}_s{s}", "clouds", s, kind, f"{lo}-{hi}", n))
    for i in range(n_real):
        s = SEED_SHIFT * seed + 20000 + i
        n = int(np.random.default_rng(s).integers(2, 9))
        jobs.append(Job(f"real_n{n:02d}_s{s}", "clouds", s, "real", "real 2-8", n))
    return jobs


def frame_jobs(per_camera: int, seed: int = 0) -> list[Job]:
    """The frame scenes: ``per_camera`` rooms for each camera."""
    jobs = []
    for cam, first in CAM_SEED.items():
        for i in range(per_camera):
            kind = BLOCK[i % len(BLOCK)]
            s = SEED_SHIFT * seed + first + i
            jobs.append(Job(f"{cam}_{i:03d}_{kind}_s{s}", "frames", s, kind, cam, camera=cam))
    return jobs


def _generate(job: Job, d: Path) -> list[Path]:
    """The scene written into ``d`` unless there already; what ``jigsaw align`` is given
    (its folder: the PLY files; or the frames' folder)."""
    if job.source == "frames":
        if not (d / "truth.json").exists():
            from bench.outside import frames  # open3d: imported in the workers only

            frames.make_scene(d, job.seed, job.camera, job.kind)
        return [d / "frames"]
    if not (d / "truth.json").exists():
        clouds.generate(job.seed, job.kind, job.n, d)
    return [d]


def _run_cli(inputs: list[Path], out: Path, timeout: float) -> tuple[Any, float, str]:
    """(exit code or "timeout", wall time in s, stderr) of ``jigsaw align``, one thread."""
    jigsaw = Path(sys.executable).parent / "jigsaw"
    env = {
        **os.environ,
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
    }
    out.unlink(missing_ok=True)
    t0 = time.time()
    try:
        p = subprocess.run(
            [str(jigsaw), "align", *map(str, inputs), "-o", str(out)],
            capture_output=True, text=True, timeout=timeout, env=env, check=False,
        )  # fmt: skip
        rc: Any = p.returncode
        err = p.stderr
    except subprocess.TimeoutExpired as e:
        rc = "timeout"
        err = e.stderr.decode() if isinstance(e.stderr, bytes) else str(e.stderr or "")
    return rc, time.time() - t0, err


def _run_in_process(
    inputs: list[Path], out: Path, settings: Iterable[str]
) -> tuple[Any, float, str]:
    """What :func:`_run_cli` gives, with ``jigsaw align`` run in this process
    (:func:`cli.pipeline.run_align`, its exit codes and stderr) under the parameters
    ``settings`` (``SECTION.FIELD=VALUE``)."""
    from cli.pipeline import run_align  # open3d: imported in the workers only

    out.unlink(missing_ok=True)
    err = io.StringIO()
    t0 = time.time()
    with contextlib.redirect_stderr(err):
        rc = run_align(inputs, out, params_with(settings))
    return rc, time.time() - t0, err.getvalue()


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def run_job(
    job: Job,
    out: Path,
    timeout: float = 900.0,
    settings: tuple[str, ...] | None = None,
    rerun: bool = False,
) -> Score:
    """One scene generated, aligned and scored (``score.json`` of its folder); the score
    already there when there is one, unless ``rerun``. Aligned by the CLI, or in this
    process under the parameters ``settings`` when they are given (an empty tuple: the
    defaults)."""
    d = Path(out) / job.name
    if (d / "score.json").exists() and not rerun:
        return dict(json.loads((d / "score.json").read_text()))
    inputs = _generate(job, d)
    if settings is None:
        rc, wall, err = _run_cli(inputs, d / "result.json", timeout)
    else:
        rc, wall, err = _run_in_process(inputs, d / "result.json", settings)
    (d / "stderr.txt").write_text(err or "")
    truth = json.loads((d / "truth.json").read_text())
    n = len(truth["fragments"]) if "fragments" in truth else len(truth["frames"])
    s = dict(
        scene=job.name, **asdict(job), corners=len(truth["polygon"]), exit_code=rc, wall_s=wall,
        traceback="Traceback" in (err or ""), stderr_tail=(err or "")[-1500:],
        n_stations=len(truth.get("stations", [])),
    )  # fmt: skip
    s.update(score_result(truth, _read_json(d / "result.json")), n=n)
    (d / "score.json").write_text(json.dumps(s, indent=1))
    return s


def _run_job(args: tuple[Job, Path, float, tuple[str, ...] | None, bool]) -> Score:
    return run_job(*args)


def summary_line(s: Score) -> str:
    """One line per scene: status, confidence, right, ACC_global, errors, time."""
    m = s["main"]
    ye = max(m["yaw_err"].values(), default=float("nan"))
    te = max(m["trans_err"].values(), default=float("nan"))
    return (
        f"{s['scene']} status={s['status']} conf={s['confidence']} right={m['right']} "
        f"acc={m['acc']} poly_err={m['poly_err']:.3f} corners {m['n_corners_est']}/"
        f"{m['n_corners_true']} max_yaw={ye:.1f} max_trans={te:.1f}% top3={s['top3']} "
        f"t={s['wall_s']:.1f}s exit={s['exit_code']}"
    )


def run_all(
    jobs: list[Job],
    out: Path,
    timeout: float,
    processes: int = 2,
    settings: tuple[str, ...] | None = None,
    rerun: bool = False,
) -> list[Score]:
    """Every job run (2 processes at most; ``settings`` and ``rerun`` as
    :func:`run_job` takes them); the scores in the jobs' order."""
    out.mkdir(parents=True, exist_ok=True)
    scores: dict[str, Score] = {}
    context = multiprocessing.get_context("spawn")
    work = [(j, out, timeout, settings, rerun) for j in jobs]
    with context.Pool(max(1, min(processes, 2))) as pool:
        for s in pool.imap_unordered(_run_job, work):
            scores[s["scene"]] = s
            print(summary_line(s), flush=True)
    return [scores[j.name] for j in jobs]


# ----------------------------------------------------------------------------- tables
HEADER = [
    "group", "rooms", "ACC_global", "right (strict)", "said closed", "closed: right",
    "ambig", "open", "failed", "top-3", "mean conf", "mean yaw err deg", "frags yaw>5deg",
    "median trans err %diag", "median time s", "largest consistent group",
]  # fmt: skip


def _pct(k: int, n: int) -> str:
    return "-" if n == 0 else f"{k}/{n} ({100.0 * k / n:.0f}%)"


def _mean(values: list[float], fmt: str = ".2f") -> str:
    return format(float(np.mean(values)), fmt) if values else "-"


def _median(values: list[float], fmt: str = ".1f") -> str:
    return format(float(np.median(values)), fmt) if values else "-"


def group_row(name: str, S: list[Score]) -> list[Any]:
    """One table row of a group of scores (columns: :data:`HEADER`); yaw errors leave out
    each scene's anchor (zero by construction)."""
    n = len(S)
    closed = [s for s in S if s["status"] == "closed"]
    status = Counter(s["status"] for s in S)
    confs = [s["confidence"] for s in S if isinstance(s["confidence"], int | float)]
    yaws = [v for s in S for k, v in s["main"]["yaw_err"].items() if k != s["main"]["anchor"]]
    trs = [v for s in S for v in s["main"]["trans_err"].values()]
    times = [s["wall_s"] for s in S if isinstance(s["wall_s"], int | float)]
    return [
        name, n, _pct(sum(s["main"]["acc"] for s in S), n),
        _pct(sum(s["main"]["right"] for s in S), n), _pct(len(closed), n),
        _pct(sum(s["main"]["right"] for s in closed), len(closed)), status["ambiguous"],
        status["open"], n - status["closed"] - status["ambiguous"] - status["open"],
        _pct(sum(s["top3"] for s in S), n), _mean(confs), _mean(yaws, ".1f"),
        _pct(sum(y > 5 for y in yaws), len(yaws)), _median(trs), _median(times),
        _mean([s["main"]["max_consistent"] / s["n"] for s in S], ".0%"),
    ]  # fmt: skip


def fmt_table(rows: list[list[Any]], header: list[str]) -> str:
    """A markdown table."""
    w = [max(len(str(x)) for x in col) for col in zip(header, *rows, strict=False)]

    def line(r: list[Any]) -> str:
        return "| " + " | ".join(str(x).ljust(k) for x, k in zip(r, w, strict=True)) + " |"

    return "\n".join(
        [line(header), "|" + "|".join("-" * (k + 2) for k in w) + "|"] + [line(r) for r in rows]
    )


def group_rows(
    scores: list[Score], key: Callable[[Score], str], order: Iterable[str] | None = None
) -> list[list[Any]]:
    """One row per group of scores (the groups sorted, or in ``order``)."""
    groups: dict[str, list[Score]] = {}
    for s in scores:
        groups.setdefault(key(s), []).append(s)
    names = [g for g in order if g in groups] if order is not None else sorted(groups)
    return [group_row(g, groups[g]) for g in names]


def grouped(
    scores: list[Score], key: Callable[[Score], str], order: Iterable[str] | None = None
) -> str:
    """A table of :func:`group_rows`."""
    return fmt_table(group_rows(scores, key, order), HEADER)


RELIABILITY = ["confidence", "count", "share right", "share ACC_global", "mean conf", "statuses"]


def reliability(scores: list[Score]) -> str:
    """Share of right rooms per confidence bin, and the Brier score of the confidence."""
    bins = [0.0, 0.2, 0.4, 0.6, 0.8, 0.9, 0.95, 0.99, 1.0001]
    rated = [s for s in scores if isinstance(s["confidence"], int | float)]
    rows: list[list[Any]] = []
    for lo, hi in itertools.pairwise(bins):
        S = [s for s in rated if lo <= s["confidence"] < hi]
        status = Counter(s["status"] for s in S)
        right, acc = sum(s["main"]["right"] for s in S), sum(s["main"]["acc"] for s in S)
        conf = _mean([s["confidence"] for s in S], ".3f")
        statuses = " ".join(f"{k}:{v}" for k, v in sorted(status.items()))
        bin_name = f"{lo:.2f}-{min(hi, 1.0):.2f}"
        rows.append([bin_name, len(S), _pct(right, len(S)), _pct(acc, len(S)), conf, statuses])
    table = fmt_table(rows, RELIABILITY)
    if rated:
        c = np.array([s["confidence"] for s in rated], float)
        y = np.array([s["main"]["right"] for s in rated], float)
        table += (
            f"\n\nBrier score {np.mean((c - y) ** 2):.3f}; mean confidence {c.mean():.3f}, "
            f"share right {y.mean():.3f}"
        )
    return table


def _tail(scores: list[Score]) -> str:
    """The wrong 'closed' results, the exit codes and the tracebacks."""
    wrong = [s for s in scores if s["status"] == "closed" and not s["main"]["right"]]
    lines = [f"### Wrong 'closed' results ({len(wrong)})"]
    for s in sorted(wrong, key=lambda s: -s["confidence"]):
        m = s["main"]
        lines.append(
            f"- {s['scene']}: {s['n']} fragments, conf {s['confidence']:.3f}, poly_err "
            f"{m['poly_err']:.3f}, corners est/true {m['n_corners_est']}/{m['n_corners_true']}, "
            f"max yaw err {max(m['yaw_err'].values(), default=float('nan')):.1f}"
        )
    codes = dict(Counter(str(s["exit_code"]) for s in scores))
    tracebacks = [s["scene"] for s in scores if s.get("traceback")]
    lines.append(
        f"\nexit codes: {codes}; a Traceback on stderr: {len(tracebacks)} {tracebacks[:10]}"
    )
    return "\n".join(lines)


LEGEND = (
    "ACC_global: the paper's metric (mean corner distance < 5 % of the diagonal, best anchor); "
    "right: ACC_global, as many corners as the truth, every fragment within 10 deg and 10 % of "
    "the diagonal (a frame's translation: its camera centre's)."
)


def cloud_report(scores: list[Score]) -> str:
    """The cloud scenes' tables: per bucket, per room kind, reliability."""
    order = [f"{lo}-{hi}" for lo, hi in BUCKETS] + ["real 2-8"]
    rows = group_rows(scores, lambda s: s["bucket"], order)
    syn = [s for s in scores if s["kind"] != "real"]
    rows += [group_row("all synthetic", syn)] if syn else []
    rows.append(group_row("ALL", scores))
    parts = [LEGEND, "### Per bucket\n" + fmt_table(rows, HEADER)]
    parts.append(
        "### Per room kind\n" + grouped(scores, lambda s: s["kind"], [*clouds.SYN_KINDS, "real"])
    )
    parts += ["### Reliability (all scenes)\n" + reliability(scores), _tail(scores)]
    return "\n\n".join(parts)


def _frames_bucket(s: Score) -> str:
    n = s["n"]
    return f"{s['camera']} " + ("2-3" if n <= 3 else ("4-5" if n <= 5 else "6-8"))


def frame_report(scores: list[Score]) -> str:
    """The frame scenes' tables: camera x frames per room (synthetic, real), per camera, per
    number of stations, overall, reliability."""
    parts = [LEGEND]
    for src in ("synthetic", "real"):
        S = [s for s in scores if (s["kind"] == "real") == (src == "real")]
        if S:
            parts.append(
                f"### {src} rooms: camera x frames per room\n" + grouped(S, _frames_bucket)
            )
    stations = grouped(scores, lambda s: f"{s['n_stations']} station(s)")
    parts += [
        "### Per camera\n" + grouped(scores, lambda s: s["camera"], CAM_SEED),
        "### Per number of stations\n" + stations,
        "### Overall\n" + fmt_table([group_row("all", scores)], HEADER),
        "### Reliability (all scenes)\n" + reliability(scores),
        _tail(scores),
    ]
    return "\n\n".join(parts)


# ----------------------------------------------------------------------------- command line
def _arguments(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    c = sub.add_parser("clouds", help="point-cloud rooms")
    c.add_argument("--per-bucket", type=int, default=20, help="synthetic rooms per bucket")
    c.add_argument("--real", type=int, default=60, help="rooms of real outlines")
    f = sub.add_parser("frames", help="RGB-D frame rooms")
    f.add_argument("--per-camera", type=int, default=20, help="rooms per camera")
    for p in (c, f):
        p.add_argument("--seed", type=int, default=0, help="seed shift (0: the originals' seeds)")
        p.add_argument("--out", type=Path, required=True, help="the scenes' folder")
        p.add_argument("--timeout", type=float, default=900.0, help="per CLI run, seconds")
        p.add_argument("--processes", type=int, default=2, choices=(1, 2))
        p.add_argument(
            "--in-process", action="store_true", help="align in the workers, not by the CLI"
        )
        p.add_argument("--rerun", action="store_true", help="align scored scenes again")
        add_params_option(p)
    args = parser.parse_args(argv)
    if args.set and not args.in_process:
        parser.error("--set needs --in-process (the CLI takes no parameters)")
    try:
        params_with(args.set)  # a bad setting stops here, not in every scene
    except ValueError as exc:  # pydantic's ValidationError is a ValueError
        parser.error(f"--set: {exc}")
    return args


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (options: see ``--help``) and print its tables."""
    args = _arguments(argv)
    real_ok = DEFAULT_PATH.exists()
    if not real_ok:
        print(f"real room shapes skipped: {DEFAULT_PATH} is missing", file=sys.stderr)
    if args.what == "clouds":
        jobs = cloud_jobs(args.per_bucket, args.real if real_ok else 0, args.seed)
    else:
        jobs = [j for j in frame_jobs(args.per_camera, args.seed) if real_ok or j.kind != "real"]
    t0 = time.time()
    settings = tuple(args.set) if args.in_process else None
    scores = run_all(jobs, args.out, args.timeout, args.processes, settings, args.rerun)
    report = cloud_report(scores) if args.what == "clouds" else frame_report(scores)
    report += f"\n\n({len(scores)} scenes; {time.time() - t0:.0f} s)"
    (args.out / "report.md").write_text(report + "\n")
    (args.out / "scores.jsonl").write_text("".join(json.dumps(s) + "\n" for s in scores))
    print(report)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
