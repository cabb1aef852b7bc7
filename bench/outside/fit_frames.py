"""The frames' calibration refitted on outside frame draws, and checked on fresh ones.

The frames' map (``placement.frame_calibration`` and the slopes that move a frames' room's
logit: ``frame_view_slope``, ``frame_view_top_slope``, ``frame_station_slope``) was fitted on
the project's own tune frames, which come out right more often than the outside draws
(:mod:`bench.outside.frames`, a renderer the pipeline was not tuned on). A map fitted there
raises confidence where it should not; this one is fitted on draws of the outside benchmark
and checked on draws it never saw.

What it fits: a second map ``(c, d)`` of the logit of each room's reported confidence
(:func:`bench.scoring.fit_logit_map`, the map in place). A frames' room's logit is
``a + b z + s x`` (its slopes' terms), so the two maps compose into ``(c + d a, d b)`` and
every slope times ``d`` (:func:`composed`). Rooms whose pieces are all frames (every outside
frames room) take that composition exactly; caps applied after the map (a loose room, an
unexplained wall) keep their ceilings.

    .venv/bin/python -m bench.outside.fit_frames --fit DIR... --check DIR...

Each DIR is a ``bench.outside.run frames`` draw (its scenes' ``score.json``). It prints the
map, the parameters to ``--set``, and the Brier score and a reliability table of the fit and
check draws before and after (the new confidences computed from the old, offline: run the
check draws again with the new parameters, ``bench.outside.run frames ... --in-process
--rerun --set ...``, to measure them through the pipeline).
"""

from __future__ import annotations

import argparse
import itertools
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from bench.scoring import fit_logit_map
from schemas.params import PlacementParams

__all__ = ["composed", "draw_verdicts", "main", "remapped"]

_SLOPES = ("frame_view_slope", "frame_view_top_slope", "frame_station_slope")
_BINS = (0.0, 0.2, 0.4, 0.6, 0.8, 0.9, 0.99, 1.0001)


def draw_verdicts(folders: Sequence[Path]) -> tuple[list[float], list[bool]]:
    """The reported confidence and whether the main room was right (ACC_global) of every
    scored scene in the draws' folders; a scene without a confidence (no result) counts as
    confidence 0."""
    confidences, right = [], []
    for folder in folders:
        for score_path in sorted(Path(folder).glob("*/score.json")):
            score = json.loads(score_path.read_text())
            confidences.append(float(score.get("confidence") or 0.0))
            right.append(bool(score["main"]["acc"]))
    return confidences, right


def composed(params: PlacementParams, coefficients: Sequence[float]) -> dict[str, object]:
    """The frames' map and slopes after a second map ``(c, d)`` of the logit.

    >>> new = composed(PlacementParams(frame_calibration=(-1.0, 0.5)), (0.5, 2.0))
    >>> new["frame_calibration"]
    (-1.5, 1.0)
    """
    bias, slope = coefficients[0], coefficients[1]
    a, b = params.frame_calibration
    out: dict[str, object] = {
        "frame_calibration": (round(bias + slope * a, 3), round(slope * b, 3))
    }
    for name in _SLOPES:
        out[name] = round(slope * float(getattr(params, name)), 3)
    return out


def remapped(confidences: Sequence[float], coefficients: Sequence[float]) -> np.ndarray:
    """The confidences through a map ``(c, d)`` of their logits."""
    conf = np.clip(np.asarray(confidences, dtype=np.float64), 1e-9, 1 - 1e-9)
    z = coefficients[0] + coefficients[1] * np.log(conf / (1 - conf))
    mapped: np.ndarray = 1.0 / (1.0 + np.exp(-z))
    return mapped


def _report(name: str, before: Sequence[float], after: np.ndarray, right: Sequence[bool]) -> str:
    ok = np.asarray(right, dtype=bool)
    old = np.asarray(before, dtype=np.float64)
    lines = [
        f"{name}: {len(ok)} rooms, {int(ok.sum())} right; Brier "
        f"{float(np.mean((old - ok) ** 2)):.3f} -> {float(np.mean((after - ok) ** 2)):.3f}",
        "| confidence | before: rooms, right | after: rooms, right |",
        "|---|---|---|",
    ]
    for lo, hi in itertools.pairwise(_BINS):
        was = (old >= lo) & (old < hi)
        now = (after >= lo) & (after < hi)
        lines.append(
            f"| {lo:g}-{min(hi, 1.0):g} | {int(was.sum())}, {int(ok[was].sum())} "
            f"| {int(now.sum())}, {int(ok[now].sum())} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Fit on ``--fit``'s draws, report on them and on ``--check``'s; exit code 0."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--fit", type=Path, nargs="+", required=True, help="draws to fit on")
    parser.add_argument("--check", type=Path, nargs="*", default=[], help="draws to check on")
    args = parser.parse_args(argv)
    confidences, right = draw_verdicts(args.fit)
    if not confidences:
        parser.error("no scored scene in the --fit folders")
    params = PlacementParams()
    coefficients, summary = fit_logit_map(confidences, right, params.closed_confidence)
    print(f"map of the reported logit: {coefficients}; {summary}")
    new = composed(params, coefficients)
    compact = {k: json.dumps(v, separators=(",", ":")) for k, v in new.items()}
    print(" ".join(f"--set placement.{k}={v}" for k, v in compact.items()))
    print(_report("fit", confidences, remapped(confidences, coefficients), right))
    if args.check:
        checked, verdicts = draw_verdicts(args.check)
        print(_report("check", checked, remapped(checked, coefficients), verdicts))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
