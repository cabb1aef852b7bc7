"""Benchmark of the local layout stage (paper section 4, "Partial layout estimation" and
"Time efficiency"): ACC_local, time per 10k points, a noisy 200k-point fragment, and the peak
memory of a 1.5M-point fragment.

Run ``python bench/local_layout.py`` (``--quick`` for a small run). Scenes come from
:mod:`services.synthetic` with fixed seeds, so runs are comparable across commits. Times are
wall-clock ``estimate_layout`` calls only (scene generation excluded), single process.

Memory is measured in a child process that loads the fragment from a ``.npy`` file and runs
``estimate_layout`` once. Resident memory: Linux ``VmHWM`` (peak resident set) from
``/proc/self/status``, reset through ``/proc/self/clear_refs`` just before the call, so it is
the peak of the whole child (interpreter, libraries and the loaded array included) during the
call. ``resource.getrusage().ru_maxrss`` is not used: Linux carries it over from the forking
parent across ``exec``, so the child would report the benchmark's own size. Heap: the peak of
``tracemalloc`` over a second call (Python and numpy allocations only; Open3D's C++
allocations are not traced).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import subprocess
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich import box
from rich.console import Console
from rich.table import Table

from schemas.params import PipelineParams
from services.evaluation import keypoint_error
from services.pipeline import estimate_layout
from services.synthetic import SceneSpec, SyntheticFragment, generate_scene

__all__ = ["FragmentRun", "main"]

PRESETS = {"easy": SceneSpec.easy, "paper": SceneSpec.paper, "hard": SceneSpec.hard}
SEED_BASE = {"easy": 10_000, "paper": 20_000, "hard": 30_000}
FULL_PER_PRESET, QUICK_PER_PRESET = 70, 10  # 3 x 70 = 210 fragments in the full run


@dataclass(frozen=True)
class FragmentRun:
    """One fragment's local layout against its truth."""

    preset: str
    n_points: int
    seconds: float  # wall clock
    cpu_seconds: float  # process CPU time (all threads): robust to a busy machine
    error: float  # mean keypoint error, m (inf when no wall was found)
    diagonal: float
    found: bool
    keypoints: tuple[int, int]  # (estimated, true)

    @property
    def correct(self) -> bool:
        """Paper: mean keypoint error below 5 % of the fragment's bounding-box diagonal."""
        return self.error < 0.05 * self.diagonal


def fragments(spec: SceneSpec, seed_base: int, count: int) -> Iterator[SyntheticFragment]:
    """The first ``count`` fragments of the scenes ``seed_base``, ``seed_base + 1``, ..."""
    seed, emitted = seed_base, 0
    while emitted < count:
        for fragment in generate_scene(spec, seed).fragments[: count - emitted]:
            emitted += 1
            yield fragment
        seed += 1


def run_fragment(preset: str, fragment: SyntheticFragment, params: PipelineParams) -> FragmentRun:
    """Estimate one fragment's layout, timed, and score it."""
    start, cpu_start = time.perf_counter(), time.process_time()
    layout = estimate_layout(fragment.points, params)
    seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu_start
    estimated = layout.keypoints_local()
    return FragmentRun(
        preset=preset,
        n_points=len(fragment.points),
        seconds=seconds,
        cpu_seconds=cpu_seconds,
        error=keypoint_error(estimated, fragment.keypoints_local),
        diagonal=fragment.diagonal,
        found=layout.ok,
        keypoints=(len(estimated), len(fragment.keypoints_local)),
    )


def accuracy_table(runs: list[FragmentRun]) -> Table:
    """ACC_local and speed per preset, and over all fragments."""
    table = Table(title="Local layout: ACC_local and speed", title_justify="left", box=box.SIMPLE)
    for header in ("setting", "fragments", "mean points", "ACC_local (%)", "no wall (%)"):
        table.add_column(header, justify="right")
    for header in ("kp count ok (%)", "median err (m)", "ms / 10k pts", "CPU ms / 10k"):
        table.add_column(header, justify="right")
    for header in ("max s / frag",):
        table.add_column(header, justify="right")
    groups = {name: [r for r in runs if r.preset == name] for name in PRESETS}
    for name, group in [*groups.items(), ("all", runs)]:
        if not group:
            continue
        points = sum(r.n_points for r in group)
        errors = [r.error for r in group]
        table.add_row(
            name,
            str(len(group)),
            f"{points / len(group):,.0f}",
            f"{100 * np.mean([r.correct for r in group]):.1f}",
            f"{100 * np.mean([not r.found for r in group]):.1f}",
            f"{100 * np.mean([r.keypoints[0] == r.keypoints[1] for r in group]):.1f}",
            f"{np.median(errors):.3f}",
            f"{1e3 * sum(r.seconds for r in group) / points * 1e4:.1f}",
            f"{1e3 * sum(r.cpu_seconds for r in group) / points * 1e4:.1f}",
            f"{max(r.seconds for r in group):.2f}",
        )
    return table


