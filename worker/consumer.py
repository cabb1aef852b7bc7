"""The consumer loop: read or reclaim one job, run it, acknowledge, retry or dead-letter it.

Delivery is at least once. A job is pending on its consumer from XREADGROUP until XACK; a
worker that dies leaves it pending, and after ``visibility_timeout_s`` of silence any worker
takes it over with XAUTOCLAIM. Live workers keep their jobs from looking silent by re-claiming
them (XCLAIM ... JUSTID resets the idle time) from the :class:`Keeper` thread, which also
writes the worker's heartbeat. Every delivery bumps the job's try counter; past
``max_tries`` the job goes to the dead-letter stream and its fragment or site is marked failed.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import time
from dataclasses import dataclass
from typing import Any

import redis
from pydantic import ValidationError

from schemas.jobs import DeadLetter, LayoutJob, PlacementJob, decode_job
from schemas.service import ErrorDetail
from schemas.settings import Settings
from services.errors import FragmentError, JigsawError
from store.connection import REDIS_DOWN, ensure_group, storage_refused, strings
from store.jobs import Extra, ack, dead_letter, retry_later
from store.keys import GROUP, Keys
from store.logs import log_fields
from store.stats import record_job
from worker.handlers import HANDLERS, Handler
from worker.updates import JobContext

__all__ = ["Consumer", "Keeper", "LeaseBook"]

log = logging.getLogger(__name__)

BLOCK_MS = 500
TRIES_TTL_S = 7 * 24 * 3600
HARD_EXIT_CODE = 70
PRUNE_PERIOD_S = 60.0
_REDIS_ERRORS: tuple[type[Exception], ...] = (*REDIS_DOWN, redis.ResponseError)


@dataclass(frozen=True)
class Lease:
    """A job one consumer is running: its stream entry and when to give up on the thread."""

    consumer: str
    message_id: str
    hard_deadline: float  # time.monotonic()


class LeaseBook:
    """The jobs this process is running, shared between consumers and the keeper."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._leases: dict[str, Lease] = {}

    def hold(self, lease: Lease) -> None:
        """Record that ``lease.consumer`` runs ``lease``'s job."""
        with self._lock:
            self._leases[lease.consumer] = lease

    def release(self, consumer: str) -> None:
        """The consumer's job is over."""
        with self._lock:
            self._leases.pop(consumer, None)

    def snapshot(self) -> list[Lease]:
        """The leases held now."""
        with self._lock:
            return list(self._leases.values())


def _entry(entry: Any) -> tuple[str, dict[str, str]]:
    message_id, fields = entry[0], entry[1]
    return str(message_id), dict(fields or {})


def _timeout(settings: Settings, job: LayoutJob | PlacementJob) -> float:
    return settings.layout_timeout_s if job.kind == "layout" else settings.placement_timeout_s


def _error(exc: BaseException) -> ErrorDetail:
    if isinstance(exc, JigsawError):
        return ErrorDetail(code=exc.code, message=exc.message)
    return ErrorDetail(code="internal_error", message=f"{type(exc).__name__}: {exc}")


