"""Deployment settings from the environment (``FPJ_`` prefix): tokens and their scopes, limits,
embedded mode."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from schemas.access import Scope
from schemas.settings import Settings

pytestmark = pytest.mark.timeout(10)


def test_settings_from_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FPJ_TOKENS", "a, b,,c")
    monkeypatch.setenv("FPJ_MAX_UPLOAD_BYTES", "1000")
    monkeypatch.setenv("FPJ_MIN_POINTS", "7")
    settings = Settings()
    assert list(settings.tokens) == ["a", "b", "c"]
    assert all(scope == Scope() for scope in settings.tokens.values())  # every right, every site
    assert settings.max_upload_bytes == 1000
    assert settings.parser_limits().min_points == 7
    assert settings.pipeline_params().parser.min_points == 7
    monkeypatch.setenv("FPJ_TOKENS", '["x"]')
    assert list(Settings().tokens) == ["x"]
    monkeypatch.setenv("FPJ_TOKENS", "bot:lab+hall:upload, view:*:read,admin")
    assert Settings().tokens == {
        "bot": Scope(sites=("lab", "hall"), rights=("upload",)),
        "view": Scope(rights=("read",)),
        "admin": Scope(),
    }
    monkeypatch.setenv("FPJ_TOKENS", '{"a:b,c": {"sites": ["lab"], "rights": ["read"]}}')
    assert Settings().tokens == {"a:b,c": Scope(sites=("lab",), rights=("read",))}
    for bad in ("bot:lab:write", "bot:../x", ":lab", '{"t": {"site": ["lab"]}}'):
        monkeypatch.setenv("FPJ_TOKENS", bad)
        with pytest.raises(ValidationError):
            Settings()


def test_local_workers_default_to_embedded_mode_only() -> None:
    assert Settings(redis_url=None).embedded
    assert Settings(redis_url=None).local_worker_count() >= 1
    assert Settings(redis_url="redis://r:6379/0").local_worker_count() == 0
    assert Settings(redis_url="redis://r:6379/0", local_workers=3).local_worker_count() == 3
