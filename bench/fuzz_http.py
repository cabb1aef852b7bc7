"""Long fuzzing profile of the HTTP API (not a test): every route from the OpenAPI schema.

Starts a private Redis, `jigsaw serve` (real uvicorn, bearer token on, zenoh off) and one
`jigsaw worker`, then sends schemathesis cases to every operation (schema-valid and
schema-invalid, upload bodies from mutated PLY/PCD/frame zips), a stateful run along the
inferred links and a fuzz of the event stream, and prints per route: requests, 5xx,
responses that break the schema or the contract's error shape, and the status codes seen.
The short profile of the same checks runs in ``make test`` (tests/api/test_fuzz_http.py).

    .venv/bin/python bench/fuzz_http.py --examples 300 --seed 1

Everything runs on this machine, against loopback only; the run is bounded by ``--examples``.
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
from hypothesis import HealthCheck, Phase, given, seed, settings
from hypothesis import strategies as st
from hypothesis.errors import FlakyStrategyDefinition

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.service_load import Service  # noqa: E402
from tests.fuzzing import (  # noqa: E402
    FUZZ_TOKEN,
    ID_PATTERN,
    STREAMING_PATHS,
    error_shape,
    error_shape_problem,
    load_http_schema,
    operation_cases,
)


@dataclass
class Row:
    """What one route got and answered."""

    requests: int = 0
    server_errors: int = 0
    violations: int = 0
    statuses: collections.Counter[int] = field(default_factory=collections.Counter)
    examples: list[str] = field(default_factory=list)

    def record(self, status: int, problems: list[str]) -> None:
        """Count one answer of the route, and what was wrong with it."""
        self.requests += 1
        self.statuses[status] += 1
        self.server_errors += status >= 500
        broken = [p for p in problems if "Server error" not in p]
        self.violations += bool(broken)
        if (broken or status >= 500) and len(self.examples) < 3:
            self.examples.append(f"{status}: {'; '.join(problems)[:300]}")


class FuzzedService(Service):
    """The load benchmark's private service, with a bearer token and zenoh off."""

    def _env(self, zenoh_listen: str = "none") -> dict[str, str]:
        env = super()._env(zenoh_listen)
        env.update(FPJ_TOKENS=FUZZ_TOKEN, FPJ_ZENOH_LISTEN="none", FPJ_MIN_POINTS="100")
        return env


def _problems(exc: BaseException) -> list[str]:
    inner = getattr(exc, "exceptions", None) or [exc]
    return [str(getattr(e, "title", "") or e).splitlines()[0] for e in inner]


def _settings(examples: int) -> settings:
    return settings(
        max_examples=examples,
        database=None,
        deadline=None,
        phases=[Phase.explicit, Phase.generate],
        suppress_health_check=list(HealthCheck),
    )


def fuzz_operation(operation: Any, examples: int, run_seed: int, row: Row) -> None:
    """Send ``examples`` cases of one operation; record every reply in ``row``."""
    from schemathesis.specs.openapi.checks import positive_data_acceptance

    @seed(run_seed)
    @_settings(examples)
    @given(case=operation_cases(operation))
    def run(case: Any) -> None:
        response = case.call()
        try:
            case.validate_response(
                response,
                additional_checks=[error_shape],
                excluded_checks=[positive_data_acceptance],
            )
        except Exception as exc:  # a FailureGroup: record, keep going
            row.record(response.status_code, _problems(exc))
            return
        row.record(response.status_code, [])

    run()


def fuzz_stateful(schema: Any, examples: int, run_seed: int, row: Row) -> None:
    """Sequences along the links schemathesis infers (upload -> status, result, delete)."""
    from schemathesis.specs.openapi.checks import positive_data_acceptance

    class Machine(schema.exclude(path=list(STREAMING_PATHS)).as_state_machine()):  # type: ignore[misc]
        def validate_response(self, response, case, additional_checks=None, **kwargs):
            try:
                case.validate_response(
                    response,
                    additional_checks=[error_shape],
                    excluded_checks=[positive_data_acceptance],
                    recorder=self.recorder,
                )
            except Exception as exc:
                row.record(response.status_code, _problems(exc))
                return
            row.record(response.status_code, [])

    config = settings(_settings(examples), stateful_step_count=8, derandomize=True)
    try:
        Machine.run(settings=config)
    except FlakyStrategyDefinition:  # the server's state moved on under a replay: stop here
        row.examples.append("stopped early: a sequence drew differently on replay")


def fuzz_events(base_url: str, examples: int, run_seed: int, row: Row) -> None:
    """The never-ending event stream: read the first event (or the error) of each request."""

    @seed(run_seed)
    @_settings(examples)
    @given(
        site=st.from_regex(ID_PATTERN, fullmatch=True) | st.text(max_size=70),
        auth=st.sampled_from(["header", "query", "none", "wrong"]),
    )
    def run(site: str, auth: str) -> None:
        headers = {"Authorization": f"Bearer {FUZZ_TOKEN}"} if auth == "header" else {}
        params = {"access_token": FUZZ_TOKEN if auth == "query" else "nope"}
        escaped = "".join(f"%{byte:02X}" for byte in site.encode())
        url = f"{base_url}/v1/sites/{escaped}/events"
        with (
            httpx.Client(timeout=10) as http,
            http.stream("GET", url, headers=headers, params=params) as reply,
        ):
            if reply.status_code != 200:
                kind = reply.headers.get("content-type", "")
                problem = error_shape_problem(reply.status_code, kind, reply.read())
                row.record(reply.status_code, [problem] if problem else [])
                return
            first = next((x for x in reply.iter_lines() if x.startswith("event:")), "")
            row.record(200, [] if first == "event: status" else [f"first event {first!r}"])

    run()


def main() -> None:
    """Fuzz the API (command-line options: see ``--help``) and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--examples", type=int, default=300, help="cases per operation")
    parser.add_argument("--stateful", type=int, default=100, help="stateful sequences")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    service = FuzzedService(workers=1, concurrency=1)
    rows: dict[str, Row] = collections.defaultdict(Row)
    started = time.monotonic()
    service.start()
    try:
        schema = load_http_schema(service.url)
        for result in schema.get_all_operations():
            operation = result.ok()
            if operation.path in STREAMING_PATHS:
                fuzz_events(service.url, args.examples, args.seed, rows[operation.label])
            else:
                fuzz_operation(operation, args.examples, args.seed, rows[operation.label])
        fuzz_stateful(schema, args.stateful, args.seed, rows["stateful sequences"])
    finally:
        service.stop()
    _print(rows, time.monotonic() - started)


def _print(rows: dict[str, Row], seconds: float) -> None:
    print(f"\n{'route':58} {'requests':>8} {'5xx':>5} {'violations':>10}  statuses")
    for label, row in rows.items():
        statuses = " ".join(f"{s}:{n}" for s, n in sorted(row.statuses.items()))
        print(
            f"{label:58} {row.requests:8d} {row.server_errors:5d} {row.violations:10d}  {statuses}"
        )
    total = sum(r.requests for r in rows.values())
    errors = sum(r.server_errors for r in rows.values())
    broken = sum(r.violations for r in rows.values())
    print(f"{'total':58} {total:8d} {errors:5d} {broken:10d}  ({seconds:.0f} s)")
    for label, row in rows.items():
        for example in row.examples:
            print(f"  {label}: {example}")


if __name__ == "__main__":
    main()
