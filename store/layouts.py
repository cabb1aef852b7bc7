"""A fragment's local layout in its stored form (``P:site:S:frag:F:layout``) and back.

The layout job writes :class:`schemas.layout.LocalLayoutWire` JSON; the placement job reads
it. Arrays travel as base64 of little-endian float64, row-major; their shape is implied by
the column count each field documents.
"""

from __future__ import annotations

import base64
from typing import Any

import numpy as np

from schemas.layout import LocalLayoutWire
from services.types import ChainVariant, FloatArray, LocalLayout, ManhattanFrame

__all__ = ["decode_array", "encode_array", "layout_from_wire", "layout_to_wire"]


def encode_array(array: FloatArray) -> str:
    """Base64 of the array as little-endian float64, row-major (shape travels separately)."""
    return base64.b64encode(np.ascontiguousarray(array, dtype="<f8").tobytes()).decode("ascii")


def decode_array(text: str, columns: int) -> FloatArray:
    """Inverse of :func:`encode_array` for an (M, columns) array."""
    flat = np.frombuffer(base64.b64decode(text), dtype="<f8")
    return flat.reshape(-1, columns).astype(np.float64)


def layout_to_wire(layout: LocalLayout) -> LocalLayoutWire:
    """The wire form of a local layout (keypoints and rotation as lists, arrays in base64)."""
    return LocalLayoutWire(
        keypoints=layout.keypoints.tolist(),
        rotation=layout.frame.rotation.tolist(),
        floor_z=layout.frame.floor_z,
        ceiling_z=layout.frame.ceiling_z,
        source_boundary=encode_array(layout.source_boundary),
        target_boundary=encode_array(layout.target_boundary),
        footprint=encode_array(layout.footprint),
        evidence=layout.evidence,
        unchained_walls=encode_array(layout.unchained_walls),
        view_angle=layout.view_angle,
        view_top=layout.view_top,
        cameras=encode_array(layout.cameras) if len(layout.cameras) else None,
        view_ranges=encode_array(layout.view_ranges) if len(layout.view_ranges) else None,
        **_runner_up_to_wire(layout.runner_up),
    )


def _runner_up_to_wire(variant: ChainVariant | None) -> dict[str, Any]:
    """The wire fields of a layout's runner-up chain (none without one)."""
    if variant is None:
        return {}
    return {
        "runner_up": variant.keypoints.tolist(),
        "runner_up_source_boundary": encode_array(variant.source_boundary),
        "runner_up_target_boundary": encode_array(variant.target_boundary),
    }


def layout_from_wire(wire: LocalLayoutWire) -> LocalLayout:
    """Inverse of :func:`layout_to_wire`: (K, 2) keypoints, (M, 3) boundaries, (F, 2)
    footprint, (W, 2) unchained walls, (C, 2) cameras and (B, 2) view ranges (none for a
    layout stored without), and the runner-up chain where there is one, all float64 in the
    aligned frame."""
    frame = ManhattanFrame(
        rotation=np.asarray(wire.rotation, dtype=np.float64),
        floor_z=wire.floor_z,
        ceiling_z=wire.ceiling_z,
    )
    return LocalLayout(
        keypoints=np.asarray(wire.keypoints, dtype=np.float64).reshape(-1, 2),
        frame=frame,
        source_boundary=decode_array(wire.source_boundary, 3),
        target_boundary=decode_array(wire.target_boundary, 3),
        footprint=decode_array(wire.footprint, 2),
        evidence=wire.evidence,
        unchained_walls=decode_array(wire.unchained_walls, 2),
        view_angle=wire.view_angle,
        view_top=wire.view_top,
        cameras=decode_array(wire.cameras or "", 2),
        view_ranges=decode_array(wire.view_ranges or "", 2),
        runner_up=None
        if wire.runner_up is None
        else ChainVariant(
            np.asarray(wire.runner_up, dtype=np.float64).reshape(-1, 2),
            decode_array(wire.runner_up_source_boundary, 3),
            decode_array(wire.runner_up_target_boundary, 3),
        ),
    )
