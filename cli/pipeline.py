"""File-level pipeline for the CLI: read fragments, run the stages, write JSON.

All file I/O of the command line lives here; ``services`` stays pure.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from time import perf_counter
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from cli.exports import ExportTargets, write_exports
from cli.preflight import OptionFileError, output_problems, read_option_file
from schemas.hints import HintsModel
from schemas.params import PipelineParams
from schemas.result import ResultModel
from services.errors import JigsawError
from services.parsing import parse_fragment
from services.pipeline import align_clouds, estimate_layout, place_site
from services.types import FloatArray, LocalLayout

__all__ = [
    "AlignRun",
    "align_fragments",
    "collect_paths",
    "read_fragments",
    "run_align",
    "run_layout",
]

EXIT_OK, EXIT_INTERNAL, EXIT_NO_INPUT = 0, 1, 2
_SUFFIXES = (".ply", ".pcd")


def collect_paths(paths: list[Path]) -> list[Path]:
    """Expand directories into their ``*.ply`` / ``*.pcd`` files (sorted)."""
    out: list[Path] = []
    for path in paths:
        if path.is_dir():
            out += sorted(p for p in path.iterdir() if p.suffix.lower() in _SUFFIXES)
        else:
            out.append(path)
    return out


def read_fragments(paths: list[Path], params: PipelineParams) -> dict[str, FloatArray]:
    """Parse every file; report unusable ones on stderr as ``file: reason`` and skip them."""
    clouds: dict[str, FloatArray] = {}
    for path in collect_paths(paths):
        try:
            data = path.read_bytes()
            parsed = parse_fragment(data, params.parser)
        except OSError as exc:
            print(f"{path}: cannot read: {exc.strerror or exc}", file=sys.stderr)
            continue
        except JigsawError as exc:
            print(f"{path}: {exc.message}", file=sys.stderr)
            continue
        if path.stem in clouds:
            print(f"{path}: duplicate fragment id {path.stem!r}, skipped", file=sys.stderr)
            continue
        if parsed.dropped_nonfinite:
            print(f"{path}: dropped {parsed.dropped_nonfinite} non-finite points", file=sys.stderr)
        clouds[path.stem] = parsed.points
    return clouds


@contextmanager
def _progress() -> Iterator[Progress]:
    """A progress bar on stderr (stdout may carry the result JSON), only on a terminal."""
    columns = (TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn())
    console = Console(stderr=True)
    with Progress(
        *columns, transient=True, console=console, disable=not sys.stderr.isatty()
    ) as bar:
        yield bar


def _layouts(clouds: dict[str, FloatArray], params: PipelineParams) -> dict[str, LocalLayout]:
    layouts: dict[str, LocalLayout] = {}
    with _progress() as bar:
        task = bar.add_task("local layouts", total=len(clouds))
        for fid, points in clouds.items():
            bar.update(task, description=f"local layout {fid}")
            layouts[fid] = estimate_layout(points, params)
            bar.advance(task)
    return layouts


def _write_json(payload: dict[str, Any], output: Path | None) -> None:
    text = json.dumps(payload, indent=2)
    if output is None:
        sys.stdout.write(text + "\n")
    else:
        output.parent.mkdir(parents=True, exist_ok=True)
        output.write_text(text + "\n")


def run_layout(paths: list[Path], output: Path | None, params: PipelineParams | None = None) -> int:
    """``jigsaw layout``: local layouts of all usable fragments as JSON. Returns the exit code."""
    params = params or PipelineParams()
    clouds = read_fragments(paths, params)
    if not clouds:
        print("error: no usable fragment", file=sys.stderr)
        return EXIT_NO_INPUT
    layouts = _layouts(clouds, params)
    fragments = [
        {
            "id": fid,
            "local_layout": {"keypoints": lay.keypoints_local().tolist()},
            "manhattan_rotation": lay.frame.rotation.tolist(),
            "floor_z": lay.frame.floor_z,
            "ceiling_z": lay.frame.ceiling_z,
            "walls_found": lay.ok,
        }
        for fid, lay in layouts.items()
    ]
    _write_json({"schema_version": 1, "fragments": fragments}, output)
    return EXIT_OK


@dataclass(frozen=True)
class AlignRun:
    """What one in-process alignment produced.

    layouts: id -> local layout; result: the contract's result; seconds: wall time per stage
    ("local_layout", "global" = placement + refinement, and its split "placement" /
    "refinement" when the orchestrator reported those stages).
    """

    layouts: dict[str, LocalLayout]
    result: ResultModel
    seconds: dict[str, float]


def align_fragments(
    clouds: dict[str, FloatArray], params: PipelineParams, hints: HintsModel | None = None
) -> AlignRun:
    """Local layouts of all clouds, then the global placement (with ``hints``, if any);
    timed per stage.

    The stages of :func:`services.pipeline.align_clouds` without the pre-merge, keeping the
    layouts (for pictures) and the time of each stage.
    """
    start = perf_counter()
    layouts = _layouts(clouds, params)
    middle = perf_counter()
    marks: dict[str, float] = {}

    def mark(stage: str, _fraction: float) -> None:
        marks.setdefault(stage, perf_counter())

    result = place_site(layouts, params, mark, hints=hints)
    end = perf_counter()
    seconds = {"local_layout": middle - start, "global": end - middle}
    if "placement" in marks and "refinement" in marks:
        seconds["placement"] = marks["refinement"] - middle
        seconds["refinement"] = end - marks["refinement"]
    return AlignRun(layouts, result, seconds)


def _preflight(
    output: Path | None, exports: ExportTargets, hints_path: Path | None
) -> tuple[list[str], HintsModel | None]:
    """Problems of the options (one line each), and the hints; nothing has run yet."""
    problems = [f"error: {p}" for p in exports.problems()]
    outputs = {"-o": output, **exports.requested()}
    problems += [f"error: {p}" for p in output_problems(outputs)]
    hints = None
    if hints_path is not None:
        try:
            hints = read_option_file(hints_path, HintsModel)
        except OptionFileError as exc:
            problems.append(exc.message)
    return problems, hints


def _summary(
    result: ResultModel, skipped: int, output: Path | None, exports: ExportTargets, notes: list[str]
) -> str:
    """Two lines for stderr after a run: what was used and found, and where it went
    (``notes``: the exports that were not written, and why)."""
    placed = sum(f.placed for f in result.fragments)
    used = f"{len(result.fragments)} fragment(s) used, {skipped} skipped, {placed} placed"
    found = f"status {result.status}, confidence {result.confidence:.2f}"
    found += f", {len(result.alternatives)} alternative(s)"
    written = [f"result {output or 'stdout'}"]
    for option, path in exports.requested().items():
        if path is not None and not any(note.startswith(f"{path}: ") for note in notes):
            written.append(f"{option.removeprefix('--')} {path}")
    return f"{used}; {found}\nwritten: {', '.join(written)}"


def run_align(
    paths: list[Path],
    output: Path | None,
    params: PipelineParams | None = None,
    exports: ExportTargets | None = None,
    premerge: bool = False,
    hints_path: Path | None = None,
) -> int:
    """``jigsaw align``: the contract's result JSON, plus optional exports. Returns the exit
    code. With ``premerge``, overlapping fragments are first merged by FPFH registration;
    ``hints_path``: a hints JSON file (contract section 2).

    The options (hints file, output paths) are checked before any fragment is read: a
    problem is exit code 2 with one line on stderr each. After a run, a short summary goes
    to stderr (the result JSON may be on stdout).
    """
    params = params or PipelineParams()
    exports = exports or ExportTargets()
    problems, hints = _preflight(output, exports, hints_path)
    if problems:
        print("\n".join(problems), file=sys.stderr)
        return EXIT_NO_INPUT
    clouds = read_fragments(paths, params)
    if not clouds:
        print("error: no usable fragment", file=sys.stderr)
        return EXIT_NO_INPUT
    try:
        if premerge:
            result = align_clouds(clouds, params, premerge_overlapping=True, hints=hints)
        else:
            result = align_fragments(clouds, params, hints).result
    except Exception as exc:  # an internal failure must still end with a message and code 1
        print(f"internal error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return EXIT_INTERNAL
    try:
        _write_json(result.model_dump(mode="json"), output)
        notes = write_exports(exports, clouds, result)
    except OSError as exc:
        print(f"{exc.filename or 'export'}: cannot write: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_INTERNAL
    for note in notes:
        print(note, file=sys.stderr)
    skipped = len(collect_paths(paths)) - len(clouds)
    print(_summary(result, skipped, output, exports, notes), file=sys.stderr)
    return EXIT_OK