def noisy_runs(count: int, params: PipelineParams) -> list[FragmentRun]:
    """``count`` noisy, cluttered 200k-point fragments (hard preset), timed."""
    spec = dataclasses.replace(
        SceneSpec.hard(), points_per_fragment=(200_000, 200_000), n_fragments_range=(4, 4)
    )
    return [run_fragment("hard 200k", f, params) for f in fragments(spec, 40_000, count)]


def big_fragment(path: Path, n_points: int) -> None:
    """Save one paper-like fragment of ``n_points`` points as ``.npy`` (float64, local)."""
    spec = dataclasses.replace(
        SceneSpec.paper(), points_per_fragment=(n_points, n_points), n_fragments_range=(2, 2)
    )
    np.save(path, generate_scene(spec, 50_000).fragments[0].points)


def _status_kib(field: str) -> float:
    """A ``kB`` line of ``/proc/self/status`` (Linux), e.g. ``VmRSS``; nan elsewhere."""
    try:
        lines = Path("/proc/self/status").read_text().splitlines()
    except OSError:
        return float("nan")
    values = [line.split()[1] for line in lines if line.startswith(field + ":")]
    return float(values[0]) if values else float("nan")


def memory_child(path: Path) -> None:
    """Child side of the memory measurement: print one JSON line with the numbers (MiB)."""
    points = np.load(path)
    params = PipelineParams()
    rss_before = _status_kib("VmRSS")
    with contextlib.suppress(OSError):
        Path("/proc/self/clear_refs").write_text("5")  # reset the VmHWM peak
    start = time.perf_counter()
    layout = estimate_layout(points, params)
    seconds = time.perf_counter() - start
    rss_peak = _status_kib("VmHWM")
    tracemalloc.start()
    estimate_layout(points, params)
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    report = {
        "points": len(points),
        "seconds": seconds,
        "rss_before_mib": rss_before / 1024,
        "rss_peak_mib": rss_peak / 1024,
        "tracemalloc_peak_mib": traced_peak / 2**20,
        "input_mib": points.nbytes / 2**20,
        "walls_found": layout.ok,
    }
    print(json.dumps(report))


def measure_memory(n_points: int) -> dict[str, float]:
    """Generate the big fragment, run the child, return its JSON report."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "fragment.npy"
        big_fragment(path, n_points)
        command = [sys.executable, str(Path(__file__).resolve()), "--memory-child", str(path)]
        done = subprocess.run(command, capture_output=True, text=True, check=True)
    report: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return report


def extra_table(noisy: list[FragmentRun], memory: dict[str, float] | None) -> Table:
    """The 200k timing and the memory numbers."""
    table = Table(title="Large fragments", title_justify="left", box=box.SIMPLE)
    table.add_column("measurement")
    table.add_column("value", justify="right")
    for k, run in enumerate(noisy):
        state = "correct" if run.correct else f"wrong (err {run.error:.2f} m)"
        value = f"{run.seconds:.2f} s, CPU {run.cpu_seconds:.2f} s ({state})"
        table.add_row(f"noisy 200k fragment #{k + 1}: time", value)
    if memory is not None:
        growth = memory["rss_peak_mib"] - memory["rss_before_mib"]
        rows = [
            ("1.5M fragment: points", f"{memory['points']:,.0f}"),
            ("1.5M: input array (float64)", f"{memory['input_mib']:.0f} MiB"),
            ("1.5M: time", f"{memory['seconds']:.2f} s"),
            ("1.5M: process RSS before the call", f"{memory['rss_before_mib']:.0f} MiB"),
            ("1.5M: process peak RSS during the call (VmHWM)", f"{memory['rss_peak_mib']:.0f} MiB"),
            ("1.5M: peak RSS growth over before", f"{growth:.0f} MiB"),
            (
                "1.5M: tracemalloc peak (numpy/Python heap)",
                f"{memory['tracemalloc_peak_mib']:.0f} MiB",
            ),
        ]
        for name, value in rows:
            table.add_row(name, value)
    return table


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print its tables; returns the exit code."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--quick", action="store_true", help="10 fragments per setting")
    parser.add_argument("--per-setting", type=int, help="fragments per setting (default 70)")
    parser.add_argument("--no-memory", action="store_true", help="skip the 1.5M-point run")
    parser.add_argument("--memory-child", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.memory_child is not None:
        memory_child(args.memory_child)
        return 0
    console = Console(width=None if sys.stdout.isatty() else 120)
    count = args.per_setting or (QUICK_PER_PRESET if args.quick else FULL_PER_PRESET)
    params = PipelineParams()
    started = time.perf_counter()
    runs = [
        run_fragment(name, fragment, params)
        for name, make in PRESETS.items()
        for fragment in fragments(make(), SEED_BASE[name], count)
    ]
    console.print(accuracy_table(runs))
    noisy = noisy_runs(1 if args.quick else 3, params)
    memory = None if args.no_memory else measure_memory(1_500_000)
    console.print(extra_table(noisy, memory))
    minutes = (time.perf_counter() - started) / 60
    console.print(f"seeds: easy {SEED_BASE['easy']}+, paper {SEED_BASE['paper']}+, ", end="")
    console.print(f"hard {SEED_BASE['hard']}+; total {minutes:.1f} min")
    return 0


if __name__ == "__main__":
    sys.exit(main())
