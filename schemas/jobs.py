"""Jobs on the Redis stream, and the states of the work they do, as versioned JSON.

A stream entry carries one field, ``job``: the JSON of a :data:`Job`. Never pickle.
"""

from __future__ import annotations

import time
import uuid
from enum import StrEnum
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter

__all__ = [
    "JOB_VERSION",
    "DeadLetter",
    "FragmentState",
    "Job",
    "LayoutJob",
    "PlacementJob",
    "PlacementState",
    "decode_job",
    "encode_job",
]

JOB_VERSION = 1


class FragmentState(StrEnum):
    """Where a fragment's local-layout job is."""

    QUEUED = "queued"
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"


class PlacementState(StrEnum):
    """Where a site's global placement is."""

    IDLE = "idle"
    QUEUED = "queued"
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"


def _new_id() -> str:
    return uuid.uuid4().hex


class _Job(BaseModel):
    model_config = ConfigDict(frozen=True, extra="ignore")

    version: Literal[1] = 1
    job_id: str = Field(default_factory=_new_id, description="stable across retries")
    site_id: str
    enqueued_at: float = Field(default_factory=time.time, description="unix time, seconds")


class LayoutJob(_Job):
    """Estimate one fragment's local layout from its stored bytes."""

    kind: Literal["layout"] = "layout"
    fragment_id: str
    sha256: str = Field(description="the bytes this job is for; other bytes make it stale")


class PlacementJob(_Job):
    """Place every laid-out fragment of a site (coalesced: one queued or running per site)."""

    kind: Literal["placement"] = "placement"


Job = Annotated[LayoutJob | PlacementJob, Field(discriminator="kind")]
_JOB = TypeAdapter(Job)


def encode_job(job: LayoutJob | PlacementJob) -> str:
    """The JSON of a job, as stored in the stream's ``job`` field."""
    return job.model_dump_json()


def decode_job(text: str | bytes) -> LayoutJob | PlacementJob:
    """Parse a job; raises :class:`pydantic.ValidationError` on an unknown kind or version."""
    return _JOB.validate_json(text)


class DeadLetter(BaseModel):
    """An entry of the dead-letter stream: a job given up on, and why."""

    model_config = ConfigDict(frozen=True)

    version: Literal[1] = 1
    job: str = Field(description="the job's JSON as it was on the stream")
    code: str
    message: str
    tries: int
    consumer: str
    failed_at: float = Field(default_factory=time.time)
