"""Top-view pictures (PNG and SVG) of fragments and layouts, without plotting libraries.

PNG is rasterised with numpy and encoded with zlib; SVG is written as text.
"""

from __future__ import annotations

import itertools
import struct
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from services.types import FloatArray

__all__ = ["Canvas", "encode_png", "palette"]

_PALETTE = np.array(
    [
        [31, 119, 180],
        [255, 127, 14],
        [44, 160, 44],
        [214, 39, 40],
        [148, 103, 189],
        [140, 86, 75],
        [227, 119, 194],
        [127, 127, 127],
        [188, 189, 34],
        [23, 190, 207],
    ],
    dtype=np.uint8,
)


def palette(index: int) -> tuple[int, int, int]:
    """A distinct colour per fragment index."""
    r, g, b = _PALETTE[index % len(_PALETTE)]
    return int(r), int(g), int(b)


def encode_png(image: NDArray[np.uint8]) -> bytes:
    """Encode an (H, W, 3) uint8 image as PNG bytes."""
    h, w, _ = image.shape
    raw = np.concatenate([np.zeros((h, 1), np.uint8), image.reshape(h, w * 3)], axis=1)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data))
            + kind
            + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
        )

    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(raw.tobytes(), 6))
        + chunk(b"IEND", b"")
    )


@dataclass
class Canvas:
    """A top view of a region in meters; draw points and polylines, then export.

    bounds: (xmin, ymin, xmax, ymax) of the drawn region; ``scale`` pixels per meter.
    """

    bounds: tuple[float, float, float, float]
    scale: float = 60.0
    margin: int = 20
    _svg: list[str] = field(default_factory=list)
    _image: NDArray[np.uint8] = field(init=False)

    def __post_init__(self) -> None:
        xmin, ymin, xmax, ymax = self.bounds
        self.width = int((xmax - xmin) * self.scale) + 2 * self.margin
        self.height = int((ymax - ymin) * self.scale) + 2 * self.margin
        self._image = np.full((self.height, self.width, 3), 255, np.uint8)

    def _pixels(self, xy: FloatArray) -> NDArray[np.int64]:
        xmin, ymin, _, _ = self.bounds
        col = (xy[:, 0] - xmin) * self.scale + self.margin
        row = self.height - ((xy[:, 1] - ymin) * self.scale + self.margin)
        return np.column_stack([col, row]).astype(np.int64)

    def points(self, xy: FloatArray, colour: tuple[int, int, int], max_svg: int = 4000) -> None:
        """Scatter points (light), vectorised."""
        px = self._pixels(xy)
        ok = (px[:, 0] >= 0) & (px[:, 0] < self.width) & (px[:, 1] >= 0) & (px[:, 1] < self.height)
        light = (np.array(colour) * 0.55 + 255 * 0.45).astype(np.uint8)
        self._image[px[ok, 1], px[ok, 0]] = light
        stride = max(1, len(xy) // max_svg)
        svg_px = px[ok][::stride]
        fill = "rgb({},{},{})".format(*light)
        self._svg.extend(
            f'<circle cx="{c}" cy="{r}" r="1" fill="{fill}"/>' for c, r in svg_px.tolist()
        )

    def polyline(
        self, xy: FloatArray, colour: tuple[int, int, int], width: int = 3, closed: bool = False
    ) -> None:
        """A thick polyline with round joints."""
        if len(xy) < 2:
            return
        pts = np.vstack([xy, xy[:1]]) if closed else xy
        px = self._pixels(pts)
        for a, b in itertools.pairwise(px):
            n = int(np.abs(b - a).max()) + 1
            line = np.rint(a + (b - a) * np.linspace(0, 1, n)[:, None]).astype(np.int64)
            for dr in range(-(width // 2), width // 2 + 1):
                for dc in range(-(width // 2), width // 2 + 1):
                    r = np.clip(line[:, 1] + dr, 0, self.height - 1)
                    c = np.clip(line[:, 0] + dc, 0, self.width - 1)
                    self._image[r, c] = colour
        path = " ".join(f"{c},{r}" for c, r in px.tolist())
        tag = "polygon" if closed else "polyline"
        self._svg.append(
            f'<{tag} points="{path}" fill="none" stroke="rgb({colour[0]},{colour[1]},{colour[2]})"'
            f' stroke-width="{width}"/>'
        )

    def marks(self, xy: FloatArray, colour: tuple[int, int, int], size: int = 4) -> None:
        """Square markers (e.g. keypoints)."""
        for c, r in self._pixels(xy).tolist():
            self._image[max(0, r - size) : r + size + 1, max(0, c - size) : c + size + 1] = colour
            self._svg.append(
                f'<rect x="{c - size}" y="{r - size}" width="{2 * size}" height="{2 * size}" '
                f'fill="rgb({colour[0]},{colour[1]},{colour[2]})"/>'
            )

    def label(self, xy: Sequence[float], text: str) -> None:
        """Text (SVG only; the PNG stays label-free)."""
        ((c, r),) = self._pixels(np.asarray([xy], dtype=np.float64)).tolist()
        self._svg.append(
            f'<text x="{c}" y="{r}" font-size="14" font-family="sans-serif">{text}</text>'
        )

    def scale_bar(self, meters: float = 1.0) -> None:
        """A scale bar in the lower left corner."""
        xmin, ymin, _, _ = self.bounds
        start = np.array([[xmin, ymin - 0.15]])
        self.polyline(np.vstack([start, start + np.array([meters, 0.0])]), (0, 0, 0), width=2)
        self.label((xmin, ymin - 0.05), f"{meters:g} m")

    def png(self) -> bytes:
        """The picture as PNG bytes."""
        return encode_png(self._image)

    def svg(self) -> str:
        """The picture as an SVG document."""
        body = "\n".join(self._svg)
        return (
            f'<svg xmlns="http://www.w3.org/2000/svg" width="{self.width}" height="{self.height}">'
            f'<rect width="100%" height="100%" fill="white"/>\n{body}\n</svg>\n'
        )
