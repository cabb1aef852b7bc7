"""``/healthz`` (the process serves) and ``/readyz`` (Redis reachable, workers alive)."""

from __future__ import annotations

from fastapi import APIRouter

from api.deps import BackendDep
from api.errors import UnavailableError, error_responses
from api.site_data import live_workers
from schemas.service import HealthReply, ReadyReply

__all__ = ["router"]

router = APIRouter(tags=["health"])


@router.get("/healthz", summary="Liveness: the API accepts requests")
async def healthz() -> HealthReply:
    return HealthReply()


@router.get(
    "/readyz",
    summary="Readiness: Redis answers and a worker is alive",
    responses=error_responses(503),
)
async def readyz(backend: BackendDep) -> ReadyReply:
    await backend.redis.ping()
    workers = await live_workers(backend)
    if workers == 0:
        raise UnavailableError("no worker has sent a heartbeat recently")
    return ReadyReply(workers=workers)
