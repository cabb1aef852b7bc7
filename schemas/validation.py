"""One line of text for validation errors, as every front end reports them (HTTP, zenoh, CLI)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

__all__ = ["summarize_errors"]

_MAX_SHOWN = 5


def summarize_errors(errors: Iterable[Mapping[str, Any]]) -> str:
    """``loc: message; loc: message`` of pydantic errors (``ValidationError.errors()``).

    At most five are listed; newlines are flattened so the result is always one line.

    >>> summarize_errors([{"loc": ("fragments", "a", "pose"), "msg": "bad"}, {"msg": "x"}])
    'fragments.a.pose: bad; x'
    >>> summarize_errors([])
    'invalid'
    """
    parts = []
    for error in errors:
        where = ".".join(str(part) for part in error.get("loc", ()))
        message = str(error.get("msg", "invalid"))
        parts.append(f"{where}: {message}" if where else message)
    shown = "; ".join(parts[:_MAX_SHOWN]) or "invalid"
    if len(parts) > _MAX_SHOWN:
        shown += f" (+{len(parts) - _MAX_SHOWN} more)"
    return " ".join(shown.split())
