"""RGB-D frames from bytes: decoding, every refusal with its code, back-projection."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from schemas.frames import FrameParams, IntrinsicsModel
from schemas.params import ParserLimits
from services.errors import (
    ColorSizeError,
    EmptyDepthError,
    InvalidDepthError,
    InvalidIntrinsicsError,
    MissingFrameFileError,
)
from services.rgbd import OPTICAL_TO_LEVEL, RgbdFrame, backproject, decode_frame, encode_frame_files

pytestmark = pytest.mark.timeout(30)

K = IntrinsicsModel(width=64, height=48, fx=50.0, fy=50.0, cx=32.0, cy=24.0)
LIMITS = ParserLimits(min_points=10)


def _files(depth: np.ndarray | None = None, color: bool = True) -> dict[str, bytes]:
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.5, 3.0, (48, 64)).astype(np.float32) if depth is None else depth
    rgb = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8) if color else None
    return encode_frame_files(depth, K, rgb)


def _png(image: np.ndarray) -> bytes:
    return cv2.imencode(".png", image)[1].tobytes()


def test_round_trip_keeps_depth_to_the_millimetre_and_colour() -> None:
    files = _files()
    frame = decode_frame(files, limits=LIMITS)
    again = decode_frame(encode_frame_files(frame.depth, K, frame.color), limits=LIMITS)
    np.testing.assert_array_equal(again.depth, frame.depth)
    np.testing.assert_array_equal(again.color, frame.color)
    assert frame.shape == (48, 64) and frame.depth.dtype == np.float32
    jpg = decode_frame(encode_frame_files(frame.depth, K, frame.color, "jpg"), limits=LIMITS)
    assert jpg.color is not None and jpg.color.shape == (48, 64, 3)


def test_depth_scale_of_the_intrinsics_is_applied() -> None:
    tum = K.model_copy(update={"depth_scale": 5000.0})
    raw = np.full((48, 64), 10000, dtype=np.uint16)  # 2 m at 5000 per meter
    files = {"depth.png": _png(raw), "intrinsics.json": tum.model_dump_json().encode()}
    assert float(decode_frame(files, limits=LIMITS).depth[0, 0]) == pytest.approx(2.0)


@pytest.mark.parametrize(
    ("change", "error", "code"),
    [
        (lambda f: f.pop("intrinsics.json"), MissingFrameFileError, "missing_frame_file"),
        (lambda f: f.pop("depth.png"), MissingFrameFileError, "missing_frame_file"),
        (
            lambda f: f.update({"intrinsics.json": b"{"}),
            InvalidIntrinsicsError,
            "invalid_intrinsics",
        ),
        (
            lambda f: f.update({"intrinsics.json": b'{"width": 64, "height": 48, "fx": 50}'}),
            InvalidIntrinsicsError,
            "invalid_intrinsics",
        ),
        (
            lambda f: f.update(
                {"intrinsics.json": K.model_copy(update={"width": 65}).model_dump_json().encode()}
            ),
            InvalidIntrinsicsError,
            "invalid_intrinsics",
        ),
        (
            lambda f: f.update({"depth.png": _png(np.full((48, 64), 9, np.uint8))}),
            InvalidDepthError,
            "invalid_depth",
        ),
        (
            lambda f: f.update({"depth.png": _png(np.full((48, 64, 3), 9, np.uint8))}),
            InvalidDepthError,
            "invalid_depth",
        ),
        (
            lambda f: f.update({"depth.png": f["depth.png"][:200]}),
            InvalidDepthError,
            "invalid_depth",
        ),
        (lambda f: f.update({"depth.png": b"not a png"}), InvalidDepthError, "invalid_depth"),
        (
            lambda f: f.update({"depth.png": _png(np.zeros((48, 64), np.uint16))}),
            EmptyDepthError,
            "empty_depth",
        ),
        (
            lambda f: f.update({"color.png": _png(np.zeros((47, 64, 3), np.uint8))}),
            ColorSizeError,
            "invalid_color",
        ),
        (lambda f: f.update({"color.png": b"junk"}), ColorSizeError, "invalid_color"),
    ],
)
def test_bad_frames_are_refused_with_their_code(change, error, code) -> None:
    files = _files()
    change(files)
    with pytest.raises(error) as caught:
        decode_frame(files, limits=LIMITS)
    assert caught.value.code == code


def test_intrinsics_outside_the_image_are_invalid() -> None:
    with pytest.raises(ValueError, match="principal point"):
        IntrinsicsModel(width=64, height=48, fx=50, fy=50, cx=80, cy=24)


def test_depth_out_of_range_is_dropped_and_none_left_is_empty() -> None:
    far = np.full((48, 64), 20.0, dtype=np.float32)  # beyond the 10 m default
    with pytest.raises(EmptyDepthError):
        decode_frame(_files(far), limits=LIMITS)


def test_backprojection_is_the_pinhole_model_in_the_optical_frame() -> None:
    depth = np.zeros((48, 64), dtype=np.float32)
    depth[24, 32], depth[0, 0], depth[47, 63] = 2.0, 1.0, 0.05  # centre, corner, too near
    frame = RgbdFrame(depth, K)
    points, mask = backproject(frame, FrameParams())
    assert mask.sum() == 2
    np.testing.assert_allclose(points[0], [(0 - 32) / 50, (0 - 24) / 50, 1.0])
    np.testing.assert_allclose(points[1], [0.0, 0.0, 2.0])
    # Optical y points down: in the level frame, z is up.
    np.testing.assert_allclose(OPTICAL_TO_LEVEL @ [0.0, 1.0, 0.0], [0.0, 0.0, -1.0])
    assert np.linalg.det(OPTICAL_TO_LEVEL) == pytest.approx(1.0)
