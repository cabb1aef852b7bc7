"""Fit the placement energy's weights and the confidence's calibration (issue 10).

On the "tune" split of ``bench/world_scenes.py`` (never the "test" split the benchmark
reports), every scene is placed with the current parameters; each assembly the search
returns is scored against the truth (right when its refined floorplan passes the paper's
5 % test), and the true assembly's own features are added when the search missed it.

1. Weights: a conditional logit. The energy w . f of the assemblies of a scene, as a
   Boltzmann distribution, should give the right ones a high probability: maximise the
   summed log of that probability over scenes (w >= 0, a small ridge on log w).
2. Calibration: on what the search really returns (without the added truth), a
   temperature and the 'none of these' energy u0 + u1 * pieces, by maximum likelihood.
3. The threshold for "closed": the lowest confidence at which, on this split, at least
   99 % of the results said closed are right in every bucket.

Prints the fitted values as ``PlacementParams`` fields; copy them into
``schemas/params.py``. Run ``python -m bench.tune_placement`` (``--rounds 2`` refits with the
first round's weights, as the search's candidates depend on them). ``--frames N`` fits the
weights of RGB-D frame sites instead (``frame_weights``) on N rendered synthetic rooms and N
rooms of the tune split's shapes (tune seeds from 2000), each frame laid out alone, seen by
the kinect or, pooled, by each ``--camera`` given.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.console import Console
from scipy.optimize import minimize
from scipy.special import logsumexp

from bench.scoring import candidate_result, fit_logistic, true_assembly
from bench.world_scenes import (
    BUCKETS,
    DEFAULT_CACHE,
    CachedScene,
    build_sets,
    load_set,
    scene_jobs,
)
from schemas.params import PipelineParams, PlacementParams
from services.confidence import CALIBRATION_FEATURES, calibration_features, same_room_groups
from services.evaluation import evaluate_result
from services.placement import PlacementCandidate, evaluate_placement, make_piece, place_pieces
from services.placement.energy import FEATURES, feature_weights
from services.synthetic.render import CAMERAS

__all__ = [
    "LIMITS",
    "SceneCandidates",
    "collect",
    "fit_calibration",
    "fit_weights",
    "limit_of",
    "main",
    "scene_candidates",
]

FITTED = FEATURES[:-1]  # the hints' prior is already a negative log-likelihood
_WEIGHT_FIELDS = (
    "weight_turn", "weight_hull", "weight_closure",
    "weight_structure", "weight_boundary", "weight_conflict", "weight_outside",
)  # fmt: skip
assert len(_WEIGHT_FIELDS) == len(FITTED), "one weight field per fitted feature"
_TARGET_RIGHT = 0.99
_FRAME_SEED = 2000  # frame scenes: tune seeds (1000-1999 are held out)


@dataclass(frozen=True)
class SceneCandidates:
    """The assemblies found for one scene, lowest energy first: (K, F) features, (K,) right
    or not, (K,) same-room group; whether the search finished; and the true assembly's
    features when the search did not return it (None otherwise)."""

    n: int
    features: np.ndarray
    right: np.ndarray
    groups: np.ndarray
    truncated: bool
    missed_truth: np.ndarray | None
    missed_truth_right: bool


LIMITS = ("ranked first", "energy", "search", "chains")


def limit_of(scene: SceneCandidates) -> str:
    """What decides a scene, from its assemblies: ``"ranked first"`` (the lowest energy is
    right), ``"energy"`` (a right one was found but ranked lower), ``"search"`` (the true
    assembly is right but was not found), ``"chains"`` (no right assembly exists with these
    chains: the true one fails the 5 % test or does not close, or a chain is missing).

    >>> import numpy as np
    >>> none = np.zeros((0, 1))
    >>> limit_of(SceneCandidates(3, none, np.array([False, True]), none, False, None, False))
    'energy'
    """
    if len(scene.right) and scene.right[0]:
        return "ranked first"
    if scene.right.any():
        return "energy"
    return "search" if scene.missed_truth_right else "chains"


def scene_candidates(scene: CachedScene, params: PlacementParams) -> SceneCandidates:
    """Place one scene; score each closed assembly found and, when the search missed it,
    the true one."""
    ids = [fid for fid, lay in scene.layouts.items() if lay.ok]
    pieces = [make_piece(fid, scene.layouts[fid]) for fid in ids]
    placement = place_pieces(pieces, params) if len(pieces) >= 2 else None
    closed = [] if placement is None or not placement.closed else list(placement.candidates)
    closed = sorted((c for c in closed if c.missing == 0), key=lambda c: c.energy)
    features = np.array([[c.features[f] for f in FITTED] for c in closed]).reshape(-1, len(FITTED))
    right = np.array(
        [
            evaluate_result(candidate_result(c, pieces, scene.layouts), scene.truth).global_correct
            for c in closed
        ],
        dtype=bool,
    )
    groups = np.array(same_room_groups(pieces, closed, params.same_room_share)[0], dtype=int)
    missed, missed_right = None, False
    if len(ids) == scene.n_fragments and len(ids) >= 2:
        order, rotations = true_assembly(scene.truth, scene.layouts, ids)
        truth = evaluate_placement(pieces, order, rotations, params)
        found = any(c.order == tuple(order) and c.rotations == tuple(rotations) for c in closed)
        if truth is not None and not found:
            missed = np.array([truth.features[f] for f in FITTED])
            result = candidate_result(truth, pieces, scene.layouts)
            missed_right = evaluate_result(result, scene.truth).global_correct
    truncated = placement is not None and not placement.exhaustive
    return SceneCandidates(
        scene.n_fragments, features, right, groups, truncated, missed, missed_right
    )


def collect(
    scenes: list[CachedScene], params: PlacementParams, workers: int = 1
) -> list[SceneCandidates]:
    """Place every scene and score each assembly the search returns (``workers``
    processes)."""
    if workers <= 1:
        return [scene_candidates(scene, params) for scene in scenes]
    with ProcessPoolExecutor(workers) as pool:
        return list(pool.map(scene_candidates, scenes, [params] * len(scenes), chunksize=4))


def save_candidates(data: list[SceneCandidates], path: Path) -> None:
    """Write collected assemblies as JSON (a refit then needs no search)."""
    rows = []
    for scene in data:
        row = dataclasses.asdict(scene)
        for key, value in row.items():
            if isinstance(value, np.ndarray):
                row[key] = value.tolist()
        rows.append(row)
    path.write_text(json.dumps({"features": list(FITTED), "scenes": rows}))


def load_candidates(path: Path) -> list[SceneCandidates]:
    """Assemblies written by :func:`save_candidates` (with the same features)."""
    record = json.loads(path.read_text())
    if record["features"] != list(FITTED):
        raise ValueError(f"{path}: features {record['features']}, want {list(FITTED)}")
    out = []
    for row in record["scenes"]:
        missed = row["missed_truth"]
        out.append(
            SceneCandidates(
                row["n"],
                np.asarray(row["features"], dtype=np.float64).reshape(-1, len(FITTED)),
                np.asarray(row["right"], dtype=bool),
                np.asarray(row["groups"], dtype=int),
                row["truncated"],
                None if missed is None else np.asarray(missed, dtype=np.float64),
                row["missed_truth_right"],
            )
        )
    return out


def _pool(a: SceneCandidates, b: SceneCandidates) -> SceneCandidates:
    """One scene's assemblies of two rounds together (for fitting the weights only)."""
    return SceneCandidates(
        a.n,
        np.vstack([a.features, b.features]),
        np.concatenate([a.right, b.right]),
        np.concatenate([a.groups, b.groups + (a.groups.max() + 1 if len(a.groups) else 0)]),
        a.truncated,
        a.missed_truth if a.missed_truth is not None else b.missed_truth,
        a.missed_truth_right or b.missed_truth_right,
    )


