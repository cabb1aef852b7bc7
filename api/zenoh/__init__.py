"""The zenoh front end: robots send fragments and receive poses over zenoh (contract 5).

Importing this package does not import zenoh; :func:`zenoh_front_end` does, and only when
``FPJ_ZENOH_LISTEN`` is not ``none``.

Key expressions (prefix ``fpj``, ``FPJ_ZENOH_PREFIX``) are listed in :mod:`transport.keys`.
Robots:

- send a fragment with a query on ``fpj/sites/{site}/fragments/{fragment}`` whose payload is
  the file; the reply is the HTTP PUT's JSON (``created`` false: the same bytes were already
  stored), or an error reply with the HTTP error body ``{"error": {"code", "message"}}``.
  A put on the same key ingests too, without any reply;
- may name themselves in the query's or put's attachment, UTF-8 JSON
  ``{"robot_id": "r1"}`` (a query may use the parameter ``?robot_id=r1`` instead), and
  declare the liveliness token ``fpj/robots/{robot_id}`` while connected: the site status
  (``GET /v1/sites/{site}``, field ``robots``) lists connected robots and the fragments each
  sent. With ``FPJ_TOKENS`` set the attachment must also carry ``"token"``;
- may add what they know of the fragment's pose to the attachment,
  ``"prior": {"pose", "sigma_xy", "sigma_yaw_deg"}``: it becomes the fragment's entry of the
  site's hints (``GET /v1/sites/{site}/hints``) and the site is placed again; an invalid
  prior gets the error ``invalid_prior`` and nothing is stored;
- should query ``fpj/service`` first: a message larger than ``max_message_bytes`` is dropped
  by zenoh without any reply, one over ``max_upload_bytes`` gets ``fragment_too_large``;
- subscribe to ``fpj/sites/{site}/poses/*`` (PoseUpdate: pose, the result's status and its
  confidence) and ``fpj/sites/{site}/result``, and query the latter for the latest result
  when they join late.

ROS 2 robots on rmw_zenoh need none of this: see :mod:`api.zenoh.ros_bridge`.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING

from store.backend import Backend

if TYPE_CHECKING:
    from api.zenoh.front import ZenohFront

__all__ = ["zenoh_front_end"]


@asynccontextmanager
async def zenoh_front_end(backend: Backend) -> AsyncIterator[ZenohFront | None]:
    """Run the zenoh front end for the duration of the block (None when it is off).

    Raises
    ------
    zenoh.ZError
        The session cannot be opened (e.g. the listen port is taken).
    """
    if not backend.settings.zenoh_enabled:
        yield None
        return
    from api.zenoh.front import ZenohFront

    front = await ZenohFront.start(backend)
    try:
        yield front
    finally:
        await front.stop()
