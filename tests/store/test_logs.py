"""The one log format: text lines with named fields, or JSON objects (FPJ_LOG_JSON=1),
uvicorn's access lines included."""

from __future__ import annotations

import json
import logging
import sys
from collections.abc import Iterator

import pytest

from store.logs import JsonFormatter, TextFormatter, configure_logging, log_fields

pytestmark = pytest.mark.timeout(10)


def _record(
    name: str, msg: str, args: tuple[object, ...] = (), **extra: object
) -> logging.LogRecord:
    record = logging.LogRecord(name, logging.INFO, __file__, 1, msg, args, None)
    for key, value in extra.items():
        setattr(record, key, value)
    return record


@pytest.fixture
def restore_logging() -> Iterator[None]:
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    yield
    root.handlers[:] = handlers
    root.setLevel(level)


def test_text_lines_carry_the_fields() -> None:
    record = _record(
        "worker.consumer",
        "%s done",
        ("placement",),
        **log_fields(site="lab", status="closed", note="two words"),
    )
    line = TextFormatter().format(record)
    assert " INFO worker.consumer[" in line
    assert line.endswith('placement done site=lab status=closed note="two words"')
    assert line[:4].isdigit() and "T" in line.split()[0] and line.split()[0].endswith("Z")


def test_json_lines_carry_the_fields() -> None:
    record = _record("worker.consumer", "placement done", **log_fields(site="lab", confidence=0.97))
    entry = json.loads(JsonFormatter().format(record))
    assert entry["message"] == "placement done" and entry["level"] == "INFO"
    assert entry["site"] == "lab" and entry["confidence"] == 0.97
    assert entry["logger"] == "worker.consumer" and isinstance(entry["pid"], int)
    assert entry["time"].endswith("Z")


def test_access_lines_become_fields() -> None:
    args = ("127.0.0.1:5000", "PUT", "/v1/sites/s/fragments/f", "1.1", 202)
    record = _record("uvicorn.access", '%s - "%s %s HTTP/%s" %d', args)
    entry = json.loads(JsonFormatter().format(record))
    assert entry["method"] == "PUT" and entry["status"] == 202
    assert entry["path"] == "/v1/sites/s/fragments/f" and entry["client"] == "127.0.0.1:5000"
    text = TextFormatter().format(record)
    assert text.endswith('"PUT /v1/sites/s/fragments/f HTTP/1.1" 202')  # no repeated fields


def test_exceptions_stay_on_one_json_line() -> None:
    try:
        raise ValueError("boom")
    except ValueError:
        record = logging.LogRecord("x", logging.ERROR, __file__, 1, "failed", (), sys.exc_info())
    line = JsonFormatter().format(record)
    assert "\n" not in line and "ValueError: boom" in json.loads(line)["exc"]


def test_configure_logging_takes_over_uvicorn(restore_logging: None) -> None:
    logging.getLogger("uvicorn.access").addHandler(logging.NullHandler())
    configure_logging("warning", json_lines=True)
    root = logging.getLogger()
    assert root.level == logging.WARNING and len(root.handlers) == 1
    assert isinstance(root.handlers[0].formatter, JsonFormatter)
    for name in ("uvicorn", "uvicorn.error", "uvicorn.access"):
        assert logging.getLogger(name).handlers == [] and logging.getLogger(name).propagate
