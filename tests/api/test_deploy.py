"""Deployment files (no Docker engine here): structure checks, and the compose topology
(Redis, `jigsaw serve` without workers, N `jigsaw worker`) started as plain processes, with
the compose health checks run against them."""

from __future__ import annotations

import shlex
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import httpx
import pytest
import redis
import yaml

from services.point_io import encode_ply
from services.synthetic import SyntheticScene
from tests.service_fixtures import (
    ROOT,
    RedisProcess,
    free_port,
    make_settings,
    settings_env,
    wait_result,
    wait_until,
    wait_workers_alive,
)

pytestmark = pytest.mark.timeout(120)

COMPOSE = ROOT / "docker-compose.yml"
K8S = ROOT / "deploy" / "k8s"


def _compose() -> dict[str, Any]:
    data: dict[str, Any] = yaml.safe_load(COMPOSE.read_text())
    return data


def _k8s_docs() -> list[dict[str, Any]]:
    return [
        doc
        for path in sorted(K8S.glob("*.yaml"))
        if path.name != "kustomization.yaml"
        for doc in yaml.safe_load_all(path.read_text())
        if doc
    ]


def test_compose_structure() -> None:
    services = _compose()["services"]
    assert set(services) == {"redis", "api", "worker"}
    redis_svc = services["redis"]
    assert "--appendonly" in redis_svc["command"]
    assert redis_svc["command"][redis_svc["command"].index("--appendonly") + 1] == "yes"
    assert redis_svc["volumes"] and "redis-cli" in redis_svc["healthcheck"]["test"]
    for name in ("api", "worker"):
        svc = services[name]
        assert svc["depends_on"]["redis"]["condition"] == "service_healthy"
        assert svc["environment"]["FPJ_REDIS_URL"].startswith("redis://redis:6379")
        assert svc["healthcheck"]["test"]
    assert services["api"]["command"][:2] == ["jigsaw", "serve"]
    assert services["api"]["environment"]["FPJ_LOCAL_WORKERS"] == "0"
    assert "/healthz" in " ".join(services["api"]["healthcheck"]["test"])
    assert services["worker"]["command"] == ["jigsaw", "worker"]
    assert services["worker"]["deploy"]["replicas"] >= 2
    assert services["api"]["build"]["dockerfile"] == "deploy/Dockerfile"


def test_kubernetes_manifests() -> None:
    docs = _k8s_docs()
    kinds = {(d["kind"], d["metadata"]["name"]) for d in docs}
    assert {
        ("StatefulSet", "redis"),
        ("Service", "redis"),
        ("Deployment", "jigsaw-api"),
        ("Service", "jigsaw-api"),
        ("Deployment", "jigsaw-worker"),
        ("ConfigMap", "jigsaw-config"),
    } <= kinds
    for doc in docs:
        if doc["kind"] in ("Deployment", "StatefulSet"):
            spec = doc["spec"]
            assert (
                spec["selector"]["matchLabels"].items()
                <= spec["template"]["metadata"]["labels"].items()
            )
            for container in spec["template"]["spec"]["containers"]:
                assert container.get("livenessProbe"), (doc["metadata"]["name"], container)
    config = next(d for d in docs if d["kind"] == "ConfigMap")
    assert config["data"]["FPJ_REDIS_URL"] == "redis://redis:6379/0"
    kustomization = yaml.safe_load((K8S / "kustomization.yaml").read_text())
    assert all((K8S / name).exists() for name in kustomization["resources"])


def test_dockerfile_copies_every_package() -> None:
    text = (ROOT / "deploy" / "Dockerfile").read_text()
    packages = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"][
        "packages"
    ]["find"]["include"]
    for package in packages:
        assert f"COPY {package.rstrip('*')} ./{package.rstrip('*')}" in text, package
    assert 'CMD ["jigsaw", "serve", "--host", "0.0.0.0", "--port", "8000"]' in text
    assert "HEALTHCHECK" in text
    assert (ROOT / "deploy" / "Dockerfile.dockerignore").exists()


def test_the_build_context_holds_what_the_dockerfile_copies() -> None:
    """The dockerignore admits only listed paths: a COPY of anything else fails the build."""
    admitted = {
        line.removeprefix("!").removesuffix("/**")
        for line in (ROOT / "deploy" / "Dockerfile.dockerignore").read_text().splitlines()
        if line.startswith("!")
    }
    copied = [
        source
        for line in (ROOT / "deploy" / "Dockerfile").read_text().splitlines()
        if line.startswith("COPY ") and "--from" not in line
        for source in line.split()[1:-1]
    ]
    assert copied
    assert [source for source in copied if source not in admitted] == []
    assert "pip install -c constraints.txt" in (ROOT / "deploy" / "Dockerfile").read_text()


def _cli(*args: str, env: dict[str, str]) -> subprocess.Popen[bytes]:
    return subprocess.Popen([sys.executable, "-m", "cli.main", *args], env=env, cwd=ROOT)


def _healthcheck(test: list[str], env: dict[str, str]) -> int:
    """Run a compose CMD health check locally (``python`` is this interpreter)."""
    assert test[0] == "CMD"
    command = [sys.executable if part == "python" else part for part in test[1:]]
    return subprocess.run(command, env=env, cwd=ROOT, timeout=30).returncode


def test_compose_topology_as_processes(
    redis_process: RedisProcess, tmp_path: Path, easy_scene: SyntheticScene
) -> None:
    settings = make_settings(redis_process.url, local_workers=0, data_dir=tmp_path)
    env = settings_env(settings)
    port = free_port()
    processes = [_cli("serve", "--port", str(port), env=env)]
    processes += [_cli("worker", env=env) for _ in range(2)]
    try:
        client = redis.Redis.from_url(redis_process.url, decode_responses=True)
        wait_workers_alive(client, "fpj", 2)
        url = f"http://127.0.0.1:{port}"

        def healthy() -> bool:
            try:
                return httpx.get(f"{url}/healthz", timeout=1).status_code == 200
            except httpx.TransportError:
                return False

        wait_until(healthy, 30, interval=0.1)
        serve_children = Path(f"/proc/{processes[0].pid}/task").glob("*/children")
        assert all(not path.read_text().split() for path in serve_children)  # no local workers
        compose = _compose()["services"]
        api_check = [
            part.replace("127.0.0.1:8000", f"127.0.0.1:{port}")
            for part in compose["api"]["healthcheck"]["test"]
        ]
        assert _healthcheck(api_check, env) == 0
        assert _healthcheck(compose["worker"]["healthcheck"]["test"], env) == 0
        with httpx.Client(base_url=url, timeout=30) as http:
            for f in easy_scene.fragments:
                http.put(f"/v1/sites/s/fragments/{f.id}", content=encode_ply(f.points))
            wait_result(http, "s", status="closed")
            assert http.get("/readyz").json()["workers"] == 2
    finally:
        for process in processes:
            process.terminate()
        codes = [process.wait(30) for process in processes]
    assert codes == [0, 0, 0]
    # No worker alive any more: the worker health check fails.
    assert _healthcheck(["CMD", *shlex.split("python -m worker.health")], env) == 1
