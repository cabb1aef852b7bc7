"""Robot side of the zenoh front end: ``jigsaw send`` and ``jigsaw watch``.

Both open one session (closed on every exit path, SIGTERM included: a process whose zenoh
session is left open can hang at exit), declare the robot's liveliness token
``fpj/robots/{robot_id}`` when given a robot id, and wait until the service's queryable
``fpj/service`` is reachable before doing anything.

Output: one JSON document per line on ``out`` (each reply, or each pose update); diagnostics
on ``err``.
"""

from __future__ import annotations

import contextlib
import json
import queue
import signal
import threading
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Any, TextIO, cast

import zenoh

from schemas.hints import FragmentPrior
from schemas.result import ResultModel
from schemas.service import ErrorBody, ErrorDetail
from schemas.zenoh import ServiceInfo, pose_updates
from services.errors import FragmentTooLargeError
from transport.config import Mode, TlsOptions, ZenohOptions, build_config
from transport.keys import ZenohKeys

__all__ = ["RobotOptions", "robot_options", "send_fragments", "watch_poses"]

JSON = zenoh.Encoding.APPLICATION_JSON


@dataclass(frozen=True)
class RobotOptions:
    """How a robot reaches the service, and who it is."""

    zenoh: ZenohOptions
    prefix: str = "fpj"
    robot_id: str | None = None
    token: str | None = None
    timeout: float = 60.0  # seconds, per query and for finding the service

    @property
    def keys(self) -> ZenohKeys:
        """The service's key expressions under this prefix."""
        return ZenohKeys(self.prefix)

    def attachment(self, prior: FragmentPrior | None = None) -> bytes | None:
        """The attachment (UTF-8 JSON): robot tag and the fragment's prior, if any."""
        tag: dict[str, Any] = {
            k: v for k, v in (("robot_id", self.robot_id), ("token", self.token)) if v
        }
        if prior is not None:
            tag["prior"] = prior.model_dump(mode="json")
        return json.dumps(tag).encode() if tag else None


def robot_options(
    connect: Sequence[str],
    *,
    mode: str = "peer",
    scout: bool = False,
    prefix: str = "fpj",
    robot_id: str | None = None,
    token: str | None = None,
    timeout: float = 60.0,
    tls: TlsOptions | None = None,
    user: str | None = None,
    password: str | None = None,
) -> RobotOptions:
    """Options of a robot-side command (``connect`` items may be comma-separated); ``tls``,
    ``user`` and ``password`` for a service whose zenoh peers must authenticate.

    Raises
    ------
    ValueError
        ``mode`` is not ``peer`` or ``client``.
    """
    if mode not in ("peer", "client"):
        raise ValueError(f"a robot's zenoh mode is peer or client, not {mode!r}")
    endpoints = [part.strip() for item in connect for part in item.split(",") if part.strip()]
    session = ZenohOptions(
        mode=cast(Mode, mode),
        connect=endpoints,
        multicast_scouting=scout,
        tls=tls,
        user=user,
        password=password,
    )
    return RobotOptions(session, prefix, robot_id, token, timeout)


class _Stop(SystemExit):
    """Raised by the SIGTERM handler so that ``with`` blocks close the session."""


def _raise_stop(signum: int, frame: FrameType | None) -> None:
    raise _Stop(0)


@contextlib.contextmanager
def _robot_session(options: RobotOptions) -> Iterator[zenoh.Session]:
    """An open session; SIGTERM unwinds it like Ctrl-C (so it is always closed)."""
    previous: Any = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _raise_stop)
    try:
        with zenoh.open(build_config(options.zenoh)) as session:
            yield session
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


@contextlib.contextmanager
def _presence(session: zenoh.Session, options: RobotOptions) -> Iterator[None]:
    """The robot's liveliness token ``fpj/robots/{robot_id}`` (nothing without an id)."""
    if not options.robot_id:
        yield
        return
    with session.liveliness().declare_token(options.keys.robot(options.robot_id)):
        yield


def find_service(session: zenoh.Session, options: RobotOptions) -> ServiceInfo | None:
    """Wait (up to the timeout) until the service answers on ``fpj/service``."""
    matched = threading.Event()
    with (
        session.declare_querier(options.keys.service, timeout=options.timeout) as querier,
        querier.declare_matching_listener(lambda s: matched.set() if s.matching else None),
    ):
        # matching_status is a MatchingStatus at run time (typed bool in zenoh's stubs)
        now = bool(getattr(querier.matching_status, "matching", False))
        if not (now or matched.wait(options.timeout)):
            return None
        for reply in querier.get():
            if reply.ok is not None:
                return ServiceInfo.model_validate_json(reply.ok.payload.to_bytes())
        return None


def _error_text(code: str, message: str) -> str:
    """The service's error body ``{"error": {"code", "message"}}`` as compact JSON."""
    body = ErrorBody(error=ErrorDetail(code=code, message=message))
    return json.dumps(body.model_dump(), separators=(",", ":"))


