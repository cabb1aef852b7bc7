"""One log format for every process of the service: the API, its access lines and the workers.

Each line has a time, a level, the logger, the process id, a message and, for structured
events such as a finished job, named fields. As text (the default)::

    2025-01-31T12:00:00.250Z INFO worker.consumer[4242]: placement done site=lab status=closed

or, with ``FPJ_LOG_JSON=1``, one JSON object a line::

    {"time": "2025-01-31T12:00:00.250Z", "level": "INFO", "logger": "worker.consumer",
     "pid": 4242, "message": "placement done", "site": "lab", "status": "closed", ...}

uvicorn's access lines get the fields ``client``, ``method``, ``path``, ``http_version`` and
``status``; tracebacks go into ``exc`` (JSON) or follow the line (text).
"""

from __future__ import annotations

import json
import logging
import sys
from datetime import UTC, datetime
from typing import Any

__all__ = ["JsonFormatter", "TextFormatter", "configure_logging", "log_fields"]

_ACCESS_FIELDS = ("client", "method", "path", "http_version", "status")
_UVICORN = ("uvicorn", "uvicorn.error", "uvicorn.access")


def log_fields(**values: Any) -> dict[str, Any]:
    """The ``extra`` of a structured log call: ``log.info("msg", extra=log_fields(a=1))``."""
    return {"fields": values}


def _given_fields(record: logging.LogRecord) -> dict[str, Any]:
    fields = getattr(record, "fields", None)
    return fields if isinstance(fields, dict) else {}


def _fields(record: logging.LogRecord) -> dict[str, Any]:
    """The record's fields; for an access line, its parts (the text line already has them)."""
    fields = _given_fields(record)
    if fields:
        return fields
    args = record.args
    if record.name == "uvicorn.access" and isinstance(args, tuple) and len(args) == 5:
        return dict(zip(_ACCESS_FIELDS, args, strict=True))
    return {}


def _time(record: logging.LogRecord) -> str:
    moment = datetime.fromtimestamp(record.created, tz=UTC)
    return moment.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _text(value: Any) -> str:
    text = value if isinstance(value, str) else json.dumps(value, default=str)
    return json.dumps(text) if (" " in text or not text) else text


class TextFormatter(logging.Formatter):
    """``TIME LEVEL logger[pid]: message key=value ...`` (values with spaces quoted)."""

    def format(self, record: logging.LogRecord) -> str:
        """The record as one text line (the traceback on the following lines)."""
        line = f"{_time(record)} {record.levelname} {record.name}[{record.process}]: "
        line += record.getMessage()
        extra = " ".join(f"{key}={_text(value)}" for key, value in _given_fields(record).items())
        if extra:
            line += " " + extra
        if record.exc_info:
            line += "\n" + self.formatException(record.exc_info)
        return line


class JsonFormatter(logging.Formatter):
    """One JSON object per record: time, level, logger, pid, message, then the fields."""

    def format(self, record: logging.LogRecord) -> str:
        """The record as one JSON object."""
        entry: dict[str, Any] = {
            "time": _time(record),
            "level": record.levelname,
            "logger": record.name,
            "pid": record.process,
            "message": record.getMessage(),
        }
        for key, value in _fields(record).items():
            entry.setdefault(key, value)
        if record.exc_info:
            entry["exc"] = self.formatException(record.exc_info)
        return json.dumps(entry, default=str)


def configure_logging(level: str, json_lines: bool = False) -> None:
    """Send every logger (uvicorn's included) to stderr in one format.

    Parameters
    ----------
    level : str
        debug, info, warning or error.
    json_lines : bool
        One JSON object per line instead of text (``FPJ_LOG_JSON=1``).

    Notes
    -----
    Start uvicorn with ``log_config=None`` so it keeps this configuration.
    """
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(JsonFormatter() if json_lines else TextFormatter())
    root = logging.getLogger()
    for old in list(root.handlers):
        root.removeHandler(old)
    root.addHandler(handler)
    root.setLevel(level.upper())
    for name in _UVICORN:
        logger = logging.getLogger(name)
        for old in list(logger.handlers):
            logger.removeHandler(old)
        logger.propagate = True