class Consumer:
    """One consumer of the group: a thread runs :meth:`run` until ``stop`` is set."""

    def __init__(
        self,
        name: str,
        client: redis.Redis,
        raw: redis.Redis,
        settings: Settings,
        leases: LeaseBook,
        stop: threading.Event,
        handlers: dict[str, Handler] | None = None,
    ) -> None:
        self.name, self.client, self.raw = name, client, raw
        self.settings, self.leases, self.stop = settings, leases, stop
        self.keys = Keys(settings.key_prefix)
        self.params = settings.pipeline_params()
        self.handlers = handlers or HANDLERS
        self.claim_interval = min(1.0, settings.visibility_timeout_s / 4)
        self._next_claim = 0.0

    def run(self) -> None:
        """Consume until stopped; Redis outages are waited out with a capped backoff."""
        backoff, need_group = 0.1, False
        while not self.stop.is_set():
            try:
                if need_group:
                    ensure_group(self.client, self.keys)
                    need_group = False
                self.step()
                backoff = 0.1
            except REDIS_DOWN as exc:
                log.warning(
                    "%s: Redis unreachable (%s); retrying in %.1fs", self.name, exc, backoff
                )
                self.stop.wait(backoff)
                backoff = min(backoff * 2, 5.0)
            except redis.ResponseError as exc:
                if storage_refused(exc):  # its job stays pending until there is room
                    log.warning("%s: Redis storage full (%s); retrying in 2s", self.name, exc)
                    self.stop.wait(2.0)
                    continue
                # NOGROUP / UNBLOCKED: the stream was deleted (e.g. Redis lost its data).
                if not str(exc).startswith(("NOGROUP", "UNBLOCKED")):
                    log.exception("%s: Redis error", self.name)
                    self.stop.wait(1.0)
                need_group = True
            except Exception:
                log.exception("%s: unexpected error in the consumer loop", self.name)
                self.stop.wait(1.0)

    def step(self) -> bool:
        """Run at most one job (reclaimed first, else new); True when one was run."""
        entry = self._claim() or self._read()
        if entry is None:
            return False
        message_id, fields = entry
        self.process(message_id, fields.get("job", ""))
        return True

    def _claim(self) -> tuple[str, dict[str, str]] | None:
        now = time.monotonic()
        if now < self._next_claim:
            return None
        self._next_claim = now + self.claim_interval
        # JUSTID: Redis 6.2 replies [cursor, ids], 7.x [cursor, ids, deleted]; redis-py
        # returns the ids in both cases, and entries deleted meanwhile are fetched as empty.
        ids = self.client.xautoclaim(
            self.keys.jobs,
            GROUP,
            self.name,
            min_idle_time=int(self.settings.visibility_timeout_s * 1000),
            start_id="0-0",
            count=1,
            justid=True,
        )
        for message_id in strings(ids):
            entries = self.client.xrange(self.keys.jobs, message_id, message_id)
            if entries:
                log.info("%s: reclaimed job entry %s", self.name, message_id)
                return _entry(entries[0])
            self.client.xack(self.keys.jobs, GROUP, message_id)
        return None

    def _read(self) -> tuple[str, dict[str, str]] | None:
        reply: Any = self.client.xreadgroup(
            GROUP, self.name, {self.keys.jobs: ">"}, count=1, block=BLOCK_MS
        )
        if not reply:
            return None
        # RESP2: [[stream, [(id, fields)]]]; RESP3: {stream: [[(id, fields)]]}.
        entries = reply[0][1] if isinstance(reply, list) else next(iter(reply.values()))[0]
        return _entry(entries[0]) if entries else None

    def process(self, message_id: str, raw_job: str) -> None:
        """Run one delivered job and settle its stream entry."""
        try:
            job = decode_job(raw_job)
        except ValidationError as exc:
            letter = self._letter(raw_job, ErrorDetail(code="bad_job", message=str(exc)), 0)
            dead_letter(self.client, self.keys, message_id, None, letter)
            return
        tries_key = self.keys.tries(job.job_id)
        with self.client.pipeline() as pipe:
            pipe.incr(tries_key)
            pipe.expire(tries_key, TRIES_TTL_S)
            tries = int(pipe.execute()[0])
        deadline = time.monotonic() + _timeout(self.settings, job)
        ctx = JobContext(
            self.client, self.raw, self.keys, self.settings, self.params, tries, deadline
        )
        if tries > self.settings.max_tries:
            error = ErrorDetail(
                code="too_many_tries",
                message=f"gave up after {self.settings.max_tries} tries (worker lost each time)",
            )
            self._give_up(ctx, job, message_id, raw_job, error)
            return
        self._run(ctx, job, message_id, raw_job)

    def _run(
        self, ctx: JobContext, job: LayoutJob | PlacementJob, message_id: str, raw_job: str
    ) -> None:
        handler = self.handlers[job.kind]
        hard = ctx.deadline + max(self.settings.shutdown_grace_s, 10.0)
        self.leases.hold(Lease(self.name, message_id, hard))
        started = time.time()
        try:
            report = handler.run(ctx, job)
        except REDIS_DOWN:
            raise  # left pending: reclaimed once Redis is back
        except Exception as exc:
            if storage_refused(exc):
                raise  # left pending too: not the job's fault, retried once there is room
            self._failed(ctx, job, message_id, raw_job, exc)
        else:
            seconds = time.time() - started
            latency = started - job.enqueued_at if ctx.tries == 1 else None
            extra = _stats(self.keys, job.kind, "done", seconds, latency)
            ack(self.client, self.keys, message_id, job.job_id, extra)
            log.info(
                "%s %s",
                job.kind,
                report.get("outcome", "done"),
                extra=self._fields(ctx, job, seconds=round(seconds, 3), **report),
            )
        finally:
            self.leases.release(self.name)

    def _failed(
        self,
        ctx: JobContext,
        job: LayoutJob | PlacementJob,
        message_id: str,
        raw_job: str,
        exc: Exception,
    ) -> None:
        error = _error(exc)
        permanent = isinstance(exc, FragmentError)
        fields = self._fields(ctx, job, code=error.code, error=error.message)
        if permanent or ctx.tries >= self.settings.max_tries:
            log.warning("%s failed", job.kind, extra=fields)
            self._give_up(ctx, job, message_id, raw_job, error)
            return
        log.warning(
            "%s failed, retrying",
            job.kind,
            extra=fields,
            exc_info=not isinstance(exc, JigsawError),
        )
        self.handlers[job.kind].failed(ctx, job, error, False)
        retry_later(
            self.client, self.keys, message_id, raw_job, _stats(self.keys, job.kind, "retried")
        )

    def _fields(
        self, ctx: JobContext, job: LayoutJob | PlacementJob, **values: Any
    ) -> dict[str, Any]:
        """The fields of a job's log line: which job, where, which try, then ``values``."""
        where = {"site": job.site_id}
        if isinstance(job, LayoutJob):
            where["fragment"] = job.fragment_id
        return log_fields(job=job.job_id, **where, tries=ctx.tries, consumer=self.name, **values)

    def _give_up(
        self,
        ctx: JobContext,
        job: LayoutJob | PlacementJob,
        message_id: str,
        raw_job: str,
        error: ErrorDetail,
    ) -> None:
        self.handlers[job.kind].failed(ctx, job, error, True)
        letter = self._letter(raw_job, error, ctx.tries)
        extra = _stats(self.keys, job.kind, "failed")
        dead_letter(self.client, self.keys, message_id, job.job_id, letter, extra)

    def _letter(self, raw_job: str, error: ErrorDetail, tries: int) -> DeadLetter:
        return DeadLetter(
            job=raw_job, code=error.code, message=error.message, tries=tries, consumer=self.name
        )


