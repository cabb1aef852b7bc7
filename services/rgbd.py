"""RGB-D frames (contract v2, section 1): decode from bytes, check, back-project.

A frame's local frame is the camera's optical frame: x right, y down, z forward, meters; its
up axis is about -y. Decoding works on the files' bytes (the zip archive is opened by the
callers, :mod:`services.uploads` and :mod:`cli.frames`); nothing here reads a file.
"""

from __future__ import annotations

import io
import struct
import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray
from PIL import Image
from pydantic import ValidationError

from schemas.frames import FrameParams, IntrinsicsModel
from schemas.params import ParserLimits
from schemas.validation import summarize_errors
from services.errors import (
    ColorSizeError,
    EmptyDepthError,
    InvalidDepthError,
    InvalidFragmentError,
    InvalidIntrinsicsError,
    MissingFrameFileError,
)
from services.types import FloatArray

__all__ = [
    "COLOR_NAMES",
    "DEPTH_NAME",
    "INTRINSICS_NAME",
    "OPTICAL_TO_LEVEL",
    "RgbdFrame",
    "backproject",
    "decode_color",
    "decode_depth",
    "decode_frame",
    "encode_frame_files",
    "parse_intrinsics",
    "valid_depth",
]

DEPTH_NAME = "depth.png"
INTRINSICS_NAME = "intrinsics.json"
COLOR_NAMES = ("color.png", "color.jpg")

OPTICAL_TO_LEVEL: FloatArray = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
"""(3, 3) rotation from the optical frame (x right, y down, z forward) to the camera's level
frame (x right, y forward, z up): ``level = OPTICAL_TO_LEVEL @ optical``."""

_DEFAULTS = FrameParams()
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_PNG_GRAY = 0  # IHDR colour type of a single-channel image


@dataclass(frozen=True)
class RgbdFrame:
    """One decoded RGB-D frame.

    depth: (H, W) float32, meters along the optical axis, 0 where there is no reading.
    intrinsics: the pinhole camera (pixels) of the depth image.
    color: (H, W, 3) uint8 RGB, or None.
    """

    depth: NDArray[np.float32]
    intrinsics: IntrinsicsModel
    color: NDArray[np.uint8] | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) of the images."""
        return int(self.depth.shape[0]), int(self.depth.shape[1])


def parse_intrinsics(data: bytes) -> IntrinsicsModel:
    """Decode ``intrinsics.json``.

    Raises
    ------
    InvalidIntrinsicsError
        Not JSON, a field missing, or invalid values.

    >>> text = b'{"width": 4, "height": 3, "fx": 2, "fy": 2, "cx": 2, "cy": 1.5}'
    >>> parse_intrinsics(text).depth_scale
    1000.0
    """
    try:
        return IntrinsicsModel.model_validate_json(data)
    except ValidationError as exc:
        raise InvalidIntrinsicsError(
            f"{INTRINSICS_NAME}: {summarize_errors(exc.errors())}"
        ) from exc


def _png_header(data: bytes) -> tuple[int, int, int, int]:
    """(width, height, bit depth, colour type) from a PNG's IHDR chunk."""
    if len(data) < 33 or not data.startswith(_PNG_MAGIC) or data[12:16] != b"IHDR":
        raise InvalidDepthError(f"{DEPTH_NAME}: not a PNG image")
    width, height, depth, colour = struct.unpack(">IIBB", data[16:26])
    return width, height, depth, colour


def decode_depth(data: bytes, intrinsics: IntrinsicsModel, max_pixels: int) -> NDArray[np.float32]:
    """Decode ``depth.png`` into meters.

    Parameters
    ----------
    data : the PNG's bytes: 16-bit, one channel.
    intrinsics : its size and ``depth_scale`` (value per meter).
    max_pixels : largest width x height decoded (checked on the header first).

    Returns
    -------
    (H, W) float32, meters; 0 where the value is 0 (no reading).

    Raises
    ------
    InvalidDepthError
        Not a PNG, 8-bit or more than one channel, corrupt or truncated.
    InvalidIntrinsicsError
        The image's size differs from the intrinsics' width and height.
    """
    width, height, bits, colour = _png_header(data)
    if colour != _PNG_GRAY or bits != 16:
        kind = {0: "grey", 2: "RGB", 3: "palette", 4: "grey+alpha", 6: "RGBA"}.get(colour, "?")
        raise InvalidDepthError(
            f"{DEPTH_NAME}: {bits}-bit {kind} image; depth must be a 16-bit single-channel PNG"
        )
    if (width, height) != (intrinsics.width, intrinsics.height):
        raise InvalidIntrinsicsError(
            f"{INTRINSICS_NAME} says {intrinsics.width}x{intrinsics.height}, "
            f"{DEPTH_NAME} is {width}x{height}"
        )
    if width * height > max_pixels:
        raise InvalidDepthError(f"{DEPTH_NAME}: {width}x{height} exceeds {max_pixels} pixels")
    raw = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if raw is None or raw.dtype != np.uint16 or raw.shape != (height, width):
        raise InvalidDepthError(f"{DEPTH_NAME}: corrupt or truncated PNG")
    depth: NDArray[np.float32] = raw.astype(np.float32) / np.float32(intrinsics.depth_scale)
    return depth