def _reply_text(replies: Any, timeout: float) -> tuple[bool, str]:
    """(ok, JSON) of the first reply of a query; zenoh's own errors (e.g. its query timeout,
    which is all a querier sees of a message zenoh dropped) become error bodies too."""
    for reply in replies:
        if reply.ok is not None:
            return True, reply.ok.payload.to_string()
        text = reply.err.payload.to_string()
        try:
            body = json.loads(text)
        except ValueError:
            body = None
        if isinstance(body, dict) and isinstance(body.get("error"), dict):
            return False, text
        return False, _error_text("zenoh_error", text)
    return False, _error_text("no_reply", f"no reply within {timeout:g} s")


def _send_one(
    session: zenoh.Session,
    options: RobotOptions,
    site_id: str,
    path: Path,
    info: ServiceInfo,
    prior: FragmentPrior | None,
) -> tuple[bool, str]:
    data = path.read_bytes()
    if len(data) > info.max_upload_bytes:
        message = f"{len(data)} bytes exceed the service's {info.max_upload_bytes}-byte limit"
        return False, _error_text(FragmentTooLargeError.code, message)
    replies = session.get(
        options.keys.fragment(site_id, path.stem),
        payload=data,
        attachment=options.attachment(prior),
        timeout=options.timeout,
    )
    return _reply_text(replies, options.timeout)


def send_fragments(
    options: RobotOptions,
    site_id: str,
    files: Sequence[Path],
    out: TextIO,
    err: TextIO,
    *,
    prior: FragmentPrior | None = None,
) -> int:
    """Send each file as fragment ``{stem}`` of ``site_id`` by query; print each reply.
    ``prior``: sent in each query's attachment (meant for a single fragment).

    Returns
    -------
    int
        0 when every fragment was acknowledged, 1 otherwise (or when no service answered).
    """
    with _robot_session(options) as session, _presence(session, options):
        info = find_service(session, options)
        if info is None:
            err.write(f"no service answered on {options.keys.service}\n")
            return 1
        failures = 0
        for path in files:
            try:
                ok, text = _send_one(session, options, site_id, path, info, prior)
            except OSError as exc:
                ok, text = False, _error_text("unreadable", str(exc))
            out.write(text + "\n")
            out.flush()
            if not ok:
                failures += 1
                err.write(f"{path}: {text}\n")
        return 1 if failures else 0


def _latest_poses(session: zenoh.Session, options: RobotOptions, site_id: str) -> list[str]:
    """The pose lines of the site's latest result (none yet: an empty list)."""
    replies = session.get(
        options.keys.result(site_id), attachment=options.attachment(), timeout=options.timeout
    )
    for reply in replies:
        if reply.ok is not None:
            result = ResultModel.model_validate_json(reply.ok.payload.to_bytes())
            return [update.model_dump_json() for update in pose_updates(result)]
    return []


def _drain(lines: queue.Queue[str], count: int | None, duration: float | None, out: TextIO) -> int:
    deadline = None if duration is None else time.monotonic() + duration
    printed = 0
    while count is None or printed < count:
        remaining = None if deadline is None else deadline - time.monotonic()
        if remaining is not None and remaining <= 0:
            break
        try:
            line = lines.get(timeout=remaining)
        except queue.Empty:
            break
        out.write(line + "\n")
        out.flush()
        printed += 1
    return printed


def watch_poses(
    options: RobotOptions,
    site_id: str,
    out: TextIO,
    err: TextIO,
    *,
    count: int | None = None,
    duration: float | None = None,
    latest: bool = True,
) -> int:
    """Print pose updates of ``site_id`` as they arrive (one PoseUpdate JSON per line).

    Stops after ``count`` updates, after ``duration`` seconds, or on SIGINT/SIGTERM.
    ``latest``: first print the poses of the latest result (for a robot joining late).
    """
    lines: queue.Queue[str] = queue.Queue()
    with _robot_session(options) as session:
        key = options.keys.site_poses(site_id)
        # The token after the subscriber: whoever sees the robot can already reach it.
        with (
            session.declare_subscriber(key, lambda s: lines.put(s.payload.to_string())),
            _presence(session, options),
        ):
            _prime(session, options, site_id, lines, err, latest=latest)
            _drain(lines, count, duration, out)
    return 0


def _prime(
    session: zenoh.Session,
    options: RobotOptions,
    site_id: str,
    lines: queue.Queue[str],
    err: TextIO,
    *,
    latest: bool,
) -> None:
    if find_service(session, options) is None:
        err.write(f"no service answered on {options.keys.service}; waiting anyway\n")
    elif latest:
        for line in _latest_poses(session, options, site_id):
            lines.put(line)
    err.write(f"watching {options.keys.site_poses(site_id)}\n")
    err.flush()
