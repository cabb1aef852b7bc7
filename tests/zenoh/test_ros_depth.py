"""ROS 2 depth cameras over rmw_zenoh: Image + CameraInfo (CDR) in, RGB-D fragments stored."""

from __future__ import annotations

import contextlib
import re
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
import zenoh
from pydantic import ValidationError

from api.zenoh import ros2
from api.zenoh.ros_depth import DepthPair, DepthPairer, frame_archive
from schemas.settings import DepthTopic
from services.errors import InvalidDepthError, InvalidIntrinsicsError
from services.rgbd import RgbdFrame
from services.uploads import decode_upload
from tests.frame_fixtures import three_frames
from tests.service_fixtures import make_settings, wait_until
from tests.zenoh.conftest import (
    ROS_DEPTH2_INFO_TOPIC,
    ROS_DEPTH2_SITE,
    ROS_DEPTH2_TOPIC,
    ROS_DEPTH_WAIT_S,
    ZenohService,
    robot_session,
)

pytestmark = pytest.mark.timeout(90)


def depth_pixels(depth: np.ndarray, encoding: str) -> np.ndarray:
    """A depth image's pixels as a camera driver sends them: mm (16UC1) or meters (32FC1)."""
    if encoding == "16UC1":
        return np.rint(depth * 1000.0).astype(np.uint16)
    return np.where(depth > 0, depth, np.nan).astype(np.float32)  # REP 118: NaN, no reading


def camera_info(frame: RgbdFrame, stamp: tuple[int, int], frame_id: str, **size: int) -> bytes:
    k = frame.intrinsics
    width, height = size.get("width", k.width), size.get("height", k.height)
    return ros2.encode_camera_info(width, height, (k.fx, k.fy, k.cx, k.cy), *stamp, frame_id)


@dataclass
class Camera:
    """A ROS 2 depth camera on rmw_zenoh: an Image and a CameraInfo publisher."""

    image: zenoh.Publisher
    info: zenoh.Publisher
    gid: bytes
    sequence: int = 0

    def put(self, publisher: zenoh.Publisher, cdr: bytes) -> None:
        self.sequence += 1
        attachment = ros2.encode_attachment(self.sequence, time.time_ns(), self.gid)
        publisher.put(cdr, attachment=attachment)

    def send(
        self,
        frame: RgbdFrame,
        stamp: tuple[int, int],
        encoding: str = "16UC1",
        *,
        info_first: bool = False,
        frame_id: str = "camera_depth_optical_frame",
    ) -> None:
        """Publish the frame's depth image and its CameraInfo (same stamp and frame)."""
        image = ros2.encode_image(depth_pixels(frame.depth, encoding), encoding, *stamp, frame_id)
        info = camera_info(frame, stamp, frame_id)
        for publisher, cdr in ((self.info, info), (self.image, image))[:: 1 if info_first else -1]:
            self.put(publisher, cdr)


@contextlib.contextmanager
def camera(session: zenoh.Session, image_topic: str, info_topic: str) -> Iterator[Camera]:
    """A camera publishing on ``image_topic`` and ``info_topic``, matched by the service."""
    image_key = ros2.topic_key(0, image_topic, ros2.IMAGE_TYPE, ros2.type_hash(ros2.IMAGE_TYPE))
    info_hash = ros2.type_hash(ros2.CAMERA_INFO_TYPE)
    info_key = ros2.topic_key(0, info_topic, ros2.CAMERA_INFO_TYPE, info_hash)
    block = zenoh.CongestionControl.BLOCK  # a burst of images must not be dropped under load
    with (
        session.declare_publisher(image_key, congestion_control=block) as image,
        session.declare_publisher(info_key, congestion_control=block) as info,
    ):
        publishers: list[Any] = [image, info]  # the stubs call matching_status a bool
        wait_until(lambda: all(p.matching_status.matching for p in publishers), 10)
        yield Camera(image, info, ros2.entity_gid(f"test camera {image_topic}"))


def _taller(cdr: bytes) -> bytes:
    """The image claiming twice its height: its data no longer fits."""
    store = ros2._store()
    msg: Any = store.deserialize_cdr(cdr, ros2.IMAGE_TYPE)
    msg.height *= 2
    return bytes(store.serialize_cdr(msg, ros2.IMAGE_TYPE))


def depth_metrics(service: ZenohService) -> dict[str, float]:
    """``fpj_ros_depth_images_total`` of the service by outcome."""
    with service.http() as http:
        text = http.get("/metrics").text
    pattern = r'^fpj_ros_depth_images_total\{outcome="([^"]+)"\} (\S+)$'
    return {m[1]: float(m[2]) for m in re.finditer(pattern, text, re.MULTILINE)}


# ------------------------------------------------------------------ settings, codec, pairing


