"""File-level pipeline for the CLI: read fragments, run the stages, write JSON.

All file I/O of the command line lives here; ``services`` stays pure.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from schemas.params import PipelineParams
from services.errors import JigsawError
from services.parsing import parse_fragment
from services.pipeline import estimate_layout, place_site
from services.types import FloatArray, LocalLayout

__all__ = ["collect_paths", "read_fragments", "run_align", "run_layout"]

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
def _progress(total: int) -> Iterator[Progress]:
    columns = (TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn())
    with Progress(*columns, transient=True, console=None, disable=not sys.stderr.isatty()) as bar:
        yield bar


def _layouts(clouds: dict[str, FloatArray], params: PipelineParams) -> dict[str, LocalLayout]:
    layouts: dict[str, LocalLayout] = {}
    with _progress(len(clouds)) as bar:
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


def run_align(paths: list[Path], output: Path | None, params: PipelineParams | None = None) -> int:
    """``jigsaw align``: the contract's result JSON. Returns the exit code."""
    params = params or PipelineParams()
    clouds = read_fragments(paths, params)
    if not clouds:
        print("error: no usable fragment", file=sys.stderr)
        return EXIT_NO_INPUT
    try:
        layouts = _layouts(clouds, params)
        result = place_site(layouts, params)
    except Exception as exc:  # an internal failure must still end with a message and code 1
        print(f"internal error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return EXIT_INTERNAL
    _write_json(result.model_dump(mode="json"), output)
    return EXIT_OK
