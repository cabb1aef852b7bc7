"""RGB-D frames: ACC_local, ACC_global, pose errors, and the time per frame to local layout.

Scenes are rendered by :mod:`services.synthetic.render` (ray casting; Kinect-like depth noise;
doors and windows seen through; furniture), a few stations per room, frames looking around
with little or no overlap. Each scene's frames go the way ``jigsaw align`` takes them
(:func:`services.pipeline.align_fragments`): frames that overlap are merged (ORB matches
verified on the depths), then the local layout of each frame or merged group, then the
global placement; scored by :func:`services.evaluation.evaluate_result` with the paper's
thresholds (5 % of the fragment's / room's diagonal). A merged group's frames all carry
the group's chain, so each is judged against the stretch of wall the group saw
(:func:`merged_truth`), not its own. Time per frame is that of each local
layout (a merged group's counts once), wall clock and process CPU time (all threads; robust
to a busy machine).

    .venv/bin/python bench/rgbd_frames.py [--scenes 20] [--seed 1000] [--shapes] [--camera wide]
    .venv/bin/python bench/rgbd_frames.py --fit --scenes 100 --seed 2000 --shapes
        --camera kinect --camera realsense --camera wide   (one line)
    .venv/bin/python bench/rgbd_frames.py --anatomy [--scenes 100] [--shapes]

``--camera`` renders with another depth camera of ``services.synthetic.render.CAMERAS``:
``kinect`` (the default, 63 degrees across), ``realsense`` (79), ``wide`` (119); repeated, each
in turn (``--fit`` pools them and also fits the map's change with the view angle,
``frame_view_slope``).

``--overlap M`` lets neighbouring frames' stretches of wall overlap by up to M meters (the
generator's default: 0.3), as a robot turning on the spot takes them; ``--gap M`` leaves up to
M meters of wall unseen between them (the generator's: 0.2), corners included, as views that
stop short of the far walls do.

``--pitch LOW HIGH`` and ``--roll DEG`` hold the cameras otherwise than the generator does
(5-20 degrees down, 3 of roll), e.g. ``--pitch -45 -30`` for views over a desk or floor
(the table, and ``--fit-view-top``, which fits ``frame_view_top_slope`` on such rooms:
use tune seeds).

``--shapes`` also runs rooms of real shapes (the MatterportLayout outlines of
``../shared/data``: the test split's for held-out seeds, the tune split's for tune seeds)
when present.

``--fit`` fits the frames' map of the confidence's logit (``frame_calibration``,
:mod:`services.confidence`) instead: the scenes run with the map off, then a logistic
regression of each main room's right/wrong on its logit (:func:`bench.scoring.main_room_verdict`);
use tune seeds (2000 and up: 1000-1999 are held out) and, with ``--shapes``, the shapes'
tune split. The two runs share the machine's two cores. It prints the map and what it does
to those rooms at the closing threshold.

``--fit-stations`` fits ``frame_station_slope`` instead (the logit's change per station
beyond two that a main room's cameras stand at), on the generator's rooms and, with
``--overlap`` or ``--gap``, also on rooms held that way; use tune seeds.

``--anatomy`` tells what limits the frames instead: each frame laid out on its own (no
merging), every scene's placement is classed by :func:`bench.tune_placement.limit_of`:
ranked first, energy (a right room found but ranked lower), search, or chains (no right room
can be built from these chains).
"""

from __future__ import annotations

import argparse
import functools
import math
import statistics
import sys
import time
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script, the repository's packages are importable

from bench.scoring import (  # noqa: E402
    add_params_option,
    fit_logit_map,
    fit_logit_shift,
    main_room_verdict,
    params_with,
)
from bench.tune_placement import LIMITS, limit_of, scene_candidates  # noqa: E402
from bench.world_scenes import BUCKETS, CachedScene, bucket_of  # noqa: E402
from schemas.params import PipelineParams  # noqa: E402
from services.confidence import (  # noqa: E402
    FITTED_STATIONS,
    view_beyond_kinect,
    view_top_below_fitted,
)
from services.evaluation import evaluate_result  # noqa: E402
from services.fragments import fragment_layout  # noqa: E402
from services.pipeline import align_fragments  # noqa: E402
from services.stations import station_count  # noqa: E402
from services.synthetic.render import (  # noqa: E402
    CAMERAS,
    FrameScene,
    FrameSpec,
    frame_ground_truth_json,
    generate_frame_scene,
)
from services.synthetic.room import Room  # noqa: E402
from services.synthetic.scan import Stretch, stretch_keypoints  # noqa: E402
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


