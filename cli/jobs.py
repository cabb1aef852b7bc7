"""``jigsaw jobs``: the dead-letter stream of the service's Redis, listed or retried."""

from __future__ import annotations

import json
import sys
from datetime import UTC, datetime

import redis

from schemas.settings import get_settings
from store.dead_letters import DeadJob, list_dead, retry_dead
from store.keys import Keys

__all__ = ["run_jobs"]


def _describe(dead: DeadJob) -> dict[str, object]:
    job, letter = dead.job, dead.letter
    return {
        "id": dead.entry_id,
        "kind": job.kind if job else None,
        "site_id": job.site_id if job else None,
        "fragment_id": getattr(job, "fragment_id", None),
        "tries": letter.tries,
        "code": letter.code,
        "message": letter.message,
        "failed_at": datetime.fromtimestamp(letter.failed_at, UTC).isoformat(),
    }


def _line(row: dict[str, object]) -> str:
    where = "/".join(str(row[k]) for k in ("site_id", "fragment_id") if row[k] is not None)
    return (
        f"{row['id']}  {row['kind'] or '?'} {where or '-'}  tries {row['tries']}  "
        f"{row['failed_at']}  {row['code']}: {row['message']}"
    )


def run_jobs(retry: list[str], retry_all: bool, as_json: bool) -> int:
    """List dead letters, or retry the given ones (or all); returns the exit code."""
    settings = get_settings()
    if settings.redis_url is None:
        print("jigsaw jobs: set FPJ_REDIS_URL to the service's Redis", file=sys.stderr)
        return 2
    client = redis.Redis.from_url(settings.redis_url, decode_responses=True)
    keys = Keys(settings.key_prefix)
    try:
        if retry or retry_all:
            ids = (
                [d.entry_id for d in list_dead(client, keys, count=10_000)] if retry_all else retry
            )
            outcomes = {entry: retry_dead(client, keys, settings, entry) for entry in ids}
            for entry, outcome in outcomes.items():
                print(
                    json.dumps({"id": entry, "retry": outcome})
                    if as_json
                    else f"{entry}: {outcome}"
                )
            return 2 if "not_found" in outcomes.values() else 0
        rows = [_describe(dead) for dead in list_dead(client, keys, count=10_000)]
        for row in rows:
            print(json.dumps(row) if as_json else _line(row))
        if not as_json:
            print(f"{len(rows)} dead job(s)", file=sys.stderr)
        return 0
    finally:
        client.close()
