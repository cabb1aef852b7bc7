"""ROS 2 over rmw_zenoh without ROS: CDR PointCloud2 in, PoseStamped out, keys, attachments."""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
import pytest
import zenoh
from zenoh.ext import Int64, z_serialize

from api.zenoh import ros2
from api.zenoh.ros_bridge import cloud_fragment_id, topic_robot
from services.errors import InvalidFragmentError
from services.parsing import parse_fragment
from services.synthetic import SceneSpec, generate_scene
from tests.service_fixtures import make_settings, wait_until
from tests.zenoh.conftest import (
    ROS_CLOUD_TOPIC,
    ROS_POSE_TOPIC,
    ROS_SITE,
    ZenohService,
    robot_session,
)

pytestmark = pytest.mark.timeout(90)


def _cloud(n: int = 300, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-3.0, 3.0, size=(n, 3))


@pytest.mark.parametrize("double", [False, True])
def test_pointcloud2_round_trip_keeps_points_and_header(double: bool) -> None:
    points = _cloud()
    points[7] = np.nan  # an organized cloud's missing return
    cdr = ros2.encode_pointcloud2(points, 12, 345, "lidar_link", double=double, height=3)
    cloud = ros2.decode_pointcloud2(cdr)
    expected = points if double else points.astype(np.float32).astype(np.float64)
    np.testing.assert_array_equal(cloud.points, expected)
    assert (cloud.stamp_sec, cloud.stamp_nanosec, cloud.frame_id) == (12, 345, "lidar_link")
    parsed = parse_fragment(ros2.cloud_to_ply(cloud), make_settings(None).parser_limits())
    assert (len(parsed.points), parsed.dropped_nonfinite) == (299, 1)


def test_pointcloud2_with_row_padding_and_odd_layout() -> None:
    """x, y, z after another field, big-endian, rows padded past width * point_step."""
    store = ros2._store()
    types = store.types
    points = _cloud(12).astype(">f4")
    width, height, step, row = 4, 3, 16, 4 * 16 + 8
    data = np.zeros((height, row), dtype=np.uint8)
    records = np.zeros(12, dtype=[("i", ">u4"), ("x", ">f4"), ("y", ">f4"), ("z", ">f4")])
    for j, axis in enumerate("xyz"):
        records[axis] = points[:, j]
    data[:, : width * step] = records.view(np.uint8).reshape(height, width * step)
    field = types["sensor_msgs/msg/PointField"]
    fields = [field(name=a, offset=4 + 4 * j, datatype=7, count=1) for j, a in enumerate("xyz")]
    msg = types[ros2.CLOUD_TYPE](
        header=ros2._header(1, 2, "f"),
        height=height,
        width=width,
        fields=[field(name="i", offset=0, datatype=6, count=1), *fields],
        is_bigendian=True,
        point_step=step,
        row_step=row,
        data=data.reshape(-1),
        is_dense=True,
    )
    cloud = ros2.decode_pointcloud2(bytes(store.serialize_cdr(msg, ros2.CLOUD_TYPE)))
    np.testing.assert_array_equal(cloud.points, points.astype(np.float64))


@pytest.mark.parametrize("cdr", [b"", b"\x00\x01\x00\x00\x01", b"\x00\x01\x00\x00" + b"\xff" * 64])
def test_garbage_is_an_invalid_fragment(cdr: bytes) -> None:
    with pytest.raises(InvalidFragmentError):
        ros2.decode_pointcloud2(cdr)


def test_cloud_without_z_is_an_invalid_fragment() -> None:
    cdr = ros2.encode_pointcloud2(_cloud(10))
    store = ros2._store()
    msg: Any = store.deserialize_cdr(cdr, ros2.CLOUD_TYPE)
    msg.fields = [f for f in msg.fields if f.name != "z"]
    with pytest.raises(InvalidFragmentError, match="'z'"):
        ros2.decode_pointcloud2(bytes(store.serialize_cdr(msg, ros2.CLOUD_TYPE)))


def test_rmw_zenoh_keys_and_attachment() -> None:
    assert (
        ros2.topic_key(0, "/chatter", "std_msgs/msg/String", ros2.type_hash("std_msgs/msg/String"))
        == "0/chatter/std_msgs::msg::dds_::String_/"
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    )  # the example of rmw_zenoh's design document
    assert ros2.type_hash(ros2.POSE_TYPE, "humble") == "TypeHashNotSupported"
    gid = bytes(range(16))
    attachment = ros2.encode_attachment(7, 1_700_000_000_123_456_789, gid)
    # rmw_zenoh writes it with zenoh's serializer: int64, int64, then the GID as a sequence.
    assert attachment == z_serialize((Int64(7), Int64(1_700_000_000_123_456_789), gid)).to_bytes()
    decoded = ros2.decode_attachment(attachment)
    assert (decoded.sequence_number, decoded.gid) == (7, gid)
    token = ros2.endpoint_token(0, "abc", "node", 10, "MP", "/a/b", ros2.POSE_TYPE, "H")
    assert (
        token
        == "@ros2_lv/0/abc/0/10/MP/%/%/node/%a%b/geometry_msgs::msg::dds_::PoseStamped_/H/"
        + ros2.DEFAULT_QOS
    )
    assert topic_robot("/robot1/fragments") == "robot1" and topic_robot("/x") == "ros"


