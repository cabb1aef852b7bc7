"""Hostile inputs for the fuzz and property tests (and ``bench/fuzz_http.py``).

Valid seed files (PLY ascii/binary, PCD ascii/binary, an RGB-D frame zip, hints JSON) and
hypothesis strategies that mutate them the way broken or hostile clients do: truncation,
flipped bytes, inserted and deleted runs, header counts replaced by huge, negative or
non-numeric values, and plain random bytes. Everything is small, so hundreds of examples
parse in a few seconds.
"""

from __future__ import annotations

import json
import re
from functools import cache
from typing import Any

import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from schemas.frames import IntrinsicsModel
from schemas.ids import ID_PATTERN
from services.point_io import encode_pcd, encode_ply
from services.rgbd import encode_frame_files
from tests.frame_fixtures import zip_files as zip_bytes

__all__ = [
    "FUZZ_MIN_POINTS",
    "ID_PATTERN",
    "PROPERTY",
    "cloud_files",
    "fragment_bodies",
    "frame_file_sets",
    "hints_bodies",
    "mutated",
    "seed_clouds",
    "seed_frame_files",
    "seed_hints",
    "zip_bytes",
]

FUZZ_MIN_POINTS = 100  # ParserLimits.min_points of the tests (the FAST settings' value)
PROPERTY = settings(
    max_examples=300,
    derandomize=True,  # the same examples on every run: CI repeats
    database=None,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
"""Hypothesis settings of the property tests (``settings(PROPERTY, max_examples=...)``)."""
_N_POINTS = 150


@cache
def seed_clouds() -> dict[str, bytes]:
    """Valid fragment files of 150 random points: every encoding the parsers read."""
    points = np.random.default_rng(7).uniform(-3.0, 3.0, size=(_N_POINTS, 3))
    points[3] = np.nan  # a missing return, dropped and counted
    colours = {"red": np.arange(_N_POINTS, dtype=np.uint8)}
    return {
        "ply_binary": encode_ply(points, extra_properties=colours),
        "ply_big_double": encode_ply(points, big_endian=True, double=True),
        "ply_ascii": encode_ply(points, binary=False, extra_properties=colours),
        "pcd_binary": encode_pcd(points, height=3),
        "pcd_ascii": encode_pcd(points, binary=False),
    }


@cache
def seed_frame_files() -> dict[str, bytes]:
    """A valid RGB-D frame (40 x 30 pixels, a wall 2 m ahead, a colour image) as its files."""
    intrinsics = IntrinsicsModel(width=40, height=30, fx=30.0, fy=30.0, cx=19.5, cy=14.5)
    depth = np.full((30, 40), 2.0, dtype=np.float32)
    depth[:5, :] = 0.0  # no reading
    color = np.random.default_rng(3).integers(0, 256, size=(30, 40, 3), dtype=np.uint8)
    return encode_frame_files(depth, intrinsics, color)


def seed_hints() -> dict[str, Any]:
    """A valid hints document (contract section 2) using every part."""
    pose = [[0.0, -1.0, 0.0, 2.5], [1.0, 0.0, 0.0, -1.0], [0.0, 0.0, 1.0, 0.0], [0, 0, 0, 1]]
    return {
        "schema_version": 1,
        "frame": "map",
        "fragments": {"frag_00": {"pose": pose, "sigma_xy": 1.5, "sigma_yaw_deg": 20}},
        "neighbours": [["frag_00", "frag_03"]],
        "order": ["frag_00", "frag_03", "frag_01"],
    }


# ---------------------------------------------------------------- mutations

# A header count or size: what a broken writer or an attacker puts there.
_NUMBERS = st.one_of(
    st.integers(-3, 3),
    st.integers(-(2**70), 2**70),
    st.sampled_from([2**31 - 1, 2**31, 2**32, 2**63 - 1, 2**63, 2**64, 10**30]),
).map(str) | st.sampled_from(["", "-", "1e9", "0x10", "nan", "inf", "١٢", "3.5", "+7"])
_HEADER_NUMBER = re.compile(rb"(?<![A-Za-z_])-?\d+")


@st.composite
def _header_number_replaced(draw: st.DrawFn, data: bytes) -> bytes:
    """Replace one number of the first 400 bytes (counts, sizes, widths, versions)."""
    spots = [m.span() for m in _HEADER_NUMBER.finditer(data[:400])]
    if not spots:
        return data
    start, end = draw(st.sampled_from(spots))
    return data[:start] + draw(_NUMBERS).encode() + data[end:]


@st.composite
def _bytes_flipped(draw: st.DrawFn, data: bytes) -> bytes:
    out = bytearray(data)
    if not out:  # an earlier step emptied the file: no byte to flip
        return data
    head = draw(st.booleans())  # half the time aim at the header, where parsing decides
    span = min(len(out), 300) if head else len(out)
    for _ in range(draw(st.integers(1, 6))):
        out[draw(st.integers(0, span - 1))] = draw(st.integers(0, 255))
    return bytes(out)


@st.composite
def _run_inserted(draw: st.DrawFn, data: bytes) -> bytes:
    at = draw(st.integers(0, len(data)))
    junk = draw(st.binary(max_size=40) | st.sampled_from([b"\n", b"\r\n", b" ", b"\x00" * 8]))
    return data[:at] + junk + data[at:]


@st.composite
def _run_deleted(draw: st.DrawFn, data: bytes) -> bytes:
    start = draw(st.integers(0, len(data)))
    stop = draw(st.integers(start, min(len(data), start + 64)))
    return data[:start] + data[stop:]


@st.composite
def _line_swapped(draw: st.DrawFn, data: bytes) -> bytes:
    """Replace one header line with another keyword line (duplicates, wrong order)."""
    lines = data[:400].split(b"\n")
    if len(lines) < 2:
        return data
    i = draw(st.integers(0, len(lines) - 2))
    lines[i] = draw(
        st.sampled_from(
            [
                b"element vertex 99999999999",
                b"element face 3",
                b"property list uchar int vertex_indices",
                b"property float x",
                b"format binary_big_endian 1.0",
                b"format ascii 1.0",
                b"end_header",
                b"FIELDS x y z",
                b"SIZE 4 4 4",
                b"TYPE F F F",
                b"COUNT 1 1 1000000000000",
                b"WIDTH -1",
                b"HEIGHT 0",
                b"POINTS 4294967296",
                b"DATA binary_compressed",
                b"DATA ascii",
                b"",
            ]
        )
    )
    return b"\n".join(lines) + data[400:]


def mutated(data: bytes) -> st.SearchStrategy[bytes]:
    """``data`` broken in one or two of the ways real uploads break."""
    once = st.one_of(
        st.integers(0, len(data)).map(lambda n: data[:n]),  # truncated
        _bytes_flipped(data),
        _header_number_replaced(data),
        _run_inserted(data),
        _run_deleted(data),
        _line_swapped(data),
    )
    twice = once.flatmap(lambda first: _bytes_flipped(first) if first else st.just(first))
    return once | twice


def cloud_files() -> st.SearchStrategy[bytes]:
    """PLY and PCD files: valid, mutated, or random bytes behind a format's magic."""
    seeds = list(seed_clouds().values())
    magic = st.sampled_from([b"ply\n", b"ply\r\n", b"# .PCD v0.7\n", b"VERSION .7\n", b"FIELDS "])
    return st.one_of(
        st.sampled_from(seeds),
        st.sampled_from(seeds).flatmap(mutated),
        st.tuples(magic, st.binary(max_size=300)).map(b"".join),
    )


@st.composite
def frame_file_sets(draw: st.DrawFn) -> dict[str, bytes]:
    """A frame's files with one or two of them mutated, dropped or replaced."""
    files = dict(seed_frame_files())
    for _ in range(draw(st.integers(1, 2))):
        name = draw(st.sampled_from([*files, "color.jpg", "notes.txt"]))
        action = draw(st.sampled_from(["mutate", "drop", "random", "intrinsics"]))
        if action == "drop":
            files.pop(name, None)
        elif action == "random":
            files[name] = draw(st.binary(max_size=200))
        elif action == "intrinsics":
            files["intrinsics.json"] = draw(_intrinsics_documents())
        elif name in files:
            files[name] = draw(mutated(files[name]))
    return files


def _intrinsics_documents() -> st.SearchStrategy[bytes]:
    number = st.one_of(
        st.integers(-(2**40), 2**40),
        st.floats(allow_nan=False, allow_infinity=False),
        st.sampled_from([0, 40, 30, 1e308, -1e308, 1e-320]),
    )
    fields = st.fixed_dictionaries(
        {},
        optional={
            key: number | st.text(max_size=4) | st.none()
            for key in ("width", "height", "fx", "fy", "cx", "cy", "depth_scale")
        },
    )
    return fields.map(lambda d: json.dumps(d).encode())


@st.composite
def _archives(draw: st.DrawFn) -> bytes:
    files = draw(frame_file_sets())
    folder = draw(st.sampled_from(["", "frame/", "a/b/", "../", "/abs/"]))
    return zip_bytes(files, folder)


def fragment_bodies() -> st.SearchStrategy[bytes]:
    """Every kind of upload body: clouds, frame archives (valid, mutated), random bytes."""
    archive = zip_bytes(seed_frame_files())
    return st.one_of(
        cloud_files(),
        _archives(),
        mutated(archive),
        st.binary(max_size=200),
    )


# ---------------------------------------------------------------- hints

_JSON_SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=False, allow_infinity=False),
    st.text(max_size=8),
)
_JSON = st.recursive(
    _JSON_SCALARS,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner),
    max_leaves=12,
)


