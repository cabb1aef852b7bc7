"""File-level pipeline for the CLI: read fragments, run the stages, write JSON.

All file I/O of the command line lives here; ``services`` stays pure.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from time import perf_counter
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from cli.exports import ExportTargets, write_exports
from cli.frames import dataset_frames, is_dataset, is_frame_dir, read_frame_dir, read_frame_zip
from cli.preflight import OptionFileError, output_problems, read_option_file
from schemas.hints import HintsModel
from schemas.layout_file import LayoutFileModel, LayoutFragmentModel
from schemas.params import PipelineParams
from schemas.result import LocalLayoutModel, ResultModel
from services import pipeline
from services.errors import JigsawError
from services.fragments import Fragment, dropped_count, fragment_layout, fragment_points
from services.parsing import parse_fragment
from services.pipeline import Alignment
from services.types import FloatArray

__all__ = [
    "AlignRun",
    "align_fragments",
    "collect_paths",
    "fragment_clouds",
    "read_fragments",
    "run_align",
    "run_layout",
]

EXIT_OK, EXIT_INTERNAL, EXIT_NO_INPUT = 0, 1, 2
EXIT_BAD_OPTION = 2  # an option's file or output path cannot be used (as no usable input)
_SUFFIXES = (".ply", ".pcd", ".zip")


def _is_input_dir(path: Path) -> bool:
    """An RGB-D frame folder or a dataset sequence (as opposed to a folder of inputs)."""
    return is_frame_dir(path) or is_dataset(path)


def collect_paths(paths: list[Path]) -> list[Path]:
    """Expand directories into their ``*.ply`` / ``*.pcd`` / ``*.zip`` files, RGB-D frame
    folders and dataset sequences (sorted); a frame folder or a sequence stands for itself."""
    out: list[Path] = []
    for path in paths:
        if path.is_dir() and not _is_input_dir(path):
            out += sorted(
                p
                for p in path.iterdir()
                if p.suffix.lower() in _SUFFIXES or (p.is_dir() and _is_input_dir(p))
            )
        else:
            out.append(path)
    return out


def _decode(path: Path, params: PipelineParams) -> Iterator[tuple[str, Fragment | Exception]]:
    """(fragment id, fragment or the error) for each fragment a path holds."""
    try:
        if path.is_dir() and is_dataset(path):
            yield from dataset_frames(path, params)
        elif path.is_dir():
            yield path.name, read_frame_dir(path, params)
        elif path.suffix.lower() == ".zip":
            yield path.stem, read_frame_zip(path, params)
        else:
            yield path.stem, parse_fragment(path.read_bytes(), params.parser)
    except (OSError, JigsawError) as exc:
        yield path.stem, exc


def read_fragments(paths: list[Path], params: PipelineParams) -> dict[str, Fragment]:
    """Decode every input (clouds, frames, frame zips, sequences); report unusable ones on
    stderr as ``file: reason`` and skip them."""
    fragments: dict[str, Fragment] = {}
    for path in collect_paths(paths):
        for fid, found in _decode(path, params):
            where = path if fid in (path.stem, path.name) else path / fid
            if isinstance(found, OSError):
                print(f"{where}: cannot read: {found.strerror or found}", file=sys.stderr)
            elif isinstance(found, JigsawError):
                print(f"{where}: {found.message}", file=sys.stderr)
            elif isinstance(found, Exception):
                print(f"{where}: {type(found).__name__}: {found}", file=sys.stderr)
            elif fid in fragments:
                print(f"{where}: duplicate fragment id {fid!r}, skipped", file=sys.stderr)
            else:
                dropped = dropped_count(found)
                if dropped:
                    print(f"{where}: dropped {dropped} non-finite points", file=sys.stderr)
                fragments[fid] = found
    return fragments


def fragment_clouds(
    fragments: Mapping[str, Fragment], params: PipelineParams
) -> dict[str, FloatArray]:
    """Each fragment's points in its local frame (a frame's back-projected)."""
    return {fid: fragment_points(f, params) for fid, f in fragments.items()}


@contextmanager
def _progress() -> Iterator[Progress]:
    """A progress bar on stderr (stdout may carry the result JSON), only on a terminal."""
    columns = (TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn())
    console = Console(stderr=True)
    with Progress(
        *columns, transient=True, console=console, disable=not sys.stderr.isatty()
    ) as bar:
        yield bar


def _write_json(payload: dict[str, Any], output: Path | None) -> None:
    text = json.dumps(payload, indent=2)
    if output is None:
        sys.stdout.write(text + "\n")
    else:
        output.parent.mkdir(parents=True, exist_ok=True)
        output.write_text(text + "\n")


def run_layout(paths: list[Path], output: Path | None, params: PipelineParams | None = None) -> int:
    """``jigsaw layout``: local layouts of all usable fragments as JSON
    (:class:`schemas.layout_file.LayoutFileModel`). Returns the exit code."""
    params = params or PipelineParams()
    inputs = read_fragments(paths, params)
    if not inputs:
        print("error: no usable fragment", file=sys.stderr)
        return EXIT_NO_INPUT
    layouts = {fid: fragment_layout(f, params) for fid, f in inputs.items()}
    fragments = [
        LayoutFragmentModel(
            id=fid,
            local_layout=LocalLayoutModel(keypoints=lay.keypoints_local().tolist()),
            manhattan_rotation=lay.frame.rotation.tolist(),
            floor_z=lay.frame.floor_z,
            ceiling_z=lay.frame.ceiling_z,
            walls_found=lay.ok,
        )
        for fid, lay in layouts.items()
    ]
    try:
        _write_json(LayoutFileModel(fragments=fragments).model_dump(mode="json"), output)
    except OSError as exc:
        return _cannot_write(exc)
    return EXIT_OK


def _cannot_write(exc: OSError) -> int:
    """Report an output that failed after the run; returns the exit code. A path the checks
    before the run could not tell is unwritable (a special file system, a disk that filled
    up) is the output's fault, not an internal failure."""
    print(f"{exc.filename or 'export'}: cannot write: {exc.strerror or exc}", file=sys.stderr)
    return EXIT_BAD_OPTION