def merged_truth(truth: Mapping[str, Any], result: Mapping[str, Any]) -> dict[str, Any]:
    """The frames' truth (:func:`~services.synthetic.render.frame_ground_truth_json`) with
    the frames of every merged group of ``result`` (``merged_into``) given the group's: the
    stretch of wall from the first of their stretches along the loop to the last (merged
    frames overlap), seen from each frame, and the largest of their diagonals and the
    stretch's. Unmerged frames keep their own."""
    groups: dict[str, list[str]] = {}
    for entry in result["fragments"]:
        anchor = entry.get("merged_into")
        if anchor is not None:
            groups.setdefault(anchor, [anchor]).append(entry["id"])
    fragments = {f["id"]: dict(f) for f in truth["fragments"]}
    room = Room.from_polygon(
        np.asarray(truth["room"]["polygon"], dtype=np.float64), truth["room"]["ceiling_z"]
    )
    perimeter = float(room.arcs[-1])
    for members in groups.values():
        arcs = [(fragments[m]["loop_start"], fragments[m]["loop_end"]) for m in members]
        lengths = [float(np.mod(end - start, perimeter)) for start, end in arcs]
        # The union starts at the one start no other stretch holds (the first along the loop).
        first = min(
            range(len(arcs)),
            key=lambda i: sum(
                0.0 < np.mod(arcs[i][0] - start, perimeter) < length
                for (start, _), length in zip(arcs, lengths, strict=True)
            ),
        )
        start = arcs[first][0]
        length = max(
            float(np.mod(other - start, perimeter)) + span
            for (other, _), span in zip(arcs, lengths, strict=True)
        )
        world = stretch_keypoints(room, Stretch(start, min(length, perimeter)))
        spread = float(np.linalg.norm(np.ptp(world, axis=0)))
        diagonal = max([spread] + [float(fragments[m]["diagonal"]) for m in members])
        on_floor = np.column_stack([world, np.zeros(len(world))])
        for m in members:
            pose = np.asarray(fragments[m]["pose"], dtype=np.float64)
            local = (on_floor - pose[:3, 3]) @ pose[:3, :3]
            fragments[m].update(
                keypoints_world=world.tolist(), keypoints_local=local.tolist(), diagonal=diagonal
            )
    return {**truth, "fragments": [fragments[f["id"]] for f in truth["fragments"]]}


def _scenes(
    n_scenes: int,
    first_seed: int,
    outlines: list[FloatArray] | None,
    camera: str = "kinect",
    stance: Mapping[str, Any] | None = None,
) -> Iterator[FrameScene | None]:
    """The frame scenes of seeds ``first_seed`` on (rooms of ``outlines`` in turn, if any),
    seen by one of ``CAMERAS`` held as ``stance`` says (``FrameSpec`` fields such as
    ``pitch_deg``, ``roll_deg``; the generator's otherwise); None for a room no station
    tiles within the camera's range."""
    spec = FrameSpec(intrinsics=CAMERAS[camera], **(stance or {}))
    for k in range(n_scenes):
        outline = outlines[k % len(outlines)] if outlines else None
        try:
            yield generate_frame_scene(spec, first_seed + k, outline)
        except RuntimeError:
            yield None


