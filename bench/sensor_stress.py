"""Other sensors: placement with scanners noisier or thinner than the calibration's.

Is a "closed" result still right when the scanner is noisier or thinner than any the
confidence was fitted on? World-preset scenes (``SceneSpec.world()``, 2-8 fragments) with
one scanner property pushed past the preset's range, per fragment-count bucket:
ACC_global, said closed (and how many right), ambiguous, open, and the Brier score of the
confidence.

- ``noisy``: depth noise 3-5 cm, 5 % outliers, tilt up to 6 degrees (the preset: 0.5-3
  cm, 2 %, 4 degrees);
- ``sparse``: 8 000-15 000 points per fragment (the preset: 30 000 and more, scaled down
  to 19 000 at 16 fragments);
- ``vsparse``: 4 000-8 000 points.

Clouds under ``LayoutParams.min_calibrated_points`` are "thin": their rooms get the map of
``PlacementParams.thin_cloud_calibration``. ``--fit`` refits that map on the thin variants
(use tune seeds, other than the report's) with the map off, and prints it.

    .venv/bin/python -m bench.sensor_stress [--per-bucket 25] [--seed 7000] [--variants ...]
    .venv/bin/python -m bench.sensor_stress --fit --per-bucket 30 --seed 9000
"""

from __future__ import annotations

import argparse
import dataclasses
from typing import Any

import numpy as np

from bench.scoring import fit_logit_map, main_room_verdict
from schemas.params import PipelineParams
from services.evaluation import evaluate_result
from services.pipeline import estimate_layout, place_site
from services.synthetic.scene import SceneSpec, generate_scene, ground_truth_json

__all__ = ["VARIANTS", "main", "run"]

VARIANTS: dict[str, dict[str, Any]] = {
    "noisy": {"noise_range": (0.03, 0.05), "outlier_fraction": 0.05, "max_tilt_deg": 6.0},
    "sparse": {"points_per_fragment": (8_000, 15_000)},
    "vsparse": {"points_per_fragment": (4_000, 8_000)},
}
BUCKETS = ((2, 3), (4, 5), (6, 8))
_SEED_STRIDE = 100  # seeds of one bucket: first + stride * bucket index + k


def run(
    variant: str, per_bucket: int, first_seed: int, params: PipelineParams = PipelineParams()
) -> list[dict[str, Any]]:
    """One record per scene: bucket, status, right (the result as reported), main (its main
    room's confidence and verdict, :func:`bench.scoring.main_room_verdict`)."""
    records = []
    for b, (lo, hi) in enumerate(BUCKETS):
        spec = dataclasses.replace(
            SceneSpec.world(), n_fragments_range=(lo, hi), **VARIANTS[variant]
        )
        for k in range(per_bucket):
            scene = generate_scene(spec, first_seed + _SEED_STRIDE * b + k)
            layouts = {f.id: estimate_layout(f.points, params) for f in scene.fragments}
            result = place_site(layouts, params).model_dump(mode="json")
            truth = ground_truth_json(scene)
            right = evaluate_result(result, truth).global_correct
            records.append(
                {
                    "bucket": f"{lo}-{hi}",
                    "status": result["status"],
                    "right": right,
                    # The main room's confidence and verdict (None: the loop did not close).
                    "main": main_room_verdict(result, right),
                }
            )
    return records


def _row(variant: str, bucket: str, records: list[dict[str, Any]]) -> str:
    right = np.array([r["right"] for r in records], dtype=bool)
    statuses = [r["status"] for r in records]
    closed = np.array([s == "closed" for s in statuses])
    conf = np.array([r["main"][0] if r["main"] else 0.0 for r in records])
    return (
        f"| {variant} | {bucket} | {len(records)} | {100 * right.mean():.1f} | "
        f"{int(closed.sum())} ({int(right[closed].sum())}) | {statuses.count('ambiguous')} | "
        f"{statuses.count('open')} | {float(np.mean((conf - right) ** 2)):.3f} |"
    )


def main(argv: list[str] | None = None) -> int:
    """Print the table (or, with ``--fit``, the thin clouds' map); returns the exit code."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-bucket", type=int, default=25)
    parser.add_argument("--seed", type=int, default=7000, help="first seed")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--fit", action="store_true", help="fit thin_cloud_calibration")
    args = parser.parse_args(argv)
    params = PipelineParams()
    if args.fit:
        off = params.placement.model_copy(update={"thin_cloud_calibration": (0.0, 1.0)})
        unmapped = params.model_copy(update={"placement": off})
        mains = [
            r["main"]
            for variant in ("sparse", "vsparse")
            for r in run(variant, args.per_bucket, args.seed, unmapped)
            if r["main"] is not None
        ]
        coefficients, summary = fit_logit_map(
            [confidence for confidence, _ in mains],
            [right for _, right in mains],
            params.placement.closed_confidence,
        )
        print(f"thin_cloud_calibration = {coefficients}: {summary}")
        return 0
    print(
        "| scanner | fragments | scenes | ACC_global % | said closed (right) | ambiguous | "
        "open | Brier |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for variant in args.variants:
        records = run(variant, args.per_bucket, args.seed)
        for lo, hi in BUCKETS:
            bucket = f"{lo}-{hi}"
            print(_row(variant, bucket, [r for r in records if r["bucket"] == bucket]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
