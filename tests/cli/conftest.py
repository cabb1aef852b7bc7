"""Fixtures of the CLI tests: a small synthetic scene on disk and the real console script."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from cli.scene_io import write_scene
from services.synthetic import SceneSpec, SyntheticScene, generate_scene

ROOT = Path(__file__).resolve().parents[2]
SCENE_SEED = 5  # an easy scene (3 fragments, 8 corners) that the pipeline closes

RunJigsaw = Callable[..., subprocess.CompletedProcess[str]]


def small_spec() -> SceneSpec:
    """The easy preset with few points per fragment, so a CLI run takes a few seconds."""
    return dataclasses.replace(SceneSpec.easy(), points_per_fragment=(15_000, 25_000))


@pytest.fixture(scope="session")
def small_scene() -> SyntheticScene:
    """The generated scene (in memory)."""
    return generate_scene(small_spec(), SCENE_SEED)


@pytest.fixture(scope="session")
def scene_dir(small_scene: SyntheticScene, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The scene written as ``<id>.ply`` files plus ``ground_truth.json``."""
    folder = tmp_path_factory.mktemp("scene")
    write_scene(small_scene, folder)
    return folder


@pytest.fixture(scope="session")
def jigsaw_exe() -> Path:
    """The installed ``jigsaw`` console script next to the running interpreter."""
    exe = Path(sys.executable).parent / "jigsaw"
    if not exe.exists():
        pytest.fail(f"{exe} is missing: install the project (pip install -e .)")
    return exe


@pytest.fixture(scope="session")
def run_jigsaw(jigsaw_exe: Path) -> RunJigsaw:
    """Run ``jigsaw ARGS...`` from the repository root; returns the completed process."""

    def run(*args: str | Path, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
        command = [str(jigsaw_exe), *map(str, args)]
        return subprocess.run(
            command, cwd=ROOT, capture_output=True, text=True, timeout=timeout, check=False
        )

    return run
