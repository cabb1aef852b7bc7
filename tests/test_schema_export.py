"""The committed JSON Schema files match the pydantic models."""

from __future__ import annotations

import json

import jsonschema
import pytest

from schemas.export import SCHEMA_DIR, render_schemas
from services.pipeline import place_site
from tests.conftest import scene_layouts

pytestmark = pytest.mark.timeout(120)


def test_committed_schemas_are_current():
    rendered = render_schemas()
    committed = {p.name for p in SCHEMA_DIR.glob("*.schema.json")}
    assert committed == set(rendered), "run: python -m schemas.export"
    for name, text in rendered.items():
        assert (SCHEMA_DIR / name).read_text(encoding="utf-8") == text, (
            f"{name} is stale: run python -m schemas.export"
        )


def test_a_real_result_validates_against_the_exported_schema():
    result = place_site(scene_layouts()).model_dump(mode="json")
    schema = json.loads((SCHEMA_DIR / "result.schema.json").read_text(encoding="utf-8"))
    jsonschema.validate(result, schema)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**result, "status": "almost"}, schema)
