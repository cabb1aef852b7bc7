"""The dead-letter stream ``P:jobs:dead``: list the jobs given up on, and retry them.

A job lands there after ``max_tries`` deliveries that crashed (or at once when its input is
refused for good, or when it cannot be decoded). Retrying takes its entry off the stream and
queues the job again with a fresh try count: a layout job when its fragment still holds the
same bytes (the fragment is ``queued`` again, its error cleared), a placement job as a new
placement request of its site (coalesced as usual). A job whose fragment or site is gone is
``stale``: its letter is dropped, nothing is queued. ``jigsaw jobs`` is the front end.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import redis
from pydantic import ValidationError

from schemas.jobs import DeadLetter, FragmentState, LayoutJob, PlacementJob, decode_job
from schemas.settings import Settings
from store.connection import hash_fields, record, watch
from store.jobs import request_placement
from store.keys import Keys
from store.records import error_fields

__all__ = ["DeadJob", "list_dead", "retry_dead"]


@dataclass(frozen=True)
class DeadJob:
    """One entry of the dead-letter stream: its stream id, the letter and its job (None when
    the job itself could not be decoded)."""

    entry_id: str
    letter: DeadLetter
    job: LayoutJob | PlacementJob | None


def _dead_job(entry: Any) -> DeadJob:
    """A stream entry ``(id, {"dead": letter JSON})`` of a client with string replies."""
    entry_id, fields = str(entry[0]), dict(entry[1] or {})
    letter = DeadLetter.model_validate_json(fields["dead"])
    try:
        job: LayoutJob | PlacementJob | None = decode_job(letter.job)
    except ValidationError:
        job = None
    return DeadJob(entry_id, letter, job)


def list_dead(client: redis.Redis, keys: Keys, count: int = 100) -> list[DeadJob]:
    """The oldest ``count`` dead letters (a client with ``decode_responses=True``)."""
    entries: Any = client.xrange(keys.dead, count=count)
    return [_dead_job(entry) for entry in entries or []]


def retry_dead(client: redis.Redis, keys: Keys, settings: Settings, entry_id: str) -> str:
    """Queue a dead job again and take its letter off the stream.

    Returns
    -------
    str
        ``"queued"``, ``"stale"`` (its fragment or site is gone or holds other bytes: the
        letter is dropped), ``"undecodable"`` (kept: nothing to run) or ``"not_found"``.
    """
    try:
        entries: Any = client.xrange(keys.dead, entry_id, entry_id)
    except redis.ResponseError:  # not a stream id at all
        return "not_found"
    if not entries:
        return "not_found"
    dead = _dead_job(entries[0])
    if dead.job is None:
        return "undecodable"
    client.delete(keys.tries(dead.job.job_id))
    if isinstance(dead.job, PlacementJob):
        queued = request_placement(client, keys, settings, dead.job.site_id) > 0
    else:
        queued = _requeue_layout(client, keys, dead.job, dead.letter.job)
    client.xdel(keys.dead, entry_id)
    return "queued" if queued else "stale"


def _requeue_layout(client: redis.Redis, keys: Keys, job: LayoutJob, raw_job: str) -> bool:
    """Mark the fragment queued and put its job back, unless its bytes changed meanwhile."""
    fragment = keys.fragment(job.site_id, job.fragment_id)
    with client.pipeline(transaction=True) as pipe:
        while True:
            try:
                watch(pipe, fragment)
                if record(pipe.hgetall(fragment)).get("sha256") != job.sha256:
                    pipe.reset()
                    return False
                pipe.multi()
                queued = FragmentState.QUEUED.value
                fields = {"state": queued, "stage": queued, "progress": "0"}
                pipe.hset(fragment, mapping=hash_fields({**fields, **error_fields("", "")}))
                pipe.xadd(keys.jobs, {"job": raw_job})
                pipe.execute()
                return True
            except redis.WatchError:
                continue
