"""Every HTTP route fuzzed from the service's own OpenAPI schema (schemathesis).

The real app on uvicorn over HTTP, real Redis (database 15), one real worker process (so
hints and uploads get placed, and the result routes see real results), bearer tokens on.
Per operation: schema-valid and schema-invalid requests, upload bodies from
:func:`tests.fuzzing.fragment_bodies` (mutated PLY, PCD and frame zips); then a stateful
run that follows the links schemathesis infers (upload -> status, result, delete ...).
Every reply passes schemathesis' checks (no 5xx, documented status codes and content
types, response schemas, auth enforced, invalid data refused) and the contract's error
shape (:func:`tests.fuzzing.error_shape`). The event stream, which never ends, is fuzzed
apart: one event read per request.

Short profile (``make test``); ``bench/fuzz_http.py`` runs the long one.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import httpx
import pytest
import redis
import schemathesis
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from hypothesis.errors import FlakyStrategyDefinition
from schemathesis.specs.openapi.checks import positive_data_acceptance

from api.main import create_app
from tests.fuzzing import (
    FUZZ_TOKEN,
    ID_PATTERN,
    STREAMING_PATHS,
    error_shape,
    error_shape_problem,
    load_http_schema,
    operation_cases,
)
from tests.service_fixtures import (
    ApiServer,
    Workers,
    make_settings,
    wait_workers_alive,
)

pytestmark = pytest.mark.timeout(120)

# Bodies that are schema-valid (any bytes, any hints-shaped JSON) are still refused when
# their content is wrong; that is the point of them, so the acceptance check is off.
EXCLUDED_CHECKS: list[schemathesis.CheckFunction] = [positive_data_acceptance]
FUZZ_PREFIX = "fpjfuzz"  # keys apart from other tests' data on the shared database
SHORT = settings(
    max_examples=25,
    derandomize=True,
    database=None,
    deadline=None,
    suppress_health_check=list(HealthCheck),
)


@pytest.fixture(scope="module")
def fuzz_server(redis7_url: str) -> Iterator[ApiServer]:
    """API with a token and one worker on database 15, its keys under their own prefix."""
    client = redis.Redis.from_url(redis7_url)
    _forget(client)
    config = make_settings(redis7_url, tokens=[FUZZ_TOKEN], key_prefix=FUZZ_PREFIX)
    workers = Workers()
    workers.start(config, count=1)
    server = ApiServer(config).start()
    try:
        wait_workers_alive(client, FUZZ_PREFIX, 1)
        yield server
    finally:
        server.stop()
        workers.stop()
        _forget(client)
        client.close()


def _forget(client: redis.Redis) -> None:
    """Delete the fuzzed service's keys (only those: the database is shared)."""
    for key in client.scan_iter(f"{FUZZ_PREFIX}:*", count=1000):
        client.delete(key)


@pytest.fixture(scope="module")
def http_schema(fuzz_server: ApiServer) -> schemathesis.BaseSchema:
    return load_http_schema(fuzz_server.url)


def _operations() -> list[tuple[str, str]]:
    """(method, path) of every operation, from the app's schema (no server needed)."""
    raw = create_app(make_settings("redis://127.0.0.1:1/0")).openapi()
    return [
        (method.upper(), path)
        for path, item in raw["paths"].items()
        for method in item
        if path not in STREAMING_PATHS
    ]


@pytest.mark.parametrize(("method", "path"), _operations())
def test_route(http_schema: schemathesis.BaseSchema, method: str, path: str) -> None:
    """Schema-valid and schema-invalid requests of one operation."""
    operation = http_schema[path][method]

    @SHORT
    @given(case=operation_cases(operation))
    def fuzz(case: schemathesis.Case[Any]) -> None:
        case.call_and_validate(additional_checks=[error_shape], excluded_checks=EXCLUDED_CHECKS)

    fuzz()


def test_stateful(http_schema: schemathesis.BaseSchema) -> None:
    """Sequences along the inferred links: upload then status, result, hints, delete.

    Failures are collected, not raised: a sequence replayed against a server whose state
    moved on draws differently, which hypothesis would report as a flaky strategy instead
    of the failure; for the same reason a divergence ends the run quietly.
    """
    finite = http_schema.exclude(path=list(STREAMING_PATHS))
    failures: list[str] = []

    class Machine(finite.as_state_machine()):  # type: ignore[misc]
        def validate_response(self, response, case, additional_checks=None, **kwargs):
            try:
                case.validate_response(
                    response,
                    additional_checks=[error_shape],
                    excluded_checks=EXCLUDED_CHECKS,
                    transport_kwargs=kwargs or None,
                    recorder=self.recorder,
                )
            except Exception as exc:  # a FailureGroup, with the request to reproduce it
                failures.append(str(exc))

    steps = settings(SHORT, max_examples=15, stateful_step_count=6, phases=[Phase.generate])
    with contextlib.suppress(FlakyStrategyDefinition):
        Machine.run(settings=steps)
    assert not failures, "\n\n".join(failures[:3])


_AUTH = st.sampled_from(["header", "query", "none", "wrong"])


@SHORT
@given(site=st.from_regex(ID_PATTERN, fullmatch=True) | st.text(max_size=70), auth=_AUTH)
def test_event_stream(fuzz_server: ApiServer, site: str, auth: str) -> None:
    """Any site id and any way of (not) giving the token: an error in the contract's shape,
    or a stream whose first event is the site's ``status``."""
    headers = {"Authorization": f"Bearer {FUZZ_TOKEN}"} if auth == "header" else {}
    params = {"access_token": FUZZ_TOKEN if auth == "query" else "nope"}
    escaped = "".join(f"%{byte:02X}" for byte in site.encode())  # every byte, "/" and "." too
    url = f"{fuzz_server.url}/v1/sites/{escaped}/events"
    with (
        httpx.Client(timeout=10) as http,
        http.stream("GET", url, headers=headers, params=params if auth != "none" else {}) as reply,
    ):
        if reply.status_code != 200:
            body = reply.read()
            problem = error_shape_problem(
                reply.status_code, reply.headers.get("content-type", ""), body
            )
            assert problem is None, problem
            assert reply.status_code in (400, 401, 403, 404), reply.status_code
            return
        assert auth in ("header", "query")
        assert reply.headers["content-type"].startswith("text/event-stream")
        lines = reply.iter_lines()
        assert next(line for line in lines if line.startswith("event:")) == "event: status"
