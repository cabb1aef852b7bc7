"""The one place a ``zenoh.Config`` is built, for the service and for robot-side commands."""

from __future__ import annotations

import ipaddress
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import zenoh

from schemas.settings import Settings
from transport.acl import RosTopics, access_control
from transport.keys import ZenohKeys

__all__ = [
    "TlsOptions",
    "ZenohOptions",
    "build_config",
    "reachable_from_network",
    "service_options",
]

Mode = Literal["peer", "client", "router"]


@dataclass(frozen=True)
class TlsOptions:
    """PEM files of ``tls/`` links (zenoh's ``transport/link/tls``).

    ``root_ca``: the CA that signed the other side's certificate (a robot: the service's; the
    service with ``mtls``: its peers'). ``certificate`` and ``private_key``: this side's, shown
    on listening endpoints and, with ``mtls``, when connecting. ``mtls``: both sides show a
    certificate; a listener refuses peers without one signed by ``root_ca``.
    """

    root_ca: Path | None = None
    certificate: Path | None = None
    private_key: Path | None = None
    mtls: bool = False

    def section(self) -> dict[str, Any]:
        """The ``transport/link/tls`` section of zenoh's config (this side's files, both ways)."""
        tls: dict[str, Any] = {"enable_mtls": self.mtls}
        if self.root_ca is not None:
            tls["root_ca_certificate"] = str(self.root_ca)
        if self.certificate is not None and self.private_key is not None:
            for side in ("listen", "connect"):
                tls[f"{side}_certificate"] = str(self.certificate)
                tls[f"{side}_private_key"] = str(self.private_key)
        return tls


@dataclass(frozen=True)
class ZenohOptions:
    """What a session is configured from.

    ``listen`` empty: the session opens no listening port (robots). ``max_message_bytes``
    None: zenoh's default (1 GiB). ``user`` and ``password``: this side's credentials when
    it opens a session with a peer that checks them (``transport/auth/usrpwd``);
    ``users_file``: ``user:password`` lines, the credentials peers opening a session with
    this one must give. ``access_control``: zenoh's section (:mod:`transport.acl`).
    """

    mode: Mode = "peer"
    listen: list[str] = field(default_factory=list)
    connect: list[str] = field(default_factory=list)
    multicast_scouting: bool = False
    max_message_bytes: int | None = None
    tls: TlsOptions | None = None
    user: str | None = None
    password: str | None = None
    users_file: Path | None = None
    access_control: dict[str, Any] | None = None


def _ros_topics(settings: Settings) -> RosTopics:
    inputs = dict(settings.ros_cloud_topics())
    for depth in settings.ros_depth_topics():
        inputs |= {depth.image: depth.site_id, depth.camera_info: depth.site_id}
    outputs = (
        settings.zenoh_ros_pose_topic,
        settings.zenoh_ros_tf_topic,
        settings.zenoh_ros_map_topic,
    )
    return RosTopics(settings.zenoh_ros_domain_id, inputs, tuple(t for t in outputs if t))


def service_options(settings: Settings) -> ZenohOptions:
    """The service's session options from its settings (``FPJ_ZENOH_*``)."""
    tls = TlsOptions(
        root_ca=settings.zenoh_tls_root_ca,
        certificate=settings.zenoh_tls_certificate,
        private_key=settings.zenoh_tls_private_key,
        mtls=settings.zenoh_tls_mtls,
    )
    acl = None
    if settings.zenoh_acl:
        acl = access_control(
            ZenohKeys(settings.zenoh_prefix),
            settings.zenoh_acl,
            by_certificate=settings.zenoh_tls_mtls,
            by_user=settings.zenoh_users_file is not None,
            ros=_ros_topics(settings) if settings.ros_enabled else None,
        )
    password = settings.zenoh_password
    return ZenohOptions(
        mode=settings.zenoh_mode,
        listen=settings.zenoh_listen_endpoints,
        connect=settings.zenoh_connect_endpoints,
        multicast_scouting=settings.zenoh_multicast_scouting,
        max_message_bytes=settings.zenoh_rx_max_message_size,
        tls=tls if tls != TlsOptions() else None,
        user=settings.zenoh_user,
        password=password.get_secret_value() if password is not None else None,
        users_file=settings.zenoh_users_file,
        access_control=acl,
    )


_LOCAL_PROTOCOLS = ("unixsock-stream", "unixpipe", "vsock", "serial")


def reachable_from_network(endpoint: str) -> bool:
    """True unless ``endpoint`` is on loopback or a local-only link (a warning's test).

    >>> [reachable_from_network(e) for e in ("tcp/127.0.0.1:7447", "tcp/[::1]:1", "tls/0.0.0.0:1")]
    [False, False, True]
    """
    protocol, _, address = endpoint.partition("/")
    if protocol in _LOCAL_PROTOCOLS:
        return False
    host = address.split("#")[0].split("?")[0].rsplit(":", 1)[0].strip("[]")
    if host == "localhost":
        return False
    try:
        return not ipaddress.ip_address(host).is_loopback
    except ValueError:  # a host name: whatever it resolves to
        return True


def _usrpwd(options: ZenohOptions) -> dict[str, str]:
    fields = {"user": options.user, "password": options.password}
    if options.users_file is not None:
        fields["dictionary_file"] = str(options.users_file)
    return {k: v for k, v in fields.items() if v is not None}


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
    if options.tls is not None:
        config.insert_json5("transport/link/tls", json.dumps(options.tls.section()))
    if usrpwd := _usrpwd(options):
        config.insert_json5("transport/auth/usrpwd", json.dumps(usrpwd))
    if options.access_control is not None:
        config.insert_json5("access_control", json.dumps(options.access_control))
    return config