@st.composite
def _hints_edited(draw: st.DrawFn) -> dict[str, Any]:
    """The seed hints with one part replaced by arbitrary JSON or an odd value."""
    doc = seed_hints()
    part = draw(st.sampled_from([*doc, "fragments.pose", "fragments.sigma", "unknown"]))
    odd = _JSON | st.sampled_from([1e308, -1e308, 1e-320, "", "..", "a" * 65, [[1e308] * 4] * 4])
    if part == "fragments.pose":
        pose = draw(st.lists(st.lists(_JSON_SCALARS | st.just(1e308), max_size=5), max_size=5))
        doc["fragments"]["frag_00"]["pose"] = pose
    elif part == "fragments.sigma":
        doc["fragments"]["frag_00"][draw(st.sampled_from(["sigma_xy", "sigma_yaw_deg"]))] = draw(
            odd
        )
    elif part == "unknown":
        doc[draw(st.text(min_size=1, max_size=8))] = draw(odd)
    else:
        doc[part] = draw(odd)
    return doc


def hints_bodies() -> st.SearchStrategy[bytes]:
    """Hints bodies: valid, edited, arbitrary JSON, deep nesting, mutated text, random bytes."""
    valid = json.dumps(seed_hints()).encode()
    depth = st.integers(1, 5000)
    return st.one_of(
        st.just(valid),
        _hints_edited().map(lambda d: json.dumps(d).encode()),
        _JSON.map(lambda d: json.dumps(d).encode()),
        depth.map(lambda n: b"[" * n + b"]" * n),
        depth.map(lambda n: b'{"fragments":' * n + b"{}" + b"}" * n),
        mutated(valid),
        st.binary(max_size=200),
        st.sampled_from([b"NaN", b'{"frame": NaN}', b"\xef\xbb\xbf{}", b"{}\x00", b""]),
    )