def _pooled(earlier: list[SceneCandidates], data: list[SceneCandidates]) -> list[SceneCandidates]:
    """A round's assemblies (``data``) joined to the earlier rounds' (the first round's alone)."""
    return data if not earlier else [_pool(a, b) for a, b in zip(earlier, data, strict=True)]


def fit_weights(data: list[SceneCandidates], ridge: float = 0.01) -> np.ndarray:
    """Weights (len(FITTED),) >= 0 maximising the probability of the right assemblies."""
    sets = []
    for scene in data:
        features, right = scene.features, scene.right
        if scene.missed_truth is not None:
            features = np.vstack([features, scene.missed_truth])
            right = np.append(right, scene.missed_truth_right)
        if right.any() and not right.all():
            sets.append((features, right))

    def loss(log_w: np.ndarray) -> tuple[float, np.ndarray]:
        w = np.exp(log_w)
        total, grad = 0.0, np.zeros(len(w))
        for features, right in sets:
            log_p = -features @ w - logsumexp(-features @ w)
            log_right = logsumexp(log_p[right])
            total -= log_right
            share = np.exp(log_p[right] - log_right)
            grad += share @ features[right] - np.exp(log_p) @ features
        total += ridge * float(log_w @ log_w)
        return total, grad * w + 2 * ridge * log_w

    bounds = [(-6.0, 3.0)] * len(FITTED)
    solution = minimize(loss, np.zeros(len(FITTED)), jac=True, method="L-BFGS-B", bounds=bounds)
    return np.asarray(np.exp(solution.x))


