"""``jigsaw demo``: a synthetic scene end to end, scored against its ground truth.

Generates a paper-like scene, writes its fragments as PLY files, reads them back through the
same code as ``jigsaw align``, runs the pipeline in-process, writes the result, pictures and
the 3D model, and prints the paper's metrics per fragment and for the scene.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from time import perf_counter
from typing import Any

import numpy as np
from rich import box
from rich.console import Console
from rich.table import Table

from cli.exports import floorplan_canvas, layout_canvas, save_picture, write_model
from cli.pipeline import AlignRun, align_fragments, fragment_clouds, read_fragments
from cli.scene_io import read_truth, write_scene
from schemas.params import PipelineParams
from services.evaluation import SceneReport, acc_local, evaluate_result
from services.model_export import layout_model
from services.synthetic import SceneSpec, generate_scene
from services.types import FloatArray

__all__ = ["run_demo"]

EXIT_OK, EXIT_FAILED = 0, 1


@contextmanager
def _timed(seconds: dict[str, float], stage: str) -> Iterator[None]:
    start = perf_counter()
    yield
    seconds[stage] = perf_counter() - start


def _yes(flag: bool) -> str:
    return "[green]yes[/]" if flag else "[red]no[/]"


def _num(value: float | None, digits: int = 2) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def _write_outputs(out: Path, clouds: dict[str, FloatArray], run: AlignRun) -> list[Path]:
    """result.json, per-fragment layout pictures, floorplan pictures, glTF model."""
    written = [out / "result.json"]
    written[0].write_text(json.dumps(run.alignment.result.model_dump(mode="json"), indent=2) + "\n")
    for index, (fid, layout) in enumerate(run.alignment.layouts.items()):
        canvas = layout_canvas(clouds[fid], layout, index)
        for suffix in (".png", ".svg"):
            save_picture(canvas, out / "layouts" / f"{fid}{suffix}")
    written.append(out / "layouts")
    plan = floorplan_canvas(clouds, run.alignment.result)
    for suffix in (".png", ".svg"):
        save_picture(plan, out / f"floorplan{suffix}")
        written.append(out / f"floorplan{suffix}")
    mesh = layout_model(run.alignment.result)
    if mesh is not None and len(mesh.triangles):
        write_model(mesh, out / "model.gltf")
        written.append(out / "model.gltf")
    return written


def _fragment_table(
    result: dict[str, Any], truth: dict[str, Any], report: SceneReport, n_points: dict[str, int]
) -> Table:
    table = Table(
        title="Fragments",
        title_justify="left",
        box=box.SIMPLE_HEAD,
        caption="kp: keypoints estimated/true; local ok: keypoint error < 5 % of the fragment "
        "diagonal (ACC_local); rot/trans: pose error after aligning the site to the world "
        "(translation in % of the room diagonal)",
        caption_justify="left",
    )
    headers = ["id", "points", "kp", "kp err (m)", "local ok", "placed", "loop"]
    headers += ["rot (deg)", "trans (%)"]
    for header in headers:
        table.add_column(header, justify="left" if header == "id" else "right", no_wrap=True)
    estimated = {f["id"]: f for f in result["fragments"]}
    for true in truth["fragments"]:
        fid = true["id"]
        est = estimated.get(fid, {})
        pose_error = report.pose_errors.get(fid)
        loop = est.get("loop_index")
        table.add_row(
            fid,
            f"{n_points.get(fid, 0):,}",
            f"{len(est.get('local_layout', {}).get('keypoints', []))}"
            f"/{len(true['keypoints_local'])}",
            _num(report.local_errors.get(fid), 3),
            _yes(report.local_correct.get(fid, False)),
            _yes(bool(est.get("placed"))),
            "-" if loop is None else str(loop),
            _num(pose_error.rotation_deg if pose_error else None),
            _num(pose_error.translation_pct if pose_error else None),
        )
    return table


def _scene_table(
    result: dict[str, Any], truth: dict[str, Any], report: SceneReport, seed: int
) -> Table:
    table = Table(title="Scene", title_justify="left", show_header=False)
    table.add_column("metric")
    table.add_column("value", justify="right")
    polygon = np.asarray(truth["room"]["polygon"])
    size = polygon.max(axis=0) - polygon.min(axis=0)
    errors = report.layout_error_pct or (math.nan, math.nan)
    rows = [
        ("seed", str(seed)),
        ("room", f"{size[0]:.1f} x {size[1]:.1f} m, {len(polygon)} corners"),
        ("fragments", str(len(truth["fragments"]))),
        ("status", str(result["status"])),
        ("ACC_local", f"{100 * acc_local(list(report.local_correct.values())):.0f} %"),
        ("ACC_global (placement correct)", _yes(report.global_correct)),
        ("layout error mean / max (% diag)", f"{_num(errors[0])} / {_num(errors[1])}"),
        ("room IoU", _num(report.iou, 3)),
        ("energy margin", _num(result.get("diagnostics", {}).get("energy_margin"), 3)),
    ]
    for name, value in rows:
        table.add_row(name, value)
    return table


def _timing_table(seconds: dict[str, float]) -> Table:
    table = Table(title="Time per stage", title_justify="left", show_header=False)
    table.add_column("stage")
    table.add_column("seconds", justify="right")
    for stage, value in seconds.items():
        table.add_row(stage, f"{value:.2f}")
    return table


def _demo(out: Path, seed: int, console: Console) -> int:
    params = PipelineParams()
    seconds: dict[str, float] = {}
    with _timed(seconds, "generate scene"):
        scene = generate_scene(SceneSpec.paper(), seed)
    with _timed(seconds, "write PLYs"):
        write_scene(scene, out / "scene")
    with _timed(seconds, "read PLYs"):
        fragments = read_fragments([out / "scene"], params)
    if not fragments:
        console.print("[red]no usable fragment was read back[/]")
        return EXIT_FAILED
    clouds = fragment_clouds(fragments, params)
    run = align_fragments(fragments, params)
    seconds |= {f"{stage} (pipeline)": value for stage, value in run.seconds.items()}
    with _timed(seconds, "exports"):
        written = _write_outputs(out, clouds, run)
    result, truth = run.alignment.result.model_dump(mode="json"), read_truth(out / "scene")
    report = evaluate_result(result, truth)
    n_points = {fid: len(points) for fid, points in clouds.items()}
    console.print(_fragment_table(result, truth, report, n_points))
    console.print(_scene_table(result, truth, report, seed))
    console.print(_timing_table(seconds))
    console.print("written: " + ", ".join(str(p) for p in [out / "scene", *written]))
    return EXIT_OK


def run_demo(out: Path, seed: int) -> int:
    """Run the demo into ``out``; return the exit code (0 when it ran, even if wrong).

    Parameters
    ----------
    out : Path
        Output folder: ``scene/`` (PLYs and ground truth), ``result.json``,
        ``layouts/<id>.png|.svg``, ``floorplan.png|.svg``, ``model.gltf``.
    seed : int
        Scene seed (``SceneSpec.paper()``).
    """
    console = Console(width=None if sys.stdout.isatty() else 110)  # pipes: no 80-col squeeze
    out.mkdir(parents=True, exist_ok=True)
    try:
        return _demo(out, seed, console)
    except Exception as exc:  # report, do not dump a traceback on the user
        console.print(f"[red]demo failed: {type(exc).__name__}: {exc}[/]")
        return EXIT_FAILED