def _stats(
    keys: Keys,
    kind: str,
    outcome: str,
    duration: float | None = None,
    latency: float | None = None,
) -> Extra:
    def extra(pipe: redis.client.Pipeline) -> None:
        record_job(pipe, keys, kind, outcome, duration=duration, latency=latency)

    return extra


class Keeper:
    """Heartbeat and lease keeper of one worker process (runs in its own thread).

    Every period: the worker's heartbeat in ``P:workers``; each running job re-claimed so it
    never looks idle; a job past its hard deadline (its thread is stuck beyond the cooperative
    timeout) makes the process exit, so a supervisor restarts it and the job is reclaimed.
    """

    def __init__(
        self,
        worker_id: str,
        client: redis.Redis,
        settings: Settings,
        leases: LeaseBook,
        stop: threading.Event,
    ) -> None:
        self.worker_id, self.client, self.settings = worker_id, client, settings
        self.leases, self.stop = leases, stop
        self.keys = Keys(settings.key_prefix)
        self.period = min(settings.heartbeat_interval_s, settings.visibility_timeout_s / 3)

    def run(self) -> None:
        """Every period until ``stop`` is set: the heartbeat, the running jobs re-claimed, their
        deadlines checked; now and then the consumers of dead workers pruned."""
        next_prune = time.monotonic() + PRUNE_PERIOD_S
        while not self.stop.wait(self.period):
            self.beat()
            self._check_deadlines()
            if time.monotonic() > next_prune:
                next_prune = time.monotonic() + PRUNE_PERIOD_S
                self.prune_consumers()

    def prune_consumers(self) -> int:
        """Forget group consumers of workers gone for good (no heartbeat, nothing pending).

        Only dead workers' consumers go: deleting a live one could drop a job it just read.
        """
        try:
            alive = set(strings(self.client.zrange(self.keys.workers, 0, -1)))
            consumers: Any = self.client.xinfo_consumers(self.keys.jobs, GROUP)
            dead = [
                c["name"]
                for c in consumers
                if int(c["pending"]) == 0 and str(c["name"]).rsplit("-", 1)[0] not in alive
            ]
            for name in dead:
                self.client.xgroup_delconsumer(self.keys.jobs, GROUP, name)
        except _REDIS_ERRORS as exc:
            log.warning("%s: pruning consumers failed: %s", self.worker_id, exc)
            return 0
        return len(dead)

    def beat(self) -> None:
        """Write the heartbeat and refresh the leases (Redis outages and full storage are
        only logged)."""
        now = time.time()
        try:
            with self.client.pipeline(transaction=False) as pipe:
                pipe.zadd(self.keys.workers, {self.worker_id: now})
                pipe.zremrangebyscore(self.keys.workers, 0, now - 10 * self.settings.worker_alive_s)
                for lease in self.leases.snapshot():
                    pipe.xclaim(
                        self.keys.jobs, GROUP, lease.consumer, 0, [lease.message_id], justid=True
                    )
                pipe.execute()
        except REDIS_DOWN as exc:
            log.warning("%s: heartbeat failed: %s", self.worker_id, exc)
        except redis.ResponseError as exc:
            if not storage_refused(exc):
                raise
            # Full storage refuses every write; this thread must outlive it to beat again.
            log.warning("%s: heartbeat refused, Redis storage full: %s", self.worker_id, exc)

    def leave(self) -> None:
        """Remove the heartbeat (clean shutdown)."""
        with contextlib.suppress(*REDIS_DOWN):
            self.client.zrem(self.keys.workers, self.worker_id)

    def _check_deadlines(self) -> None:
        now = time.monotonic()
        for lease in self.leases.snapshot():
            if now > lease.hard_deadline:
                log.critical(
                    "%s: job entry %s is stuck past its time limit; exiting so it is reclaimed",
                    lease.consumer,
                    lease.message_id,
                )
                logging.shutdown()
                os._exit(HARD_EXIT_CODE)