def fit_calibration(
    data: list[SceneCandidates], w: np.ndarray, temperature: float | None = None
) -> tuple[float, float, float]:
    """(temperature, u0, u1): energies / temperature, 'none of these' at u0 + u1 * pieces;
    a given temperature is kept."""
    sets = [(s.features @ w, s.right, s.n) for s in data if len(s.right)]

    def loss(x: np.ndarray) -> float:
        t = _temperature(x[0]) if temperature is None else temperature
        u0, u1 = x[1], x[2]
        total = 0.0
        for energies, right, n in sets:
            scaled = (energies - energies.min()) / t
            logits = np.append(-scaled, -(u0 + u1 * n))
            norm = logsumexp(logits)
            total -= (logsumexp(-scaled[right]) if right.any() else logits[-1]) - norm
        return total

    solution = minimize(loss, np.array([0.0, 3.0, 0.0]), method="Nelder-Mead")
    fitted = _temperature(solution.x[0]) if temperature is None else temperature
    return fitted, float(solution.x[1]), float(solution.x[2])


def _temperature(log_temperature: float) -> float:
    """The temperature of a log-temperature, within exp(+-6): fits on a handful of rooms
    otherwise wander off to a temperature of 0 or infinity (fits find about 1)."""
    return float(np.exp(np.clip(log_temperature, -6.0, 6.0)))