def test_pose_stamped_round_trip() -> None:
    angle = 0.7
    pose = np.eye(4)
    pose[:2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
    pose[:3, 3] = [1.5, -2.0, 0.25]
    decoded, sec, nanosec, frame = ros2.decode_pose_stamped(
        ros2.encode_pose_stamped(pose, 3, 4, "site")
    )
    np.testing.assert_allclose(decoded, pose, atol=1e-12)
    assert (sec, nanosec, frame) == (3, 4, "site")


def test_ros2_robot_clouds_become_fragments_and_poses_come_back(
    zenoh_service: ZenohService,
) -> None:
    """A ROS 2 robot publishing PointCloud2 over rmw_zenoh gets PoseStamped back."""
    scene = generate_scene(SceneSpec.easy(), 2)
    received: list[tuple[np.ndarray, int, int, str, ros2.RmwAttachment]] = []
    lock = threading.Lock()

    def on_pose(sample) -> None:
        pose, sec, nanosec, frame = ros2.decode_pose_stamped(sample.payload.to_bytes())
        attachment = ros2.decode_attachment(sample.attachment.to_bytes())
        with lock:
            received.append((pose, sec, nanosec, frame, attachment))

    cloud_hash = ros2.type_hash(ros2.CLOUD_TYPE)
    stamps = {}
    with robot_session(zenoh_service) as session:
        pose_key = ros2.topic_key(0, ROS_POSE_TOPIC, ros2.POSE_TYPE)  # any type hash
        cloud_key = ros2.topic_key(0, ROS_CLOUD_TOPIC, ros2.CLOUD_TYPE, cloud_hash)
        with (
            session.declare_subscriber(pose_key, on_pose),
            # A reliable ROS publisher (rmw_zenoh's default QoS) blocks under congestion: a
            # burst of three clouds must not lose one, as the default (drop) once did in CI.
            session.declare_publisher(
                cloud_key, congestion_control=zenoh.CongestionControl.BLOCK
            ) as publisher,
        ):
            wait_until(lambda: publisher.matching_status.matching, 10)  # type: ignore[attr-defined]
            gid = ros2.entity_gid("test robot publisher")
            for seq, fragment in enumerate(scene.fragments, start=1):
                points = fragment.points.copy()
                points[:5] = np.nan  # a few missing returns
                stamp = (1_700_000_000 + seq, 250_000_000)
                cdr = ros2.encode_pointcloud2(points, *stamp, "robot1/lidar")
                attachment = ros2.encode_attachment(seq, time.time_ns(), gid)
                publisher.put(cdr, attachment=attachment)
                fid = cloud_fragment_id("robot1", ros2.decode_pointcloud2(cdr))
                stamps[stamp] = fid
            assert min(stamps.values()) == "robot1_1700000001_250000000"

            with zenoh_service.http() as http:

                def closed() -> dict[str, Any] | None:
                    reply = http.get(f"/v1/sites/{ROS_SITE}/result")
                    body = reply.json() if reply.status_code == 200 else {}
                    return body if body.get("status") == "closed" else None

                result = wait_until(closed, 60)
                status = http.get(f"/v1/sites/{ROS_SITE}").json()
            expected = {f["id"]: np.asarray(f["pose"]) for f in result["fragments"]}
            assert set(expected) == set(stamps.values())
            assert [f["dropped_nonfinite"] for f in status["fragments"]] == [5, 5, 5]
            assert [f["fragment_id"] for f in status["fragments"]] == list(stamps.values())

            def poses_match() -> dict[tuple[int, int], Any] | None:
                """The latest PoseStamped of each cloud, once they are the result's poses."""
                with lock:
                    latest = {(s, ns): (p, a) for p, s, ns, f, a in received if f == ROS_SITE}
                if set(latest) < set(stamps):
                    return None
                same = all(
                    np.allclose(latest[stamp][0], expected[fid], atol=1e-9)
                    for stamp, fid in stamps.items()
                )
                return latest if same else None

            latest = wait_until(poses_match, 20)
    for _, attachment in latest.values():
        assert len(attachment.gid) == 16 and attachment.sequence_number >= 1
