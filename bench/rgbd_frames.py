"""RGB-D frames: ACC_local, ACC_global, pose errors, and the time per frame to local layout.

Scenes are rendered by :mod:`services.synthetic.render` (ray casting; Kinect-like depth noise;
doors and windows seen through; furniture), a few stations per room, frames looking around
with little or no overlap. Each scene's frames go the way ``jigsaw align`` takes them
(:func:`services.pipeline.align_fragments`): frames that overlap are merged (ORB matches
verified on the depths), then the local layout of each frame or merged group, then the
global placement; scored by :func:`services.evaluation.evaluate_result` with the paper's
thresholds (5 % of the fragment's / room's diagonal). Time per frame is that of each local
layout (a merged group's counts once), wall clock and process CPU time (all threads; robust
to a busy machine).

    .venv/bin/python bench/rgbd_frames.py [--scenes 20] [--seed 1000] [--shapes]

``--shapes`` also runs rooms of real shapes (the MatterportLayout outlines of
``../shared/data``, the benchmark's test split) when present.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script, the repository's packages are importable

from services.evaluation import evaluate_result  # noqa: E402
from services.pipeline import align_fragments  # noqa: E402
from services.synthetic.render import (  # noqa: E402
    FrameSpec,
    frame_ground_truth_json,
    generate_frame_scene,
)
from services.types import FloatArray  # noqa: E402


@dataclass
class LayoutClock:
    """Wall and CPU seconds of each local layout, from the pipeline's progress reports (a
    stage lasts until the next one is reported)."""

    seconds: list[float] = field(default_factory=list)
    cpu: list[float] = field(default_factory=list)
    started: tuple[float, float] | None = None

    def __call__(self, stage: str, fraction: float) -> None:
        """Close the running layout's time, if any; open one if ``stage`` is a layout."""
        now = (time.perf_counter(), time.process_time())
        if self.started is not None:
            self.seconds.append(now[0] - self.started[0])
            self.cpu.append(now[1] - self.started[1])
        self.started = now if stage.startswith("local layout") else None


def run(
    n_scenes: int, first_seed: int, outlines: list[FloatArray] | None = None
) -> dict[str, float]:
    """Local and global figures over ``n_scenes`` frame scenes from ``first_seed``."""
    spec = FrameSpec()
    local, global_ok, rotation, translation, frames, statuses = [], [], [], [], [], []
    clock = LayoutClock()
    for k in range(n_scenes):
        seed = first_seed + k
        outline = outlines[k % len(outlines)] if outlines else None
        try:
            scene = generate_frame_scene(spec, seed, outline)
        except RuntimeError:
            continue  # no station tiles this room within range
        aligned = align_fragments({f.id: f.frame for f in scene.frames}, progress=clock)
        result = aligned.result.model_dump(mode="json")
        report = evaluate_result(result, frame_ground_truth_json(scene))
        local += list(report.local_correct.values())
        global_ok.append(report.global_correct)
        statuses.append(result["status"])
        frames.append(len(scene.frames))
        rotation += [e.rotation_deg for e in report.pose_errors.values()]
        translation += [e.translation_pct for e in report.pose_errors.values()]
    ms, ms_p90 = _median_ms(clock.seconds)
    cpu_ms, cpu_ms_p90 = _median_ms(clock.cpu)
    return {
        "scenes": len(global_ok),
        "frames": sum(frames),
        "acc_local": float(np.mean(local)) if local else math.nan,
        "acc_global": float(np.mean(global_ok)) if global_ok else math.nan,
        "rotation_deg": float(np.mean(rotation)) if rotation else math.nan,
        "translation_pct": float(np.mean(translation)) if translation else math.nan,
        "closed": statuses.count("closed"),
        "closed_right": sum(
            ok for ok, status in zip(global_ok, statuses, strict=True) if status == "closed"
        ),
        "ambiguous": statuses.count("ambiguous"),
        "ms_per_frame": ms,
        "ms_per_frame_p90": ms_p90,
        "cpu_ms_per_frame": cpu_ms,
        "cpu_ms_per_frame_p90": cpu_ms_p90,
    }


def _median_ms(values: list[float]) -> tuple[float, float]:
    """Median and 90th percentile of ``values`` (seconds), in milliseconds."""
    if not values:
        return math.nan, math.nan
    return 1000 * statistics.median(values), 1000 * float(np.percentile(values, 90))


def _row(name: str, r: dict[str, float]) -> str:
    return (
        f"| {name} | {r['scenes']} | {r['frames']} | {100 * r['acc_local']:.1f} | "
        f"{100 * r['acc_global']:.1f} | {r['rotation_deg']:.2f} | {r['translation_pct']:.2f} | "
        f"{r['closed']} ({r['closed_right']}) | {r['ambiguous']} | "
        f"{r['ms_per_frame']:.0f} ({r['ms_per_frame_p90']:.0f}) | "
        f"{r['cpu_ms_per_frame']:.0f} ({r['cpu_ms_per_frame_p90']:.0f}) |"
    )


def main() -> None:
    """Run the benchmark (command-line options: see ``--help``) and print its table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=1000, help="first seed (unseen: >= 1000)")
    parser.add_argument("--shapes", action="store_true", help="also real room shapes")
    args = parser.parse_args()
    print(
        "| rooms | scenes | frames | ACC_local % | ACC_global % | rotation deg | "
        "translation % | said closed (right) | ambiguous | ms/frame median (p90) | "
        "CPU ms/frame median (p90) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    print(_row("synthetic", run(args.scenes, args.seed)))
    if args.shapes:
        from bench.room_shapes import DEFAULT_PATH, load_room_shapes, split_houses

        if DEFAULT_PATH.exists():
            shapes = load_room_shapes(DEFAULT_PATH)
            _, test = split_houses(house for house, _ in shapes)
            # Rooms a few stations can see within the camera's range.
            outlines = [p for h, p in shapes if h in test and float(np.ptp(p, axis=0).max()) <= 9.0]
            print(_row("MatterportLayout shapes", run(args.scenes, args.seed, outlines)))
    print("paper (RGB-D and clouds): ACC_global 85.1 %, rotation 8.79 deg, translation 9.15 %")


if __name__ == "__main__":
    main()