# ---------------------------------------------------------------- the HTTP API

FUZZ_TOKEN = "fuzz-token"  # the one bearer token of the fuzzed service (FPJ_TOKENS)
STREAMING_PATHS = ("/v1/sites/{site_id}/events",)  # never end: fuzzed apart, reading one event
_TRACEBACK_MARKERS = ("Traceback (most recent call last)", 'File "/', "Exception:")


def refine_schema(raw: dict[str, Any]) -> dict[str, Any]:
    """The service's OpenAPI document with the id pattern on every path parameter.

    The routes check ids themselves (400 ``invalid_id``) so the schema does not carry the
    pattern; with it, positive examples reach the storage and negative ones test the 400.
    """
    for path_item in raw["paths"].values():
        for operation in path_item.values():
            for parameter in operation.get("parameters", []):
                if parameter["in"] == "path":
                    parameter["schema"]["pattern"] = ID_PATTERN
    return raw


def load_http_schema(base_url: str) -> Any:
    """A schemathesis schema of the live service at ``base_url`` (token included), with
    upload bodies drawn from :func:`fragment_bodies`."""
    import httpx
    import schemathesis

    schemathesis.openapi.media_type("application/octet-stream", fragment_bodies())
    raw = httpx.get(f"{base_url}/openapi.json", timeout=10).json()
    schema = schemathesis.openapi.from_dict(refine_schema(raw))
    schema.config.update(
        base_url=base_url, headers={"Authorization": f"Bearer {FUZZ_TOKEN}"}, request_timeout=30
    )
    return schema


def error_shape_problem(status: int, content_type: str, body: bytes) -> str | None:
    """What is wrong with a reply by the contract's rules, or None.

    No 5xx; every 4xx is JSON ``{"error": {"code": str, "message": str}}`` and nothing
    else; no reply carries a Python traceback.
    """
    text = body.decode("utf-8", "replace")
    if any(marker in text for marker in _TRACEBACK_MARKERS):
        return f"{status}: the body carries a traceback: {text[:300]}"
    if status >= 500:
        return f"server error {status}: {text[:300]}"
    if status < 400:
        return None
    if not content_type.startswith("application/json"):
        return f"{status} error with content type {content_type!r}"
    try:
        doc = json.loads(text)
    except ValueError:
        return f"{status} error body is not JSON: {text[:200]}"
    detail = doc.get("error") if isinstance(doc, dict) else None
    if not (
        isinstance(doc, dict)
        and set(doc) == {"error"}
        and isinstance(detail, dict)
        and set(detail) == {"code", "message"}
        and all(isinstance(detail[k], str) and detail[k] for k in ("code", "message"))
    ):
        return f"{status} error body not in the contract's shape: {text[:200]}"
    return None


def error_shape(ctx: Any, response: Any, case: Any) -> bool | None:
    """A schemathesis check: :func:`error_shape_problem` of the reply."""
    problem = error_shape_problem(
        response.status_code, response.headers.get("content-type", [""])[0], response.content
    )
    if problem is not None:
        raise AssertionError(problem)
    return True


def operation_cases(operation: Any) -> st.SearchStrategy[Any]:
    """Schema-valid and schema-invalid cases of one operation (invalid ids, out-of-range
    queries, bodies off the schema), half and half; only valid ones when the operation has
    nothing that can be invalid."""
    from schemathesis import GenerationMode

    positive = operation.as_strategy(GenerationMode.POSITIVE)
    if not any(True for _ in operation.iter_parameters()) and not operation.body:
        return positive
    negative = operation.as_strategy(GenerationMode.NEGATIVE)
    return st.one_of(positive, negative)
