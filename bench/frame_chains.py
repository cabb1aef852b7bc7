"""RGB-D frames whose wall chain is wrong in the floor plan, one by one: where chain work on
frames starts.

Each frame of the rendered scenes (:func:`bench.rgbd_frames.cached_scenes`: laid out on its
own, no merging) is judged in the floor plan (:func:`bench.scoring.chain_error_in_plan`,
wrong at 5 % of the frame's diagonal or more: a wrong floor height alone is no chain error).
For each wrong one it prints the true and the estimated chain in world coordinates, and
whether its room's main placement is right anyway.

    .venv/bin/python bench/frame_chains.py [--scenes 60] [--seed 2000] [--shapes]
        [--camera kinect]

Use tune seeds (2000 and up; 1000-1999 are held out) when choosing what to change.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script, the repository's packages are importable

from bench.rgbd_frames import cached_scenes, outlines_for_seeds  # noqa: E402
from bench.scoring import add_params_option, chain_error_in_plan, params_with  # noqa: E402
from bench.world_scenes import CachedScene  # noqa: E402
from schemas.params import PipelineParams  # noqa: E402
from services.evaluation import evaluate_result  # noqa: E402
from services.model_export import to_site  # noqa: E402
from services.pipeline import place_site  # noqa: E402
from services.synthetic.render import CAMERAS  # noqa: E402
from services.types import FloatArray  # noqa: E402


@dataclass(frozen=True)
class WrongChain:
    """A frame whose chain is wrong in the floor plan.

    error, threshold: its mean keypoint error in plan and 5 % of its diagonal, m;
    truth, estimate: (K, 2) the true and the estimated chain, world x, y.
    """

    seed: int
    frame: str
    room_right: bool
    error: float
    threshold: float
    truth: FloatArray
    estimate: FloatArray


def wrong_chains(
    scenes: Iterable[CachedScene], params: PipelineParams = PipelineParams()
) -> tuple[int, list[WrongChain]]:
    """How many frames ``scenes`` hold, and those whose chain is wrong in plan."""
    total = 0
    wrong = []
    for scene in scenes:
        result = place_site(scene.layouts, params).model_dump(mode="json")
        room_right = evaluate_result(result, scene.truth).global_correct
        for fragment in scene.truth["fragments"]:
            total += 1
            layout = scene.layouts[fragment["id"]]
            estimated = layout.keypoints_local() if layout.ok else np.zeros((0, 3))
            error = chain_error_in_plan(estimated, fragment)
            threshold = 0.05 * float(fragment["diagonal"])
            if error < threshold:
                continue
            pose = np.asarray(fragment["pose"], dtype=np.float64)
            truth = np.asarray(fragment["keypoints_local"], dtype=np.float64)
            wrong.append(
                WrongChain(
                    scene.seed,
                    fragment["id"],
                    room_right,
                    error,
                    threshold,
                    to_site(truth, pose)[:, :2],
                    to_site(estimated, pose)[:, :2],
                )
            )
    return total, wrong


def describe(chain: WrongChain) -> str:
    """Three lines: the frame and its verdicts, its true and its estimated chain."""
    room = "right" if chain.room_right else "wrong"
    return (
        f"{chain.seed} {chain.frame}: error {chain.error:.2f} m (wrong from "
        f"{chain.threshold:.2f} m), room {room}\n"
        f"  truth    {np.round(chain.truth, 2).tolist()}\n"
        f"  estimate {np.round(chain.estimate, 2).tolist()}"
    )


def main(argv: list[str] | None = None) -> int:
    """List the wrong chains of synthetic rooms (and real shapes); returns the exit code."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--scenes", type=int, default=60)
    parser.add_argument("--seed", type=int, default=2000, help="first seed (tune: 2000 and up)")
    parser.add_argument("--shapes", action="store_true", help="real room shapes instead")
    parser.add_argument("--camera", choices=sorted(CAMERAS), default="kinect")
    add_params_option(parser)
    args = parser.parse_args(argv)
    params = params_with(args.set)
    outlines = outlines_for_seeds(args.seed) if args.shapes else None
    scenes = cached_scenes(args.scenes, args.seed, outlines, params, args.camera)
    total, wrong = wrong_chains(scenes, params)
    for chain in wrong:
        print(describe(chain))
    rooms = "real shapes" if args.shapes else "synthetic rooms"
    print(f"{args.camera}, {rooms}: {len(wrong)} of {total} frames wrong in plan")
    return 0


if __name__ == "__main__":
    sys.exit(main())
