"""ROS 2 depth cameras: an ``Image`` paired with its ``CameraInfo`` becomes an RGB-D upload.

A camera driver publishes the depth image and its ``CameraInfo`` on two topics with the same
``header.stamp`` and ``header.frame_id``; they arrive in either order, and either may be lost.
:class:`DepthPairer` keeps the unpaired ones of one camera for a bounded time and number, and
:func:`frame_archive` turns a pair into the zip archive of ``depth.png`` and
``intrinsics.json`` a client would upload, so the frame takes the one ingest path with the
same checks and error codes as an uploaded frame (contract v2, section 1).
"""

from __future__ import annotations

import io
import json
import time
import zipfile
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, TypeVar

from api.zenoh.ros2 import DecodedCameraInfo, DecodedDepth
from services.rgbd import encode_frame_files, parse_intrinsics

__all__ = ["DepthPair", "DepthPairer", "frame_archive"]

StampKey = tuple[int, int, str]  # header.stamp.sec, header.stamp.nanosec, header.frame_id

_INFOS_KEPT = 64  # CameraInfos are a few hundred bytes: keep more than images
_Item = TypeVar("_Item", DecodedDepth, DecodedCameraInfo)


@dataclass(frozen=True)
class DepthPair:
    """A depth image and the CameraInfo of the same stamp and frame."""

    image: DecodedDepth
    info: DecodedCameraInfo


def _key(item: DecodedDepth | DecodedCameraInfo) -> StampKey:
    return item.stamp_sec, item.stamp_nanosec, item.frame_id


class _Waiting(Generic[_Item]):
    """Messages waiting for their pair, oldest first, each with its arrival time."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.items: OrderedDict[StampKey, tuple[float, _Item]] = OrderedDict()

    def add(self, item: _Item, now: float) -> list[_Item]:
        """Keep ``item``; returns those pushed out (oldest first) to stay within the limit."""
        self.items[_key(item)] = (now, item)
        self.items.move_to_end(_key(item))
        pushed = []
        while len(self.items) > self.limit:
            pushed.append(self.items.popitem(last=False)[1][1])
        return pushed

    def expire(self, before: float) -> list[_Item]:
        """Drop and return the items that arrived before ``before``."""
        old = [key for key, (arrived, _) in self.items.items() if arrived < before]
        return [self.items.pop(key)[1] for key in old]


class DepthPairer:
    """Pairs one camera's depth images with its CameraInfos by stamp and frame id.

    An unpaired message waits ``wait_s`` seconds; at most ``max_images`` images wait (the
    oldest is dropped first). Images dropped unpaired are returned to the caller to log.
    Not thread-safe: the bridge calls it from the event loop only.
    """

    def __init__(
        self, wait_s: float, max_images: int, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.wait_s, self.clock = wait_s, clock
        self._images: _Waiting[DecodedDepth] = _Waiting(max_images)
        self._infos: _Waiting[DecodedCameraInfo] = _Waiting(_INFOS_KEPT)

    @property
    def waiting(self) -> int:
        """Images waiting for their CameraInfo."""
        return len(self._images.items)

    def add_image(self, image: DecodedDepth) -> tuple[DepthPair | None, list[DecodedDepth]]:
        """``(pair, images dropped unpaired)`` after ``image`` arrived."""
        dropped = self.expire()
        found = self._infos.items.pop(_key(image), None)
        if found is not None:
            return DepthPair(image, found[1]), dropped
        return None, dropped + self._images.add(image, self.clock())

    def add_info(self, info: DecodedCameraInfo) -> tuple[DepthPair | None, list[DecodedDepth]]:
        """``(pair, images dropped unpaired)`` after ``info`` arrived."""
        dropped = self.expire()
        found = self._images.items.pop(_key(info), None)
        if found is not None:
            return DepthPair(found[1], info), dropped
        self._infos.add(info, self.clock())
        return None, dropped

    def expire(self) -> list[DecodedDepth]:
        """Drop what waited longer than ``wait_s``; returns the images dropped."""
        before = self.clock() - self.wait_s
        self._infos.expire(before)
        return self._images.expire(before)


def frame_archive(pair: DepthPair) -> bytes:
    """The upload of a pair: a zip of ``depth.png`` (millimetres) and ``intrinsics.json``
    (size and ``K`` of the CameraInfo, which is checked against the image on ingest).

    Raises
    ------
    InvalidIntrinsicsError
        The CameraInfo is no usable pinhole camera (zero size or focal length, ...), as an
        uploaded ``intrinsics.json`` would be refused.
    """
    info = pair.info
    fields: dict[str, float] = {"width": info.width, "height": info.height}
    fields |= {"fx": info.fx, "fy": info.fy, "cx": info.cx, "cy": info.cy}
    intrinsics = parse_intrinsics(json.dumps(fields).encode())
    out = io.BytesIO()
    # Stored, not deflated: the PNG is compressed already and ingest compresses what it keeps.
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as archive:
        for name, data in encode_frame_files(pair.image.depth, intrinsics).items():
            archive.writestr(name, data)
    return out.getvalue()