def run(
    n_scenes: int,
    first_seed: int,
    outlines: list[FloatArray] | None = None,
    params: PipelineParams = PipelineParams(),
    camera: str = "kinect",
    stance: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Local and global figures over ``n_scenes`` frame scenes from ``first_seed``, seen by
    ``CAMERAS[camera]`` (held as ``stance`` says, :func:`_scenes`); ``"confidences"``,
    ``"right"``, ``"views"``, ``"tops"`` and ``"stations"`` list each main room's confidence,
    verdict, its frames' view beyond the kinect's
    (:func:`services.confidence.view_beyond_kinect`), their view's top below the fitted
    (:func:`~services.confidence.view_top_below_fitted`), radians, and the stations its
    cameras stand at beyond ``FITTED_STATIONS`` (:func:`result_stations`); ``"buckets"`` maps a
    frame-count bucket ("4-5") to its rooms' ``[right, said closed, closed and right, rooms]``."""
    local, global_ok, rotation, translation, frames, statuses = [], [], [], [], [], []
    confidences: list[float] = []
    right: list[bool] = []
    views: list[float] = []
    tops: list[float] = []
    stations: list[float] = []
    clock = LayoutClock()
    buckets: dict[str, list[int]] = {}
    skipped = 0
    for scene in _scenes(n_scenes, first_seed, outlines, camera, stance):
        if scene is None:
            skipped += 1
            continue
        aligned = align_fragments({f.id: f.frame for f in scene.frames}, params, clock)
        result = aligned.result.model_dump(mode="json")
        truth = merged_truth(frame_ground_truth_json(scene), result)
        report = evaluate_result(result, truth)
        verdict = main_room_verdict(result, report.global_correct)
        if verdict is not None:
            confidences.append(verdict[0])
            right.append(verdict[1])
            laid_out = [v for v in aligned.layouts.values() if v.ok]
            views.append(view_beyond_kinect([v.view_angle for v in laid_out if v.view_angle]))
            tops.append(
                view_top_below_fitted([v.view_top for v in laid_out if v.view_top is not None])
            )
            reach = params.placement.station_reach
            stations.append(max(0, result_stations(result, reach) - FITTED_STATIONS))
        local += list(report.local_correct.values())
        global_ok.append(report.global_correct)
        statuses.append(result["status"])
        frames.append(len(scene.frames))
        closed = result["status"] == "closed"
        verdicts = (report.global_correct, closed, closed and report.global_correct, True)
        bucket = bucket_of(len(scene.frames))
        counts = buckets.get(bucket, [0, 0, 0, 0])
        buckets[bucket] = [c + int(v) for c, v in zip(counts, verdicts, strict=True)]
        rotation += [e.rotation_deg for e in report.pose_errors.values()]
        translation += [e.translation_pct for e in report.pose_errors.values()]
    ms, ms_p90 = _median_ms(clock.seconds)
    cpu_ms, cpu_ms_p90 = _median_ms(clock.cpu)
    return {
        "scenes": len(global_ok),
        "skipped": skipped,
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
        "confidences": confidences,
        "right": right,
        "views": views,
        "tops": tops,
        "stations": stations,
        "buckets": buckets,
    }


def _median_ms(values: list[float]) -> tuple[float, float]:
    """Median and 90th percentile of ``values`` (seconds), in milliseconds."""
    if not values:
        return math.nan, math.nan
    return 1000 * statistics.median(values), 1000 * float(np.percentile(values, 90))


def result_stations(result: Mapping[str, Any], reach: float) -> int:
    """How many stations a result's placed frames stand at
    (:func:`services.stations.station_count`): a frame's camera is its local origin, so it
    stands where its pose's translation says."""
    cameras = [
        np.asarray(f["pose"], dtype=np.float64)[None, :2, 3]
        for f in result.get("fragments", [])
        if f.get("pose") is not None
    ]
    return station_count(cameras, reach)


def _row(name: str, r: dict[str, Any]) -> str:
    scenes = f"{r['scenes']}" + (f" ({r['skipped']} not rendered)" if r["skipped"] else "")
    return (
        f"| {name} | {scenes} | {r['frames']} | {100 * r['acc_local']:.1f} | "
        f"{100 * r['acc_global']:.1f} | {r['rotation_deg']:.2f} | {r['translation_pct']:.2f} | "
        f"{r['closed']} ({r['closed_right']}) | {r['ambiguous']} | "
        f"{r['ms_per_frame']:.0f} ({r['ms_per_frame_p90']:.0f}) | "
        f"{r['cpu_ms_per_frame']:.0f} ({r['cpu_ms_per_frame_p90']:.0f}) | {_calibration(r)} |"
    )


def bucket_row(name: str, r: dict[str, Any]) -> str:
    """One table row of ACC_global per frame-count bucket: "right of rooms (%), closed
    (right)" in each, "-" where no room has that many frames."""
    cells = []
    for lo, hi in BUCKETS:
        right, closed, closed_right, rooms = r["buckets"].get(f"{lo}-{hi}", (0, 0, 0, 0))
        cells.append(
            f"{right}/{rooms} ({100 * right / rooms:.0f} %), {closed} ({closed_right})"
            if rooms
            else "-"
        )
    return f"| {name} | " + " | ".join(cells) + " |"


def _calibration(r: dict[str, Any]) -> str:
    """Main rooms' mean confidence, share right and Brier score, e.g. "0.61 / 0.58 / 0.17"."""
    if not r["confidences"]:
        return "-"
    confidence = np.asarray(r["confidences"], dtype=np.float64)
    right = np.asarray(r["right"], dtype=np.float64)
    brier = float(np.mean((confidence - right) ** 2))
    return f"{confidence.mean():.2f} / {right.mean():.2f} / {brier:.3f}"


def main() -> None:
    """Run the benchmark (command-line options: see ``--help``) and print its table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=20)
    parser.add_argument(
        "--seed", type=int, default=1000, help="first seed (held out: 1000-1999; tune: 2000 and up)"
    )
    parser.add_argument("--shapes", action="store_true", help="also real room shapes")
    parser.add_argument("--fit", action="store_true", help="fit the frames' calibration")
    parser.add_argument(
        "--fit-view-top",
        action="store_true",
        help="fit frame_view_top_slope on rooms seen from --pitch (steeper than the generator)",
    )
    parser.add_argument(
        "--fit-stations",
        action="store_true",
        help="fit frame_station_slope (with --overlap or --gap: also on rooms held that way)",
    )
    parser.add_argument("--anatomy", action="store_true", help="what limits each scene")
    parser.add_argument(
        "--camera",
        choices=sorted(CAMERAS),
        action="append",
        help="the depth camera rendered (repeat for several; --fit pools them; default kinect)",
    )
    parser.add_argument(
        "--pitch",
        type=float,
        nargs=2,
        metavar=("LOW", "HIGH"),
        help="the cameras' pitch range, degrees (negative: down; the generator's: -20 -5)",
    )
    parser.add_argument("--roll", type=float, help="the cameras' largest roll, degrees (3)")
    parser.add_argument(
        "--overlap",
        type=float,
        metavar="M",
        help="largest overlap of neighbouring frames' stretches of wall, m (the generator's: "
        "0.3; robots turning on the spot overlap by metres)",
    )
    parser.add_argument(
        "--gap",
        type=float,
        metavar="M",
        help="largest unseen wall between neighbouring frames' stretches, m (the generator's: "
        "0.2; a view that stops short of a corner leaves metres, corners included, unseen)",
    )
    add_params_option(parser)
    args = parser.parse_args()
    params = params_with(args.set)
    cameras = args.camera or ["kinect"]
    stance = _stance(args)
    if stance and (args.fit or args.anatomy):
        parser.error(
            "--pitch, --roll, --overlap and --gap apply to the table, --fit-view-top and "
            "--fit-stations only"
        )
    if args.fit_stations:
        _fit_stations(args.scenes, args.seed, args.shapes, params, cameras, stance)
        return
    if args.fit_view_top:
        if not args.pitch:
            parser.error("--fit-view-top needs --pitch (views steeper than the fitted)")
        _fit_view_top(args.scenes, args.seed, params, cameras, stance)
        return
    if args.fit:
        _fit(args.scenes, args.seed, args.shapes, params, cameras)
        return
    for camera in cameras:
        if args.anatomy:
            _anatomy(args.scenes, args.seed, args.shapes, params, camera)
        else:
            _table(args.scenes, args.seed, args.shapes, params, camera, stance)


def _stance(args: argparse.Namespace) -> dict[str, Any]:
    """The ``FrameSpec`` fields the options hold the cameras by (none: the generator's)."""
    stance: dict[str, Any] = {}
    if args.pitch:
        stance["pitch_deg"] = tuple(args.pitch)
    if args.roll is not None:
        stance["roll_deg"] = args.roll
    low, high = FrameSpec().gap_range
    if args.overlap is not None:
        low = -args.overlap
    if args.gap is not None:
        high = args.gap
    if args.overlap is not None or args.gap is not None:
        stance["gap_range"] = (low, high)
    return stance


def _table(
    n_scenes: int,
    first_seed: int,
    shapes: bool,
    params: PipelineParams,
    name: str,
    stance: Mapping[str, Any] | None = None,
) -> None:
    """Print the figures of the frames of one camera, synthetic (and real shapes), held as
    ``stance`` says (:func:`_scenes`)."""
    camera = CAMERAS[name]
    across = math.degrees(2 * math.atan(camera.width / (2 * camera.fx)))
    held = f", held {dict(stance)}" if stance else ""
    print(f"camera: {name}, {camera.width}x{camera.height}, {across:.0f} degrees across{held}")
    print(
        "| rooms | scenes | frames | ACC_local % | ACC_global % | rotation deg | "
        "translation % | said closed (right) | ambiguous | ms/frame median (p90) | "
        "CPU ms/frame median (p90) | main rooms: mean confidence / right / Brier |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    figures = {"synthetic": run(n_scenes, first_seed, None, params, name, stance)}
    print(_row("synthetic", figures["synthetic"]))
    outlines = outlines_for_seeds(first_seed) if shapes else []
    if outlines:
        shaped = run(n_scenes, first_seed, outlines, params, name, stance)
        figures["MatterportLayout shapes"] = shaped
        print(_row("MatterportLayout shapes", shaped))
    print("paper (RGB-D and clouds): ACC_global 85.1 %, rotation 8.79 deg, translation 9.15 %")
    print("\nACC_global by frames per room: right of rooms (%), said closed (right)")
    print("| rooms | " + " | ".join(f"{lo}-{hi} frames" for lo, hi in BUCKETS) + " |")
    print("|---|" + "---|" * len(BUCKETS))
    for room_set, r in figures.items():
        print(bucket_row(room_set, r))


def frame_outlines(split: str) -> list[FloatArray]:
    """Real room outlines of one split (``"tune"`` or ``"test"``) that a few stations see
    within the camera's range; none when the data file is missing."""
    from bench.room_shapes import DEFAULT_PATH, load_room_shapes, split_houses

    if not DEFAULT_PATH.exists():
        return []
    shapes = load_room_shapes(DEFAULT_PATH)
    tune, test = split_houses(house for house, _ in shapes)
    chosen = tune if split == "tune" else test
    return [p for h, p in shapes if h in chosen and float(np.ptp(p, axis=0).max()) <= 9.0]


def outlines_for_seeds(first_seed: int) -> list[FloatArray]:
    """The real room outlines scenes of seeds ``first_seed`` on are drawn from: tune seeds
    (2000 and up) draw the shapes' tune split, held-out seeds its test split."""
    return frame_outlines("tune" if first_seed >= 2000 else "test")


Result = TypeVar("Result")


def side_by_side(
    measure: Callable[[int, int, list[FloatArray] | None, PipelineParams, str], Result],
    n_scenes: int,
    first_seed: int,
    outlines: list[FloatArray],
    params: PipelineParams,
    camera: str = "kinect",
) -> dict[str, Result]:
    """``measure`` of the synthetic rooms and, when there are ``outlines``, of the real
    shapes, seen by ``CAMERAS[camera]``, in two processes (the machine's two cores)."""
    with ProcessPoolExecutor(2) as pool:
        jobs = {"synthetic": pool.submit(measure, n_scenes, first_seed, None, params, camera)}
        if outlines:
            jobs["MatterportLayout shapes"] = pool.submit(
                measure, n_scenes, first_seed, outlines, params, camera
            )
        return {name: job.result() for name, job in jobs.items()}


def _fit(
    n_scenes: int, first_seed: int, shapes: bool, params: PipelineParams, cameras: list[str]
) -> None:
    """Fit and print the frames' calibration on synthetic (and tune-split shaped) rooms seen
    by each of ``cameras``; with more than one, also the map's change per radian of view."""
    placement = params.placement.model_copy(
        update={"frame_calibration": (0, 1), "frame_view_slope": 0.0}
    )
    off = params.model_copy(update={"placement": placement})
    outlines = frame_outlines("tune") if shapes else []
    confidences: list[float] = []
    right: list[bool] = []
    views: list[float] = []
    for camera in cameras:
        for r in side_by_side(run, n_scenes, first_seed, outlines, off, camera).values():
            confidences += r["confidences"]
            right += r["right"]
            views += r["views"]
    wider = views if len(cameras) > 1 else None
    coefficients, summary = fit_logit_map(
        confidences, right, params.placement.closed_confidence, wider
    )
    print(f"frame_calibration = {coefficients[:2]}", end="")
    if len(coefficients) > 2:
        print(f", frame_view_slope = {coefficients[2]}", end="")
    print(f": {summary}")


def _fit_view_top(
    n_scenes: int,
    first_seed: int,
    params: PipelineParams,
    cameras: list[str],
    stance: Mapping[str, Any],
) -> None:
    """Fit and print ``frame_view_top_slope`` on synthetic rooms seen by each of
    ``cameras`` held as ``stance``, with the rest of the frames' map as it is."""
    placement = params.placement.model_copy(update={"frame_view_top_slope": 0.0})
    off = params.model_copy(update={"placement": placement})
    confidences: list[float] = []
    right: list[bool] = []
    tops: list[float] = []
    for camera in cameras:
        r = run(n_scenes, first_seed, None, off, camera, stance)
        confidences += r["confidences"]
        right += r["right"]
        tops += r["tops"]
    slope, summary = fit_logit_shift(confidences, right, tops)
    print(f"frame_view_top_slope = {slope:.3f}: {summary}")


def _fit_stations(
    n_scenes: int,
    first_seed: int,
    shapes: bool,
    params: PipelineParams,
    cameras: list[str],
    stance: Mapping[str, Any],
) -> None:
    """Fit and print ``frame_station_slope`` on synthetic (and tune-split shaped) rooms seen
    by each of ``cameras`` as the generator holds them and, when ``stance`` says otherwise
    (a larger overlap or gap), so too, with the rest of the frames' map as it is."""
    placement = params.placement.model_copy(update={"frame_station_slope": 0.0})
    off = params.model_copy(update={"placement": placement})
    outlines = frame_outlines("tune") if shapes else []
    confidences: list[float] = []
    right: list[bool] = []
    beyond: list[float] = []
    for held in [{}, stance] if stance else [{}]:
        for camera in cameras:
            measure = functools.partial(run, stance=held)
            for r in side_by_side(measure, n_scenes, first_seed, outlines, off, camera).values():
                confidences += r["confidences"]
                right += r["right"]
                beyond += r["stations"]
    slope, summary = fit_logit_shift(confidences, right, beyond)
    print(f"frame_station_slope = {slope:.3f}: {summary}")


def cached_scenes(
    n_scenes: int,
    first_seed: int,
    outlines: list[FloatArray] | None = None,
    params: PipelineParams = PipelineParams(),
    camera: str = "kinect",
) -> list[CachedScene]:
    """The frame scenes of seeds ``first_seed`` on, seen by ``CAMERAS[camera]``, each frame
    laid out on its own (no merging), with their truth; rooms no station tiles are left
    out."""
    out = []
    for scene in _scenes(n_scenes, first_seed, outlines, camera):
        if scene is not None:
            layouts = {f.id: fragment_layout(f.frame, params) for f in scene.frames}
            truth = frame_ground_truth_json(scene)
            out.append(CachedScene(f"frames-{scene.seed}", truth, layouts, 0.0))
    return out


def limits(
    n_scenes: int,
    first_seed: int,
    outlines: list[FloatArray] | None = None,
    params: PipelineParams = PipelineParams(),
    camera: str = "kinect",
) -> dict[int, str]:
    """Seed -> what limits that frame scene (:func:`bench.tune_placement.limit_of`), seen by
    ``CAMERAS[camera]``; rooms no station tiles are left out."""
    return {
        scene.seed: limit_of(scene_candidates(scene, params.placement))
        for scene in cached_scenes(n_scenes, first_seed, outlines, params, camera)
    }


def _anatomy(
    n_scenes: int, first_seed: int, shapes: bool, params: PipelineParams, camera: str
) -> None:
    """Print how many scenes each limit decides, synthetic (and real shapes)."""
    outlines = outlines_for_seeds(first_seed) if shapes else []
    runs = side_by_side(limits, n_scenes, first_seed, outlines, params, camera)
    print("| rooms | scenes | " + " | ".join(LIMITS) + " |")
    print("|---|---|" + "---|" * len(LIMITS))
    for name, found in runs.items():
        counts = [list(found.values()).count(limit) for limit in LIMITS]
        print(f"| {name} | {len(found)} | " + " | ".join(str(c) for c in counts) + " |")


if __name__ == "__main__":
    main()