def test_depth_topic_settings() -> None:
    settings = make_settings(
        None,
        zenoh_ros_depth_topics="/robot1/depth/image_raw=lab, cam/depth:/cam/info=lab2",
    )
    assert settings.ros_depth_topics() == [
        DepthTopic("/robot1/depth/image_raw", "/robot1/depth/camera_info", "lab"),
        DepthTopic("/cam/depth", "/cam/info", "lab2"),
    ]
    assert settings.ros_enabled and not make_settings(None).ros_enabled
    assert make_settings(None, zenoh_ros_tf_topic="/tf").ros_enabled
    for bad in (
        {"zenoh_ros_depth_topics": "/robot1/depth"},  # no site
        {"zenoh_ros_depth_topics": "/robot1/depth:/bad info=lab"},
        {"zenoh_ros_map_topic": "map!"},
        {"zenoh_ros_map_resolution": 0.0},
    ):
        with pytest.raises(ValidationError):
            make_settings(None, **bad)


@pytest.mark.parametrize("encoding", ["16UC1", "32FC1"])
def test_depth_image_round_trip(encoding: str) -> None:
    depth = np.array([[0.0, 1.234, 2.5], [9.999, 0.0, 0.5]], dtype=np.float32)
    pixels = depth_pixels(depth, encoding)
    if encoding == "32FC1":
        pixels[1, 1] = np.inf  # REP 118: +inf is "too far", no reading either
    decoded = ros2.decode_depth_image(ros2.encode_image(pixels, encoding, 5, 6, "cam"))
    np.testing.assert_allclose(decoded.depth, depth, atol=1e-6)
    assert decoded.depth.dtype == np.float32
    assert (decoded.stamp_sec, decoded.stamp_nanosec, decoded.frame_id) == (5, 6, "cam")


def test_big_endian_depth_with_padded_rows() -> None:
    store = ros2._store()
    mm = np.array([[1000, 2000], [3000, 0]], dtype=">u2")
    rows = np.zeros((2, 6), dtype=np.uint8)  # 4 bytes of pixels, 2 of padding per row
    rows[:, :4] = mm.view(np.uint8).reshape(2, 4)
    msg = store.types[ros2.IMAGE_TYPE](
        header=ros2._header(1, 2, "cam"),
        height=2,
        width=2,
        encoding="16UC1",
        is_bigendian=1,
        step=6,
        data=rows.reshape(-1),
    )
    decoded = ros2.decode_depth_image(bytes(store.serialize_cdr(msg, ros2.IMAGE_TYPE)))
    np.testing.assert_allclose(decoded.depth, [[1.0, 2.0], [3.0, 0.0]])


@pytest.mark.parametrize(
    "cdr",
    [
        ros2.encode_image(np.zeros((4, 4, 3), np.uint8), "rgb8"),
        ros2.encode_image(np.zeros((4, 4), np.uint8), "mono8"),
        ros2.encode_image(np.zeros((4, 4), np.uint8), "16UC1"),  # half the data of 4x4 16-bit
        _taller(ros2.encode_image(np.zeros((4, 4), np.uint16), "16UC1")),
        b"\x00\x01\x00\x00" + b"\xff" * 16,
    ],
)
def test_bad_images_are_invalid_depth(cdr: bytes) -> None:
    with pytest.raises(InvalidDepthError) as caught:
        ros2.decode_depth_image(cdr)
    assert caught.value.code == "invalid_depth"


def test_camera_info_round_trip() -> None:
    info = ros2.decode_camera_info(ros2.encode_camera_info(640, 480, (525, 524, 319.5, 239), 1, 2))
    assert (info.width, info.height, info.fx, info.fy, info.cx, info.cy) == (
        640,
        480,
        525.0,
        524.0,
        319.5,
        239.0,
    )
    with pytest.raises(InvalidIntrinsicsError):
        ros2.decode_camera_info(b"\x00\x01\x00\x00")


def _image(sec: int, frame_id: str = "cam") -> ros2.DecodedDepth:
    return ros2.DecodedDepth(np.ones((2, 2), np.float32), sec, 0, frame_id, "16UC1")


def _info(sec: int, frame_id: str = "cam") -> ros2.DecodedCameraInfo:
    return ros2.DecodedCameraInfo(2, 2, 1.0, 1.0, 1.0, 1.0, sec, 0, frame_id)