class _AlignProgress:
    """The pipeline's progress callback: the local layouts' bar, and the time of each stage.

    A stage lasts from its first report to the first report of the next stage.
    """

    def __init__(self, bar: Progress) -> None:
        self._bar = bar
        self._task = bar.add_task("local layouts", total=1.0)
        self.started: dict[str, float] = {}

    def __call__(self, stage: str, fraction: float) -> None:
        self.started.setdefault(stage, perf_counter())
        if stage.startswith("local layout "):
            self._bar.update(self._task, description=stage, completed=fraction)
        elif stage in ("placement", "done"):
            self._bar.stop()  # the bar shows the local layouts only

    def seconds(self, start: float, end: float) -> dict[str, float]:
        """Wall time per stage: "local_layout" (frame merging included), "global" (placement
        and refinement), and its split "placement" / "refinement" when both ran."""
        placement = self.started.get("placement", end)
        seconds = {"local_layout": placement - start, "global": end - placement}
        if "placement" in self.started and "refinement" in self.started:
            seconds["placement"] = self.started["refinement"] - placement
            seconds["refinement"] = end - self.started["refinement"]
        return seconds


@dataclass(frozen=True)
class AlignRun:
    """An in-process alignment and the wall time of each stage (see ``_AlignProgress``)."""

    alignment: Alignment
    seconds: dict[str, float]


def align_fragments(
    fragments: Mapping[str, Fragment],
    params: PipelineParams,
    hints: HintsModel | None = None,
    premerge: bool = False,
) -> AlignRun:
    """:func:`services.pipeline.align_fragments` with a progress bar on the terminal, timed
    per stage."""
    start = perf_counter()
    with _progress() as bar:
        progress = _AlignProgress(bar)
        alignment = pipeline.align_fragments(fragments, params, progress, hints, premerge)
    return AlignRun(alignment, progress.seconds(start, perf_counter()))


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
        return EXIT_BAD_OPTION
    fragments = read_fragments(paths, params)
    if not fragments:
        print("error: no usable fragment", file=sys.stderr)
        return EXIT_NO_INPUT
    clouds = fragment_clouds(fragments, params)
    try:
        result = align_fragments(fragments, params, hints, premerge).alignment.result
    except Exception as exc:  # an internal failure must still end with a message and code 1
        print(f"internal error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return EXIT_INTERNAL
    try:
        _write_json(result.model_dump(mode="json"), output)
        notes = write_exports(exports, clouds, result)
    except OSError as exc:
        return _cannot_write(exc)
    for note in notes:
        print(note, file=sys.stderr)
    skipped = max(len(collect_paths(paths)) - len(fragments), 0)
    print(_summary(result, skipped, output, exports, notes), file=sys.stderr)
    return EXIT_OK
