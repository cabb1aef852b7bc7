"""Checks of a command's option files and output paths, before anything runs.

``jigsaw align`` refuses a bad hints file and an output it could not write, and ``jigsaw
send`` a bad prior file, with exit code 2 and one line each on stderr, before reading any
fragment or opening any session (nothing is computed only to be lost).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import TypeVar

from pydantic import BaseModel, ValidationError

from schemas.validation import summarize_errors
from services.errors import JigsawError

__all__ = ["OptionFileError", "output_problems", "read_option_file"]

Model = TypeVar("Model", bound=BaseModel)


class OptionFileError(JigsawError):
    """An option's JSON file cannot be read or is not valid; the message is ``FILE: reason``."""

    code = "invalid_option_file"


def read_option_file(path: Path, model: type[Model]) -> Model:
    """Read and validate a JSON file given as an option (hints, prior).

    Raises
    ------
    OptionFileError
        Unreadable, not JSON, unknown fields or invalid values; one line ``FILE: reason``.
    """
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise OptionFileError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    try:
        return model.model_validate_json(data)
    except ValidationError as exc:
        raise OptionFileError(f"{path}: {summarize_errors(exc.errors())}") from exc


def _unwritable(path: Path) -> str | None:
    """Why ``path`` cannot be written (its missing folders would be created), or None."""
    try:
        if path.is_dir():
            return "is a directory"
        if path.exists():
            return None if os.access(path, os.W_OK) else "not writable"
        folder = path.parent
        while not folder.exists():
            folder = folder.parent
    except OSError as exc:
        return f"cannot check: {exc.strerror or exc}"
    if not folder.is_dir():
        return f"{folder} is not a directory"
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"cannot write in {folder}"
    return None


def output_problems(outputs: Mapping[str, Path | None]) -> list[str]:
    """``option path: reason`` for each given output path that cannot be written.

    >>> output_problems({"-o": Path("/"), "--cloud": None})
    ['-o /: is a directory']
    """
    problems = []
    for option, path in outputs.items():
        reason = None if path is None else _unwritable(path)
        if reason is not None:
            problems.append(f"{option} {path}: {reason}")
    return problems
