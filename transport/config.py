"""The one place a ``zenoh.Config`` is built, for the service and for robot-side commands."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Literal

import zenoh

from schemas.settings import Settings

__all__ = ["ZenohOptions", "build_config", "service_options"]

Mode = Literal["peer", "client", "router"]


@dataclass(frozen=True)
class ZenohOptions:
    """What a session is configured from.

    ``listen`` empty: the session opens no listening port (robots). ``max_message_bytes``
    None: zenoh's default (1 GiB).
    """

    mode: Mode = "peer"
    listen: list[str] = field(default_factory=list)
    connect: list[str] = field(default_factory=list)
    multicast_scouting: bool = False
    max_message_bytes: int | None = None


def service_options(settings: Settings) -> ZenohOptions:
    """The service's session options from its settings (``FPJ_ZENOH_*``)."""
    return ZenohOptions(
        mode=settings.zenoh_mode,
        listen=settings.zenoh_listen_endpoints,
        connect=settings.zenoh_connect_endpoints,
        multicast_scouting=settings.zenoh_multicast_scouting,
        max_message_bytes=settings.zenoh_rx_max_message_size,
    )


def build_config(options: ZenohOptions) -> zenoh.Config:
    """A ``zenoh.Config`` for ``options``.

    Clients never listen (zenoh rejects listen endpoints in client mode), so ``listen`` is
    ignored there. Gossip scouting keeps zenoh's default (on), so peers that reach the
    service learn about each other.
    """
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(options.mode))
    listen = [] if options.mode == "client" else options.listen
    config.insert_json5("listen/endpoints", json.dumps(listen))
    config.insert_json5("connect/endpoints", json.dumps(options.connect))
    config.insert_json5("scouting/multicast/enabled", json.dumps(options.multicast_scouting))
    if options.max_message_bytes is not None:
        size = json.dumps(options.max_message_bytes)
        config.insert_json5("transport/link/rx/max_message_size", size)
    return config
