"""JSON Schema of every model that crosses a boundary, written to ``schemas/json/``.

Run ``python -m schemas.export`` after changing a model; ``tests/test_schema_export.py``
fails while the committed files differ from the models. Clients in other languages
validate results, uploads' replies, jobs and zenoh messages against these files.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from pydantic import BaseModel, TypeAdapter

from schemas.hints import HintsModel
from schemas.jobs import DeadLetter, Job
from schemas.layout import LocalLayoutWire
from schemas.layout_file import LayoutFileModel
from schemas.params import PipelineParams
from schemas.result import ResultModel
from schemas.service import (
    ErrorBody,
    PendingReply,
    SiteEvent,
    SiteList,
    SiteStatus,
    UploadReply,
)
from schemas.zenoh import PoseUpdate, ServiceInfo

__all__ = ["SCHEMA_DIR", "render_schemas", "write_schemas"]

SCHEMA_DIR = Path(__file__).parent / "json"

_MODELS: dict[str, type[BaseModel]] = {
    "result": ResultModel,
    "hints": HintsModel,
    "error": ErrorBody,
    "upload_reply": UploadReply,
    "pending_reply": PendingReply,
    "site_status": SiteStatus,
    "site_list": SiteList,
    "site_event": SiteEvent,
    "pose_update": PoseUpdate,
    "service_info": ServiceInfo,
    "local_layout_wire": LocalLayoutWire,
    "layout_file": LayoutFileModel,
    "dead_letter": DeadLetter,
    "pipeline_params": PipelineParams,
}


def render_schemas() -> dict[str, str]:
    """File name -> JSON text (sorted keys, trailing newline) of every exported schema."""
    schemas: dict[str, dict[str, Any]] = {
        name: model.model_json_schema() for name, model in _MODELS.items()
    }
    schemas["job"] = TypeAdapter(Job).json_schema()
    return {
        f"{name}.schema.json": json.dumps(schema, indent=2, sort_keys=True) + "\n"
        for name, schema in sorted(schemas.items())
    }


def write_schemas(directory: Path = SCHEMA_DIR) -> list[Path]:
    """Write every schema into ``directory`` (created if missing); return the paths."""
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for name, text in render_schemas().items():
        path = directory / name
        path.write_text(text, encoding="utf-8")
        written.append(path)
    return written


if __name__ == "__main__":
    for written_path in write_schemas(Path(sys.argv[1]) if len(sys.argv) > 1 else SCHEMA_DIR):
        print(written_path)
