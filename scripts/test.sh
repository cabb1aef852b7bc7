#!/usr/bin/env bash
# The one test command: lint, type check, layering, then the test suite against the real Redis.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=.venv/bin
if ! redis-cli -h 127.0.0.1 -p 6379 ping >/dev/null 2>&1; then
    if command -v redis-server >/dev/null 2>&1; then
        echo "starting redis-server on 127.0.0.1:6379" >&2
        redis-server --daemonize yes --bind 127.0.0.1 --port 6379 --save "" --appendonly no >/dev/null
        for _ in $(seq 50); do redis-cli ping >/dev/null 2>&1 && break; sleep 0.1; done
    fi
fi
$BIN/ruff check .
$BIN/mypy .
$BIN/lint-imports  # the layering contracts in pyproject.toml
$BIN/pytest -q "$@"