def decode_color(data: bytes, shape: tuple[int, int], name: str = "color") -> NDArray[np.uint8]:
    """Decode a colour PNG or JPEG of the depth image's ``(height, width)`` to RGB.

    Raises
    ------
    ColorSizeError
        Not an image, corrupt, or of another size (checked on the header first).
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(io.BytesIO(data)) as image:
                size = image.size  # (width, height), read from the header only
    except (OSError, ValueError, Image.DecompressionBombWarning, Image.DecompressionBombError) as e:
        raise ColorSizeError(f"{name}: not a readable image ({e})") from e
    if (size[1], size[0]) != shape:
        raise ColorSizeError(
            f"{name} is {size[0]}x{size[1]}, the depth image {shape[1]}x{shape[0]}"
        )
    bgr = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
    if bgr is None or bgr.shape[:2] != shape:
        raise ColorSizeError(f"{name}: corrupt or truncated image")
    rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    return np.asarray(rgb, dtype=np.uint8)


def valid_depth(depth: NDArray[np.float32], params: FrameParams) -> NDArray[np.bool_]:
    """(H, W) mask of readings inside the depth range (0 and NaN are never valid)."""
    mask: NDArray[np.bool_] = (depth >= params.min_depth) & (depth <= params.max_depth)
    return mask


def decode_frame(
    files: Mapping[str, bytes],
    params: FrameParams = _DEFAULTS,
    limits: ParserLimits = ParserLimits(),
) -> RgbdFrame:
    """Decode and check a frame from its files' bytes.

    Parameters
    ----------
    files : file name -> bytes: ``depth.png``, ``intrinsics.json``, optionally ``color.png``
        or ``color.jpg``; other names are ignored.
    params : depth range and the largest image.
    limits : ``min_points``: fewest readings in the depth range a usable frame has.

    Raises
    ------
    MissingFrameFileError, InvalidIntrinsicsError, InvalidDepthError, EmptyDepthError,
    ColorSizeError, InvalidFragmentError
        What is wrong, in that order of checks.
    """
    for name in (DEPTH_NAME, INTRINSICS_NAME):
        if name not in files:
            raise MissingFrameFileError(f"the frame has no {name}")
    intrinsics = parse_intrinsics(files[INTRINSICS_NAME])
    depth = decode_depth(files[DEPTH_NAME], intrinsics, params.max_pixels)
    readings = int(np.count_nonzero(depth))
    if readings == 0:
        raise EmptyDepthError(f"{DEPTH_NAME}: every value is 0 (no reading)")
    usable = int(np.count_nonzero(valid_depth(depth, params)))
    if usable == 0:
        raise EmptyDepthError(
            f"{DEPTH_NAME}: no reading within {params.min_depth} to {params.max_depth} m "
            f"(depth_scale {intrinsics.depth_scale} per meter)"
        )
    if usable < limits.min_points:
        raise InvalidFragmentError(
            f"{DEPTH_NAME}: {usable} readings in the depth range, fewer than the minimum of "
            f"{limits.min_points}"
        )
    colors = [name for name in COLOR_NAMES if name in files]
    if len(colors) > 1:
        raise ColorSizeError("the frame has both color.png and color.jpg")
    color = decode_color(files[colors[0]], depth.shape, colors[0]) if colors else None
    return RgbdFrame(depth=depth, intrinsics=intrinsics, color=color)


def backproject(
    frame: RgbdFrame, params: FrameParams = _DEFAULTS, stride: int = 1
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Points of the valid readings, optical frame.

    Parameters
    ----------
    frame : the decoded frame.
    params : the depth range.
    stride : use every ``stride``-th row and column.

    Returns
    -------
    points : (N, 3) float64, optical frame (x right, y down, z forward), meters.
    mask : (H', W') bool over the strided image, True where a point was made (row-major,
        the order of ``points``).
    """
    k = frame.intrinsics
    depth = frame.depth[::stride, ::stride]
    mask = valid_depth(depth, params)
    rows, cols = np.nonzero(mask)
    z = depth[mask].astype(np.float64)
    # Offsets from the principal point per column and row, gathered: cheaper than computing
    # them per pixel, and the same numbers.
    x = (np.arange(depth.shape[1]) * stride - k.cx)[cols] * z / k.fx
    y = (np.arange(depth.shape[0]) * stride - k.cy)[rows] * z / k.fy
    points = np.empty((len(z), 3))
    points[:, 0], points[:, 1], points[:, 2] = x, y, z
    return points, mask


def encode_frame_files(
    depth: NDArray[np.float32],
    intrinsics: IntrinsicsModel,
    color: NDArray[np.uint8] | None = None,
    color_format: str = "png",
) -> dict[str, bytes]:
    """The files of a frame (the inverse of :func:`decode_frame`), as bytes.

    depth: (H, W) meters (0: no reading), stored as ``round(depth * depth_scale)`` in 16 bits.
    color: (H, W, 3) uint8 RGB, stored as ``color.png`` or ``color.jpg``.
    """
    scaled = np.clip(np.rint(depth * intrinsics.depth_scale), 0, 65535).astype(np.uint16)
    ok, png = cv2.imencode(".png", scaled)
    if not ok:
        raise ValueError("depth image could not be encoded")
    files = {
        DEPTH_NAME: png.tobytes(),
        INTRINSICS_NAME: intrinsics.model_dump_json().encode(),
    }
    if color is not None:
        ok, encoded = cv2.imencode(f".{color_format}", cv2.cvtColor(color, cv2.COLOR_RGB2BGR))
        if not ok:
            raise ValueError("colour image could not be encoded")
        files[f"color.{color_format}"] = encoded.tobytes()
    return files
