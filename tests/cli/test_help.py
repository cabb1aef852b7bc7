"""What a new user sees first: ``jigsaw --version`` and the commands' help."""

from __future__ import annotations

import re
from importlib.metadata import version

import pytest

from tests.cli.conftest import RunJigsaw

pytestmark = pytest.mark.timeout(60)

COMMANDS = ("layout", "align", "demo", "serve", "worker", "send", "watch")


@pytest.fixture(autouse=True)
def wide_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    """Help lines as wide as the tests read them (rich wraps at the terminal's width)."""
    monkeypatch.setenv("COLUMNS", "160")


def _help(run_jigsaw: RunJigsaw, *args: str) -> str:
    process = run_jigsaw(*args, "--help")
    assert process.returncode == 0, process.stderr
    return re.sub(r"\s+", " ", process.stdout)


def test_version(run_jigsaw: RunJigsaw) -> None:
    process = run_jigsaw("--version")
    assert process.returncode == 0, process.stderr
    assert process.stdout.strip() == f"jigsaw (floorplan-jigsaw) {version('floorplan-jigsaw')}"


@pytest.mark.parametrize("command", ["", *COMMANDS])
def test_flags_show_no_bool_type(run_jigsaw: RunJigsaw, command: str) -> None:
    text = _help(run_jigsaw, *([command] if command else []))
    assert "<bool>" not in text and "--help" in text


def test_flags_read_as_flags(run_jigsaw: RunJigsaw) -> None:
    assert "--premerge first merge fragments" in _help(run_jigsaw, "align")
    assert re.search(r"--latest --no-latest first print", _help(run_jigsaw, "watch"))


def test_serve_binds_localhost_by_default(run_jigsaw: RunJigsaw) -> None:
    assert "[default: 127.0.0.1]" in _help(run_jigsaw, "serve")
