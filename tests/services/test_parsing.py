"""Tests for services.parsing (PLY/PCD from bytes) and its inverse services.point_io."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

from schemas.params import ParserLimits
from services.errors import (
    FragmentError,
    FragmentTooLargeError,
    InvalidFragmentError,
    UnsupportedFormatError,
)
from services.parsing import detect_format, parse_fragment
from services.point_io import encode_pcd, encode_ply

pytestmark = pytest.mark.timeout(60)

N = 50
LIMITS = ParserLimits(min_points=1)
PLY_ENCODINGS = ["ascii", "binary_little_endian", "binary_big_endian"]


@pytest.fixture
def points() -> np.ndarray:
    return np.random.default_rng(7).uniform(-5.0, 5.0, size=(N, 3))


def _f32(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float32).astype(np.float64)


# --- hand-made PLY builder, for layouts encode_ply does not produce -----------------------

_NP_CODES = {"char": "i1", "uchar": "u1", "short": "i2", "ushort": "u2", "int": "i4"}
_NP_CODES |= {"uint": "u4", "float": "f4", "double": "f8", "float32": "f4", "uint8": "u1"}
_NP_CODES |= {"int8": "i1", "int16": "i2", "uint16": "u2", "int32": "i4", "uint32": "u4"}
_NP_CODES |= {"float64": "f8"}


def _element(encoding: str, name: str, cols: list[tuple[str, str, np.ndarray]]):
    """Header lines and body bytes of one element of scalar properties."""
    n = len(cols[0][2])
    header = [f"element {name} {n}"] + [f"property {t} {p}" for t, p, _ in cols]
    if encoding == "ascii":
        fmt = " ".join("%.17g" if _NP_CODES[t][0] == "f" else "%d" for t, _, _ in cols) + "\n"
        table = np.column_stack([np.asarray(v, _NP_CODES[t]).astype(float) for t, _, v in cols])
        return header, ((fmt * n) % tuple(table.ravel().tolist())).encode()
    order = "<" if encoding == "binary_little_endian" else ">"
    dt = np.dtype([(f"c{i}", order + _NP_CODES[t]) for i, (t, _, _) in enumerate(cols)])
    rec = np.empty(n, dtype=dt)
    for i, (_, _, v) in enumerate(cols):
        rec[f"c{i}"] = v
    return header, rec.tobytes()


def _faces(encoding: str, n_faces: int, n_vertices: int):
    """A face element (list property) with triangles over the vertices."""
    idx = np.arange(n_faces * 3).reshape(n_faces, 3) % n_vertices
    header = [f"element face {n_faces}", "property list uchar int vertex_indices"]
    if encoding == "ascii":
        return header, b"".join(b"3 %d %d %d\n" % tuple(row) for row in idx.tolist())
    order = "<" if encoding == "binary_little_endian" else ">"
    rec = np.empty(n_faces, dtype=[("n", "u1"), ("i", order + "i4", (3,))])
    rec["n"], rec["i"] = 3, idx
    return header, rec.tobytes()


def _ply(encoding: str, *elements: tuple[list[str], bytes], eol: str = "\n") -> bytes:
    lines = ["ply", f"format {encoding} 1.0", "comment made by a test", "obj_info scanner 1"]
    for header, _ in elements:
        lines += header
    lines += ["end_header", ""]
    return eol.join(lines).encode() + b"".join(body for _, body in elements)


def _xyz_cols(pts: np.ndarray, ptype: str = "float"):
    return [(ptype, axis, pts[:, j]) for j, axis in enumerate("xyz")]


def _pcd(fields: str, size: str, type_: str, count: str | None, body: bytes, **kw: object):
    lines = ["# .PCD v0.7 - Point Cloud Data file format", "VERSION 0.7", f"FIELDS {fields}"]
    lines += [f"SIZE {size}", f"TYPE {type_}"] + ([f"COUNT {count}"] if count else [])
    lines += [f"{k.upper()} {v}" for k, v in kw.items()]
    return ("\n".join(lines) + "\n").encode() + body


# --- round trips ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("binary", "big_endian"),
    [(True, False), (True, True), (False, False)],
    ids=["le", "be", "ascii"],
)
@pytest.mark.parametrize("double", [False, True], ids=["float", "double"])
def test_ply_round_trip(points, binary, big_endian, double):
    data = encode_ply(points, binary=binary, big_endian=big_endian, double=double)
    parsed = parse_fragment(data, LIMITS)
    expected = points if double else _f32(points)
    if double or binary:
        np.testing.assert_array_equal(parsed.points, expected)
    else:  # ascii float: 9 significant digits round-trip through float32
        np.testing.assert_array_equal(_f32(parsed.points), expected)
    assert parsed.format == "ply"
    assert parsed.dropped_nonfinite == 0
    assert parsed.points.dtype == np.float64
    assert parsed.points.flags["C_CONTIGUOUS"]
    assert parsed.points.shape == (N, 3)


@pytest.mark.parametrize("binary", [True, False])
@pytest.mark.parametrize("big_endian", [False, True])
def test_ply_extra_properties_after_xyz(points, binary, big_endian):
    rng = np.random.default_rng(1)
    extras: dict[str, np.ndarray] = {
        "nx": rng.normal(size=N).astype(np.float32),
        "ny": rng.normal(size=N),
        "red": rng.integers(0, 256, N).astype(np.uint8),
        "label": rng.integers(-1000, 1000, N).astype(np.int16),
        "idx": np.arange(N, dtype=np.uint32),
    }
    data = encode_ply(points, binary=binary, big_endian=big_endian, extra_properties=extras)
    parsed = parse_fragment(data, LIMITS)
    np.testing.assert_array_equal(_f32(parsed.points), _f32(points))


@pytest.mark.parametrize("encoding", PLY_ENCODINGS)
def test_ply_properties_before_and_around_xyz(points, encoding):
    rng = np.random.default_rng(2)
    cols = [
        ("uchar", "red", rng.integers(0, 256, N)),
        ("float", "nx", rng.normal(size=N)),
        ("double", "x", points[:, 0]),
        ("char", "flag", rng.integers(-128, 128, N)),
        ("double", "y", points[:, 1]),
        ("ushort", "ring", rng.integers(0, 65536, N)),
        ("double", "z", points[:, 2]),
        ("uchar", "alpha", rng.integers(0, 256, N)),
    ]
    parsed = parse_fragment(_ply(encoding, _element(encoding, "vertex", cols)), LIMITS)
    np.testing.assert_array_equal(parsed.points, points)


@pytest.mark.parametrize("encoding", PLY_ENCODINGS)
def test_ply_sized_type_aliases(points, encoding):
    cols = [("uint8", "r", np.full(N, 3)), *_xyz_cols(points, "float64")]
    cols += [("int32", "i", np.arange(N)), ("float32", "w", np.ones(N))]
    parsed = parse_fragment(_ply(encoding, _element(encoding, "vertex", cols)), LIMITS)
    np.testing.assert_array_equal(parsed.points, points)


@pytest.mark.parametrize("encoding", PLY_ENCODINGS)
def test_ply_face_element_after_vertices(points, encoding):
    data = _ply(
        encoding,
        _element(encoding, "vertex", _xyz_cols(points)),
        _faces(encoding, 7, N),
        _element(encoding, "edge", [("int", "a", np.arange(4)), ("int", "b", np.arange(4))]),
    )
    parsed = parse_fragment(data, LIMITS)
    np.testing.assert_array_equal(parsed.points, _f32(points))


@pytest.mark.parametrize("encoding", PLY_ENCODINGS)
def test_ply_fixed_size_element_before_vertices_is_skipped(points, encoding):
    camera = _element(
        encoding, "camera", [("float", "px", np.arange(3.0)), ("uchar", "k", np.ones(3))]
    )
    data = _ply(encoding, camera, _element(encoding, "vertex", _xyz_cols(points, "double")))
    np.testing.assert_array_equal(parse_fragment(data, LIMITS).points, points)


def test_ply_ascii_list_element_before_vertices_is_skipped(points):
    data = _ply("ascii", _faces("ascii", 4, N), _element("ascii", "vertex", _xyz_cols(points)))
    np.testing.assert_array_equal(parse_fragment(data, LIMITS).points, _f32(points))


def test_ply_ascii_crlf_line_endings(points):
    header, _ = _element("ascii", "vertex", _xyz_cols(points, "double"))
    body = b"".join(b"%r %r %r\r\n" % tuple(row) for row in points.tolist())
    data = _ply("ascii", (header, body), eol="\r\n")
    assert data.startswith(b"ply\r\n")
    np.testing.assert_array_equal(parse_fragment(data, LIMITS).points, points)


def test_ply_ascii_last_line_without_newline(points):
    data = encode_ply(points, binary=False, double=True).rstrip(b"\n")
    np.testing.assert_array_equal(parse_fragment(data, LIMITS).points, points)


@pytest.mark.parametrize("binary", [True, False])
def test_pcd_round_trip(points, binary):
    parsed = parse_fragment(encode_pcd(points, binary=binary), LIMITS)
    np.testing.assert_array_equal(_f32(parsed.points), _f32(points))
    assert parsed.format == "pcd"
    assert parsed.points.flags["C_CONTIGUOUS"]


@pytest.mark.parametrize("binary", [True, False])
def test_pcd_rgb_and_other_fields_are_skipped(points, binary):
    rng = np.random.default_rng(3)
    extras: dict[str, np.ndarray] = {
        "rgb": rng.integers(0, 2**24, N).astype(np.uint32),
        "intensity": rng.uniform(size=N).astype(np.float32),
        "ring": rng.integers(0, 64, N).astype(np.uint16),
    }
    parsed = parse_fragment(encode_pcd(points, binary=binary, extra_fields=extras), LIMITS)
    np.testing.assert_array_equal(_f32(parsed.points), _f32(points))


def test_pcd_binary_packed_float_rgb_before_xyz_and_count_field(points):
    # PCL layout: a field before x, float-packed rgb, a COUNT 3 field, no COUNT for padding.
    rec = np.zeros(N, dtype=[("i", "<u2"), ("xyz", "<f8", 3), ("rgb", "<f4"), ("n", "<f4", 3)])
    rec["xyz"] = points
    rec["rgb"] = np.full(N, 0xFF8000, dtype=np.uint32).view(np.float32)
    data = _pcd(
        "intensity x y z rgb normal",
        "2 8 8 8 4 4",
        "U F F F F F",
        "1 1 1 1 1 3",
        rec.tobytes(),
        width=N,
        height=1,
        viewpoint="0 0 0 1 0 0 0",
        points=N,
        data="binary",
    )
    np.testing.assert_array_equal(parse_fragment(data, LIMITS).points, points)


def test_pcd_ascii_without_count_and_points_lines(points):
    body = b"".join(b"%r %r 7 %r\n" % tuple(row) for row in points.tolist())
    data = _pcd("x y label z", "4 4 4 4", "F F I F", None, body, width=N, height=1, data="ascii")
    np.testing.assert_array_equal(parse_fragment(data, LIMITS).points, points)


@pytest.mark.parametrize("binary", [True, False])
def test_pcd_organized_cloud_drops_nan_rows(points, binary):
    pts = points.copy()
    pts[::5, 0] = np.nan  # 10 rows
    pts[1, 2] = np.nan
    parsed = parse_fragment(encode_pcd(pts, binary=binary, height=5), LIMITS)
    keep = np.isfinite(pts).all(axis=1)
    assert parsed.dropped_nonfinite == 11
    np.testing.assert_array_equal(_f32(parsed.points), _f32(pts[keep]))


@pytest.mark.parametrize("binary", [True, False])
def test_ply_inf_and_nan_are_dropped_and_counted(points, binary):
    pts = points.copy()
    pts[3] = [np.inf, 0.0, 0.0]
    pts[4, 1] = -np.inf
    pts[5, 2] = np.nan
    parsed = parse_fragment(encode_ply(pts, binary=binary, double=True), LIMITS)
    assert parsed.dropped_nonfinite == 3
    assert len(parsed.points) == N - 3
    assert np.isfinite(parsed.points).all()


def test_default_limits_accept_enough_points():
    pts = np.random.default_rng(4).normal(size=(1500, 3))
    assert len(parse_fragment(encode_ply(pts)).points) == 1500


def test_detect_format():
    assert detect_format(b"ply\r\nformat ascii 1.0\r\n") == "ply"
    assert detect_format(b"VERSION .7\n") == "pcd"
    assert detect_format(b"FIELDS x y z\n") == "pcd"


# --- the encoder is standard-conformant ---------------------------------------------------


@pytest.mark.parametrize(
    ("name", "kwargs"),
    [
        ("le.ply", {"binary": True}),
        ("be.ply", {"binary": True, "big_endian": True}),
        ("double.ply", {"binary": True, "double": True}),
        ("ascii.ply", {"binary": False}),
        ("extra.ply", {"binary": True, "extra_properties": {"red": np.arange(N, dtype="u1")}}),
        ("bin.pcd", {"binary": True}),
        ("ascii.pcd", {"binary": False}),
    ],
)
def test_open3d_reads_encoded_files(tmp_path, points, name, kwargs):
    o3d = pytest.importorskip("open3d")
    encode = encode_pcd if name.endswith(".pcd") else encode_ply
    path = tmp_path / name
    path.write_bytes(encode(points, **kwargs))
    cloud = o3d.io.read_point_cloud(str(path))
    np.testing.assert_allclose(np.asarray(cloud.points), points, atol=1e-6)


@pytest.mark.parametrize(
    ("name", "compressed"),
    [
        ("o.ply", False),
        ("o_ascii.ply", False),
        ("o.pcd", False),
        ("o_ascii.pcd", False),
        ("o_compressed.pcd", True),
    ],
)
def test_parse_files_written_by_open3d(tmp_path, points, name, compressed):
    o3d = pytest.importorskip("open3d")
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud.normals = o3d.utility.Vector3dVector(np.tile([0.0, 0.0, 1.0], (N, 1)))
    cloud.colors = o3d.utility.Vector3dVector(np.full((N, 3), 0.5))
    path = tmp_path / name
    ascii_ = "ascii" in name
    assert o3d.io.write_point_cloud(str(path), cloud, write_ascii=ascii_, compressed=compressed)
    if compressed:
        _raises(path.read_bytes(), InvalidFragmentError, "binary_compressed", "not supported")
        return
    parsed = parse_fragment(path.read_bytes(), LIMITS)
    # Open3D's ASCII PLY writer keeps only 6 significant digits.
    np.testing.assert_allclose(parsed.points, points, atol=1e-4 if ascii_ else 1e-6)


def test_encoder_rejects_bad_input(points):
    with pytest.raises(ValueError, match="shape"):
        encode_ply(points[:, :2])
    with pytest.raises(ValueError, match="not a PLY type"):
        encode_ply(points, extra_properties={"t": np.zeros(N, dtype=np.int64)})
    with pytest.raises(ValueError, match="name"):
        encode_ply(points, extra_properties={"x": np.zeros(N)})
    with pytest.raises(ValueError, match="height"):
        encode_pcd(points, height=7)


# --- bad input ----------------------------------------------------------------------------


def _raises(data: bytes, exc: type[Exception], *words: str, limits: ParserLimits = LIMITS):
    with pytest.raises(exc) as info:
        parse_fragment(data, limits)
    message = str(info.value).lower()
    for word in words:
        assert word.lower() in message, f"{word!r} not in {message!r}"


@pytest.mark.parametrize(
    ("data", "word"),
    [
        (b"", "empty"),
        (bytes(range(256)) * 4, "not PLY or PCD"),
        (b"PLY\nformat ascii 1.0\n", "not PLY or PCD"),
        (b"solid cube\nfacet normal 0 0 1\n", "not PLY or PCD"),
    ],
)
def test_unsupported_format(data, word):
    _raises(data, UnsupportedFormatError, word)


@pytest.mark.parametrize("kwargs", [{}, {"big_endian": True}, {"double": True}])
def test_ply_binary_truncated(points, kwargs):
    _raises(encode_ply(points, **kwargs)[:-5], InvalidFragmentError, "truncated")


def test_ply_binary_truncated_before_vertex_bytes(points):
    data = encode_ply(points)
    header_end = data.index(b"end_header\n") + len(b"end_header\n")
    _raises(data[:header_end], InvalidFragmentError, "truncated", f"{N} points")


def test_ply_binary_face_element_truncated(points):
    enc = "binary_little_endian"
    data = _ply(enc, _element(enc, "vertex", _xyz_cols(points)), _faces(enc, 10, N))
    # 10 faces of 13 bytes; with lists only the 1-byte-per-face minimum is checkable.
    _raises(data[:-126], InvalidFragmentError, "truncated")


def test_ply_ascii_truncated(points):
    data = encode_ply(points, binary=False)
    cut = data[: data.rstrip(b"\n").rindex(b"\n") + 1]  # drop the last vertex line
    _raises(cut, InvalidFragmentError, "truncated")


def test_ply_ascii_truncated_before_vertices(points):
    data = _ply("ascii", _faces("ascii", 4, N), _element("ascii", "vertex", _xyz_cols(points)))
    header_end = data.index(b"end_header\n") + len(b"end_header\n")
    _raises(data[: header_end + 6], InvalidFragmentError, "truncated")


@pytest.mark.parametrize("kwargs", [{}, {"big_endian": True}])
def test_ply_binary_trailing_garbage(points, kwargs):
    _raises(encode_ply(points, **kwargs) + b"\x00" * 12, InvalidFragmentError, "inconsistent")


def test_ply_binary_trailing_garbage_after_fixed_size_element(points):
    enc = "binary_little_endian"
    edges = _element(enc, "edge", [("int", "a", np.arange(4)), ("int", "b", np.arange(4))])
    data = _ply(enc, _element(enc, "vertex", _xyz_cols(points)), edges)
    _raises(data + b"junk", InvalidFragmentError, "inconsistent")


def test_ply_ascii_extra_lines(points):
    data = encode_ply(points, binary=False) + b"1 2 3\n"
    _raises(data, InvalidFragmentError, "inconsistent")


def test_ply_ascii_wrong_number_of_columns(points):
    header, body = encode_ply(points, binary=False).split(b"end_header\n")
    data = header + b"end_header\n" + body.replace(b"\n", b" 0\n")
    _raises(data, InvalidFragmentError, "inconsistent")


def test_ply_ascii_non_numeric_token(points):
    data = encode_ply(points, binary=False)
    _raises(data[:-3] + b"abc\n", InvalidFragmentError, "non-numeric")


def test_ply_missing_end_header(points):
    data = encode_ply(points).replace(b"end_header", b"end_headr")
    _raises(data, InvalidFragmentError, "end_header")


def test_ply_no_vertex_element():
    _raises(b"ply\nformat ascii 1.0\nelement face 0\nend_header\n", InvalidFragmentError, "vertex")


@pytest.mark.parametrize("encoding", PLY_ENCODINGS)
def test_ply_missing_z(points, encoding):
    cols = [("float", "x", points[:, 0]), ("float", "y", points[:, 1])]
    data = _ply(encoding, _element(encoding, "vertex", cols))
    _raises(data, InvalidFragmentError, "x/y/z", "missing z")


def test_ply_unknown_property_type(points):
    data = encode_ply(points).replace(b"property float y", b"property half y")
    _raises(data, InvalidFragmentError, "unknown property type", "half")


@pytest.mark.parametrize(
    ("line", "word"),
    [
        (b"format binary_middle_endian 1.0", "format"),
        (b"element vertex many", "non-integer"),
        (b"property uchar y", "unexpected line"),  # property before any element
        (b"vertex \xff\xfe", "unexpected line"),
    ],
)
def test_ply_malformed_header_lines(points, line, word):
    data = encode_ply(points).replace(b"comment floorplan-jigsaw", line)
    if line.startswith(b"format"):
        data = data.replace(b"format binary_little_endian 1.0\n", b"")
    _raises(data, InvalidFragmentError, word)


def test_ply_malformed_property_line(points):
    data = encode_ply(points).replace(b"property float z", b"property list uchar z")
    _raises(data, InvalidFragmentError, "malformed property")


def test_ply_non_utf8_comment_is_fine(points):
    data = encode_ply(points).replace(b"comment floorplan-jigsaw", b"comment caf\xe9 \xff")
    assert len(parse_fragment(data, LIMITS).points) == N


def test_ply_binary_list_element_before_vertex(points):
    enc = "binary_little_endian"
    data = _ply(enc, _faces(enc, 4, N), _element(enc, "vertex", _xyz_cols(points)))
    _raises(data, InvalidFragmentError, "list", "before the vertex")


def test_ply_vertex_with_list_property():
    data = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
    data += b"property float z\nproperty list uchar int ids\nend_header\n1 2 3 2 0 1\n"
    _raises(data, InvalidFragmentError, "list properties", "not supported")


@pytest.mark.parametrize("binary", [True, False])
def test_too_few_finite_points(points, binary):
    pts = points[:12].copy()
    pts[:5] = np.nan  # 7 finite left
    limits = ParserLimits(min_points=10)
    _raises(encode_ply(pts, binary=binary), InvalidFragmentError, "7", "10", limits=limits)
    _raises(encode_pcd(pts, binary=binary), InvalidFragmentError, "7", "10", limits=limits)


def test_too_many_points_declared(points):
    limits = ParserLimits(min_points=1, max_points=N - 1)
    for data in (encode_ply(points), encode_ply(points, binary=False), encode_pcd(points)):
        _raises(data, FragmentTooLargeError, str(N), str(N - 1), limits=limits)


def test_huge_declared_count_is_rejected_before_allocating():
    # 10^12 vertices over a few bytes: must be "too large", not a MemoryError or "truncated".
    ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\n"
    ply += b"property float x\nproperty float y\nproperty float z\nend_header\n\x00\x00"
    _raises(ply, FragmentTooLargeError, "1000000000000")
    pcd = _pcd("x y z", "4 4 4", "F F F", "1 1 1", b"", width=10**12, height=1, data="binary")
    _raises(pcd, FragmentTooLargeError, "1000000000000")


def test_pcd_binary_truncated(points):
    _raises(encode_pcd(points)[:-1], InvalidFragmentError, "truncated")


def test_pcd_ascii_truncated(points):
    data = encode_pcd(points, binary=False)
    _raises(data[: data.rstrip(b"\n").rindex(b"\n")], InvalidFragmentError, "truncated")


def test_pcd_binary_trailing_garbage(points):
    _raises(encode_pcd(points) + b"\n", InvalidFragmentError, "inconsistent")


def test_pcd_ascii_extra_values(points):
    _raises(encode_pcd(points, binary=False) + b"1 2 3\n", InvalidFragmentError, "inconsistent")


def test_pcd_missing_data_line(points):
    data = encode_pcd(points, binary=False).replace(b"DATA ascii", b"DATUM ascii")
    # The DATUM line is taken as an unknown header key; no DATA line ever follows.
    _raises(data.split(b"DATUM")[0], InvalidFragmentError, "no DATA line")


def test_pcd_binary_compressed_not_supported(points):
    data = encode_pcd(points).replace(b"DATA binary", b"DATA binary_compressed")
    _raises(data, InvalidFragmentError, "binary_compressed", "not supported")


def test_pcd_missing_z(points):
    body = encode_pcd(points[:, :2].repeat([1, 2], axis=1), binary=False).split(b"DATA ascii\n")[1]
    data = _pcd("x y w", "4 4 4", "F F F", "1 1 1", body, width=N, height=1, data="ascii")
    _raises(data, InvalidFragmentError, "x/y/z", "missing z")


@pytest.mark.parametrize(
    ("replace", "words"),
    [
        ((b"TYPE F F F", b"TYPE F F Q"), ("unknown field type",)),
        ((b"SIZE 4 4 4", b"SIZE 4 4 2"), ("unknown field type",)),
        ((b"SIZE 4 4 4", b"SIZE 4 4"), ("inconsistent", "length")),
        ((b"SIZE 4 4 4\n", b""), ("no SIZE",)),
        ((b"FIELDS x y z\n", b""), ("no FIELDS",)),
        ((b"COUNT 1 1 1", b"COUNT 1 1 0"), ("COUNT",)),
        ((b"COUNT 1 1 1", b"COUNT 1 1 3"), ("x/y/z", "COUNT 1")),
        ((b"POINTS 50", b"POINTS 49"), ("inconsistent", "POINTS")),
        ((b"WIDTH 50", b"WIDTH fifty"), ("non-integer", "WIDTH")),
        ((b"DATA binary", b"DATA packed"), ("unknown DATA",)),
    ],
)
def test_pcd_malformed_header(points, replace, words):
    data = encode_pcd(points)
    assert replace[0] in data
    _raises(data.replace(*replace), InvalidFragmentError, *words)


@pytest.mark.parametrize(
    "data",
    [
        encode_ply(np.ones((20, 3))),
        encode_ply(np.ones((20, 3)), binary=False),
        encode_pcd(np.ones((20, 3))),
        encode_pcd(np.ones((20, 3)), binary=False),
    ],
    ids=["ply-bin", "ply-ascii", "pcd-bin", "pcd-ascii"],
)
def test_any_truncation_or_corruption_raises_only_fragment_errors(data):
    # Cut at every byte and flip header bytes: success or a FragmentError, never a raw error.
    rng = np.random.default_rng(5)
    variants = [data[:cut] for cut in range(len(data))]
    for _ in range(200):
        corrupt = bytearray(data)
        corrupt[int(rng.integers(4, 120))] = int(rng.integers(0, 256))
        variants.append(bytes(corrupt))
    for variant in variants:
        with contextlib.suppress(FragmentError):
            parse_fragment(variant, LIMITS)