def main_rooms(
    data: list[SceneCandidates], w: np.ndarray, calibration: tuple[float, float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """Per scene with a closed loop: (calibration inputs of its main room, main room right).

    The main room is the same-room group of largest Boltzmann share, as in
    :func:`services.confidence.rank_assemblies`."""
    temperature, u0, u1 = calibration
    inputs, right = [], []
    for scene in data:
        if not len(scene.right):
            continue
        energies = scene.features @ w / temperature
        weights = np.exp(-(energies - energies.min()))
        mass = np.bincount(scene.groups, weights=weights)
        shares = mass / (weights.sum() + np.exp(-(u0 + u1 * scene.n)))
        main = int(np.argmax(shares))
        first = int(np.flatnonzero(scene.groups == main)[np.argmin(energies[scene.groups == main])])
        best = dict(zip(FITTED, scene.features[first].tolist(), strict=True))
        candidate = PlacementCandidate(0.0, (), (), best)
        inputs.append(
            calibration_features(float(shares[main]), candidate, scene.n, scene.truncated)
        )
        right.append(bool(scene.right[first]))
    return np.array(inputs), np.array(right)


def cross_validated(inputs: np.ndarray, right: np.ndarray, folds: int = 5) -> np.ndarray:
    """Out-of-fold calibrated confidences (honest figures for the tune split itself)."""
    out = np.zeros(len(right))
    fold = np.arange(len(right)) % folds
    for k in range(folds):
        coefficients = fit_logistic(inputs[fold != k], right[fold != k])
        out[fold == k] = 1.0 / (1.0 + np.exp(-(inputs[fold == k] @ coefficients)))
    return out


def closed_threshold(counts: np.ndarray, conf: np.ndarray, right: np.ndarray) -> float:
    """Lowest threshold with >= 99 % right among results at or above it, in every bucket."""
    for threshold in np.arange(0.50, 0.995, 0.01):
        ok = True
        for lo, hi in BUCKETS:
            chosen = (conf >= threshold) & (counts >= lo) & (counts <= hi)
            if chosen.any() and right[chosen].mean() < _TARGET_RIGHT:
                ok = False
        if ok:
            return float(round(threshold, 2))
    return 0.99


def main(argv: list[str] | None = None) -> int:
    """Fit the energy's weights and the confidence on the tune split; returns the exit code."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--per-bucket", type=int, default=24)
    parser.add_argument("--real", type=int, default=48)
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--workers", type=int, default=2, help="processes placing scenes")
    parser.add_argument("--save", type=Path, help="write the first round's assemblies here")
    parser.add_argument("--load", type=Path, help="fit on assemblies saved by --save")
    parser.add_argument(
        "--keep-weights",
        action="store_true",
        help="fit only the 'none of these' energy and the calibration: the energy's weights "
        "(and temperature) stay the current ones",
    )
    parser.add_argument(
        "--frames",
        type=int,
        default=0,
        help="fit placement.frame_weights instead, on this many rendered RGB-D frame scenes of "
        "tune seeds (2000 on), as many synthetic rooms as rooms of the tune split's shapes",
    )
    parser.add_argument(
        "--camera",
        action="append",
        choices=sorted(CAMERAS),
        help="with --frames: a depth camera whose rooms are pooled in the fit (repeat for "
        "several; default kinect)",
    )
    args = parser.parse_args(argv)
    console = Console()
    if args.frames:
        return _fit_frame_weights(args.frames, args.rounds, console, args.camera or ["kinect"])
    scenes: list[CachedScene] = []
    if args.load is None:
        jobs = scene_jobs("tune", args.per_bucket, args.real, args.cache)
        build_sets(jobs, 2, lambda line: console.log(f"layouts {line}"))
        scenes = list(load_set(jobs))
    params = PlacementParams()
    current = feature_weights(params)[: len(FITTED)]
    pooled: list[SceneCandidates] = []
    for round_ in range(args.rounds):
        if args.load is not None:
            data = load_candidates(args.load)
        else:
            data = collect(scenes, params, args.workers)
            if args.save is not None and round_ == 0:
                save_candidates(data, args.save)
        # Each round's assemblies join the earlier ones': the weights must tell the truth
        # from what any of the searches so far preferred.
        pooled = _pooled(pooled, data)
        w = current if args.keep_weights else fit_weights(pooled)
        calibration = fit_calibration(data, w, 1.0 if args.keep_weights else None)
        temperature, u0, u1 = calibration
        fitted = dict(zip(_WEIGHT_FIELDS, (w / temperature).round(3).tolist(), strict=True))
        fitted |= {"unexplored_energy": round(u0, 3), "unexplored_per_piece": round(u1, 3)}
        inputs, right = main_rooms(data, w, calibration)
        counts = inputs[:, CALIBRATION_FEATURES.index("pieces")]
        honest = cross_validated(inputs, right)
        coefficients = fit_logistic(inputs, right)
        fitted |= {"confidence_coefficients": tuple(coefficients.round(3).tolist())}
        fitted |= {"closed_confidence": closed_threshold(counts, honest, right)}
        console.print(f"round {round_ + 1}: {fitted}")
        console.print(
            f"  main room right {right.mean():.3f}; out-of-fold mean confidence "
            f"{honest.mean():.3f}, Brier {np.mean((honest - right) ** 2):.3f}"
        )
        params = params.model_copy(update=fitted)
    return 0


def _fit_frame_weights(n_scenes: int, rounds: int, console: Console, cameras: list[str]) -> int:
    """Fit and print ``frame_weights`` on frame scenes seen by each of ``cameras`` (synthetic
    and tune-split shapes, in two processes), pooled. Refit the frames' calibration map with
    the new weights afterwards (``bench/rgbd_frames.py --fit``): the map depends on them."""
    from bench.rgbd_frames import cached_scenes, frame_outlines, side_by_side

    pipeline = PipelineParams()
    outlines = frame_outlines("tune")
    scenes = []
    for camera in cameras:
        runs = side_by_side(cached_scenes, n_scenes, _FRAME_SEED, outlines, pipeline, camera)
        seen = [scene for found in runs.values() for scene in found]
        console.log(f"{camera}: {len(seen)} frame scenes")
        scenes += seen
    params = pipeline.placement
    pooled: list[SceneCandidates] = []
    for round_ in range(rounds):
        data = collect(scenes, params, 2)
        pooled = _pooled(pooled, data)
        ranked_first = sum(bool(len(s.right) and s.right[0]) for s in data)
        w = fit_weights(pooled)
        temperature = fit_calibration(data, w)[0]
        fitted = tuple((w / temperature).round(3).tolist())
        console.print(
            f"round {round_ + 1}: frame_weights = {fitted} ({', '.join(_WEIGHT_FIELDS)}); "
            f"right room ranked first with the weights before: {ranked_first} of {len(data)}"
        )
        params = params.model_copy(update={"frame_weights": fitted})
    return 0


if __name__ == "__main__":
    sys.exit(main())