def test_pairing_by_stamp_and_frame_in_either_order() -> None:
    now = [0.0]
    pairer = DepthPairer(wait_s=1.0, max_images=2, clock=lambda: now[0])
    assert pairer.add_image(_image(1)) == (None, [])
    assert pairer.add_info(_info(1, "other_cam")) == (None, [])  # same stamp, other frame
    pair, dropped = pairer.add_info(_info(1))
    assert pair is not None and (pair.image.stamp_sec, pair.info.stamp_sec) == (1, 1)
    assert pairer.add_info(_info(2)) == (None, [])  # CameraInfo first
    pair, _ = pairer.add_image(_image(2))
    assert pair is not None and pairer.waiting == 0
    # At most two images wait: a third pushes the oldest out.
    pairer.add_image(_image(3))
    pairer.add_image(_image(4))
    _, dropped = pairer.add_image(_image(5))
    assert [d.stamp_sec for d in dropped] == [3] and pairer.waiting == 2
    # After wait_s everything unpaired is dropped, CameraInfos too.
    now[0] = 1.5
    assert [d.stamp_sec for d in pairer.expire()] == [4, 5]
    assert pairer.add_image(_image(1, "other_cam")) == (None, [])


def test_frame_archive_is_the_upload_of_the_frame() -> None:
    frame = three_frames(0).frames[0].frame
    stamp = (7, 8)
    image = ros2.decode_depth_image(
        ros2.encode_image(depth_pixels(frame.depth, "16UC1"), "16UC1", *stamp, "cam")
    )
    info = ros2.decode_camera_info(camera_info(frame, stamp, "cam"))
    decoded = decode_upload(frame_archive(DepthPair(image, info)))
    assert isinstance(decoded, RgbdFrame)
    np.testing.assert_allclose(decoded.depth, frame.depth, atol=5e-4)
    assert decoded.intrinsics.model_dump() == frame.intrinsics.model_dump()
    # A CameraInfo of another size is refused as an upload's intrinsics.json would be.
    small = ros2.decode_camera_info(camera_info(frame, stamp, "cam", width=320))
    with pytest.raises(InvalidIntrinsicsError, match="320x480"):
        decode_upload(frame_archive(DepthPair(image, small)))
    zero = ros2.DecodedCameraInfo(640, 480, 0.0, 0.0, 0.0, 0.0, *stamp, "cam")
    with pytest.raises(InvalidIntrinsicsError):
        frame_archive(DepthPair(image, zero))


# ------------------------------------------------------------------ through the service


def test_depth_camera_frames_become_fragments_and_bad_ones_are_counted(
    zenoh_service: ZenohService,
) -> None:
    """One good 32FC1 frame is stored; wrong encoding, short data, a CameraInfo of another
    size and an image without CameraInfo are logged and counted, and store nothing."""
    frame = three_frames(0).frames[0].frame
    before = depth_metrics(zenoh_service)
    with (
        robot_session(zenoh_service) as session,
        camera(session, ROS_DEPTH2_TOPIC, ROS_DEPTH2_INFO_TOPIC) as cam,
    ):
        cam.send(frame, (1_700_000_100, 5), "32FC1")  # image first, then its CameraInfo
        bad: list[tuple[bytes, bytes]] = [
            (ros2.encode_image(np.zeros((480, 640, 3), np.uint8), "rgb8", 200, 0, "c"),
             camera_info(frame, (200, 0), "c")),
            (_taller(ros2.encode_image(np.zeros((480, 640), np.uint16), "16UC1", 201, 0, "c")),
             camera_info(frame, (201, 0), "c")),
            (ros2.encode_image(depth_pixels(frame.depth, "16UC1"), "16UC1", 202, 0, "c"),
             camera_info(frame, (202, 0), "c", height=240)),
            (ros2.encode_image(depth_pixels(frame.depth, "16UC1"), "16UC1", 203, 0, "c"),
             camera_info(frame, (203, 1), "c")),  # another stamp: never paired
        ]  # fmt: skip
        for image, info in bad:
            cam.put(cam.image, image)
            cam.put(cam.info, info)

        def counted() -> dict[str, float] | None:
            now = depth_metrics(zenoh_service)
            delta = {k: v - before.get(k, 0.0) for k, v in now.items()}
            return delta if sum(delta.values()) >= 5 else None

        delta = wait_until(counted, 10 + ROS_DEPTH_WAIT_S)
    assert {k: v for k, v in delta.items() if v} == {
        "accepted": 1.0,
        "invalid_depth": 2.0,
        "invalid_intrinsics": 1.0,
        "unpaired": 1.0,
    }
    with zenoh_service.http() as http:
        status: Any = http.get(f"/v1/sites/{ROS_DEPTH2_SITE}").json()
    [stored] = status["fragments"]
    assert stored["fragment_id"] == "robot3_1700000100_000000005"  # robot: the namespace
    assert stored["format"] == "rgbd" and stored["n_points"] > 1000
    log = zenoh_service.log.read_text(errors="replace")
    assert "dropped: no CameraInfo of the same stamp and frame" in log
    assert "depth Image on /robot3/depth rejected: invalid_depth" in log
