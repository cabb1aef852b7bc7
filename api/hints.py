"""A site's hints (contract section 2) in Redis: parse, read, replace, merge one prior.

Shared by the HTTP routes (``PUT``/``GET /v1/sites/{site}/hints``) and the zenoh front end
(a fragment's attachment ``prior``). Hints are stored whole, as HintsModel JSON under
``P:site:S:hints``. Storing them creates the site if it is new (as an upload does), so a fleet
may say what it knows before the first scan arrives; hints naming fragments the site does not
have yet are kept. Every change has the site placed again (coalesced as usual); the placement
job reads the hints when it runs.
"""

from __future__ import annotations

import logging
import time

import redis
from pydantic import ValidationError

from api.errors import InvalidHintsError, InvalidPriorError
from api.site_data import touch_site
from schemas.hints import FragmentPrior, HintsModel
from schemas.validation import summarize_errors
from store.backend import Backend
from store.connection import abort_watch, begin_multi
from store.jobs import request_placement_async

__all__ = [
    "MAX_HINTS_BYTES",
    "load_hints",
    "merge_prior",
    "parse_hints",
    "parse_prior",
    "replace_hints",
]

log = logging.getLogger(__name__)

MAX_HINTS_BYTES = 1_000_000  # a few thousand prior poses; larger bodies get hints_too_large


def parse_hints(data: bytes | str) -> HintsModel:
    """Validate a hints JSON document.

    Raises
    ------
    InvalidHintsError
        Not JSON, unknown fields, invalid ids or poses (the message lists what is wrong).
    """
    try:
        return HintsModel.model_validate_json(data)
    except ValidationError as exc:
        raise InvalidHintsError(f"invalid hints: {summarize_errors(exc.errors())}") from exc


def parse_prior(value: object) -> FragmentPrior:
    """Validate one fragment's prior (``{"pose", "sigma_xy", "sigma_yaw_deg"}``).

    Raises
    ------
    InvalidPriorError
        Not an object with a rigid 4x4 pose and positive deviations, or unknown fields.
    """
    try:
        return FragmentPrior.model_validate(value)
    except ValidationError as exc:
        raise InvalidPriorError(f"invalid prior: {summarize_errors(exc.errors())}") from exc


def _stored(site_id: str, raw: bytes | str | None) -> HintsModel | None:
    if raw is None:
        return None
    try:
        return HintsModel.model_validate_json(raw)
    except ValidationError as exc:  # written by a newer version: not ours to read
        log.warning("site %s: stored hints are not valid here: %s", site_id, exc)
        return None


async def load_hints(backend: Backend, site_id: str) -> HintsModel | None:
    """The site's stored hints, if any."""
    return _stored(site_id, await backend.redis.get(backend.keys.hints(site_id)))


async def replace_hints(backend: Backend, site_id: str, hints: HintsModel) -> None:
    """Store ``hints`` in place of the site's earlier ones (creating the site if new) and have
    the site placed again."""
    keys = backend.keys
    async with backend.redis.pipeline(transaction=True) as pipe:
        pipe.set(keys.hints(site_id), hints.model_dump_json())
        touch_site(pipe, keys, site_id, time.time())
        await pipe.execute()
    await request_placement_async(backend.redis, keys, backend.settings, site_id)


async def merge_prior(
    backend: Backend, site_id: str, fragment_id: str, prior: FragmentPrior
) -> bool:
    """Make ``prior`` the fragment's entry of the site's hints (the rest stays as it is).

    Returns
    -------
    bool
        True when the hints changed (the site is then placed again), False when the same
        prior was already stored.
    """
    keys, key = backend.keys, backend.keys.hints(site_id)
    async with backend.redis.pipeline(transaction=True) as pipe:
        while True:
            try:
                await pipe.watch(key)
                current = _stored(site_id, await pipe.get(key)) or HintsModel()
                if current.fragments.get(fragment_id) == prior:
                    await abort_watch(pipe)
                    return False
                fragments = {**current.fragments, fragment_id: prior}
                merged = current.model_copy(update={"fragments": fragments})
                begin_multi(pipe)
                pipe.set(key, merged.model_dump_json())
                touch_site(pipe, keys, site_id, time.time())
                await pipe.execute()
                break
            except redis.WatchError:
                continue
    await request_placement_async(backend.redis, keys, backend.settings, site_id)
    return True
