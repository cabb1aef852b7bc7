"""ROS 2 outputs over rmw_zenoh: the site's OccupancyGrid and one TF transform per fragment.

Three rendered depth frames go in as Image + CameraInfo; once the site closes, what the
service publishes is decoded with rosbags and checked against the result.
"""

from __future__ import annotations

import asyncio
import threading
import time
from typing import Any

import numpy as np
import pytest
import zenoh

from api.zenoh import ros2
from api.zenoh.bridge import LoopBridge
from api.zenoh.ros_bridge import RosBridge
from schemas.result import ResultModel
from services.frame_layout import estimate_rgbd_layout
from services.geometry import distance_to_polygon, points_in_polygon
from services.occupancy import FREE, OCCUPIED, UNKNOWN, rasterize_floorplan
from services.pipeline import place_site
from services.rgbd import backproject
from store.backend import Backend
from tests.frame_fixtures import ROOM_SEED, three_frames
from tests.service_fixtures import make_settings, wait_result, wait_until
from tests.zenoh.conftest import (
    ROS_DEPTH_SITE,
    ROS_DEPTH_TOPIC,
    ROS_MAP_TOPIC,
    ROS_TF_TOPIC,
    ZenohService,
    robot_session,
)
from tests.zenoh.test_ros_depth import camera

pytestmark = pytest.mark.timeout(120)


class Latest:
    """The latest decoded message of a topic for one frame id, its attachment, and how many
    such messages came."""

    def __init__(self, decode: Any, frame_of: Any, frame_id: str) -> None:
        self.decode, self.frame_of, self.frame_id = decode, frame_of, frame_id
        self.value: Any = None
        self.attachment: ros2.RmwAttachment | None = None
        self.count = 0
        self.lock = threading.Lock()

    def __call__(self, sample: zenoh.Sample) -> None:  # zenoh thread
        value = self.decode(sample.payload.to_bytes())
        if self.frame_of(value) == self.frame_id:
            with self.lock:
                self.value = value
                self.count += 1
                assert sample.attachment is not None
                self.attachment = ros2.decode_attachment(sample.attachment.to_bytes())

    def get(self) -> Any:
        with self.lock:
            return self.value

    def received(self) -> int:
        with self.lock:
            return self.count


def _cell(grid, xy: np.ndarray) -> int:
    col, row = np.floor((xy - grid.origin) / grid.resolution).astype(int)
    return int(grid.cells[row, col])


def test_depth_frames_close_the_site_and_map_and_transforms_come_out(
    zenoh_service: ZenohService,
) -> None:
    scene = three_frames(ROOM_SEED)
    tf = Latest(ros2.decode_tf_message, lambda ts: ts[0].parent_frame if ts else "", ROS_DEPTH_SITE)
    grid = Latest(ros2.decode_occupancy_grid, lambda g: g[3], ROS_DEPTH_SITE)
    stamps = {}
    with robot_session(zenoh_service) as session:
        tf_key = ros2.topic_key(0, ROS_TF_TOPIC, ros2.TF_TYPE)  # any type hash
        map_key = ros2.topic_key(0, ROS_MAP_TOPIC, ros2.MAP_TYPE)
        info_topic = ROS_DEPTH_TOPIC.rsplit("/", 1)[0] + "/camera_info"  # the ROS convention
        with (
            session.declare_subscriber(tf_key, tf),
            session.declare_subscriber(map_key, grid),
            camera(session, ROS_DEPTH_TOPIC, info_topic) as cam,
        ):
            for seq, (synthetic, encoding) in enumerate(
                zip(scene.frames, ["16UC1", "32FC1", "16UC1"], strict=True)
            ):
                stamp = (1_700_000_200 + seq, 1_000 * seq)
                cam.send(synthetic.frame, stamp, encoding, info_first=seq == 0)
                stamps[f"robot2.depth_{stamp[0]}_{stamp[1]:09d}"] = synthetic.id  # namespace

            with zenoh_service.http() as http:
                result = wait_result(http, ROS_DEPTH_SITE, 60, ("closed", "ambiguous"))
            poses = {f["id"]: np.asarray(f["pose"]) for f in result["fragments"] if f["placed"]}
            assert set(poses) == set(stamps)
            [room] = result["floorplan"]["rooms"]
            polygon = np.asarray(room["polygon"])
            expected = rasterize_floorplan([polygon], 0.05)

            def transforms_match() -> list[ros2.DecodedTransform] | None:
                latest = tf.get()
                if latest is None or {t.child_frame for t in latest} != set(poses):
                    return None
                same = all(np.allclose(t.pose, poses[t.child_frame], atol=1e-9) for t in latest)
                return latest if same else None

            def grid_matches() -> Any:
                latest = grid.get()
                if latest is None or latest[0].cells.shape != expected.cells.shape:
                    return None
                return latest if np.array_equal(latest[0].cells, expected.cells) else None

            transforms = wait_until(transforms_match, 20)
            published, sec, _, frame_id = wait_until(grid_matches, 20)

    for t in transforms:  # parent the site frame, stamped when published
        assert t.parent_frame == ROS_DEPTH_SITE and abs(t.stamp_sec - time.time()) < 120
    assert tf.attachment is not None and len(tf.attachment.gid) == 16
    assert frame_id == ROS_DEPTH_SITE and abs(sec - time.time()) < 120
    assert published.resolution == pytest.approx(0.05)
    assert published.origin == pytest.approx(expected.origin)
    # The cells say what the floorplan says: its corners are walls, its middle is free,
    # the grid's corner (outside the room) is unknown.
    assert _cell(published, polygon.mean(axis=0)) == FREE
    assert all(_cell(published, vertex) == OCCUPIED for vertex in polygon)
    assert published.cells[0, 0] == UNKNOWN
    # Every frame's points, moved by its transform, fall in the room or on its walls (within
    # 15 cm: depth noise), so rviz draws each scan in place on the map.
    ids = {v: k for k, v in stamps.items()}
    by_child = {t.child_frame: t.pose for t in transforms}
    for synthetic in scene.frames:
        local, _ = backproject(synthetic.frame, stride=8)
        pose = by_child[ids[synthetic.id]]
        xy = (local @ pose[:3, :3].T + pose[:3, 3])[:, :2]
        near = points_in_polygon(xy, polygon) | (distance_to_polygon(xy, polygon) < 0.15)
        assert near.mean() > 0.98, (synthetic.id, near.mean())


def test_an_open_result_sends_transforms_but_no_map_to_navigate_by(
    zenoh_service: ZenohService,
) -> None:
    # A loop that closed into a room the confidence doubts, with no runner-up, is "open"
    # but keeps that room as its floorplan (README, a lone doubted room): its poses and
    # transforms go out, its OccupancyGrid does not (ros_bridge.MAP_STATUSES). The same
    # room, said closed, is then published with its map: messages of one publisher arrive in
    # order, so a map of the open result would have come first and made two. The bridge
    # publishes on a robot's session (a real one, connected to the service) that also
    # subscribes: the service's own bridge is driven by its workers' results instead.
    site, map_topic, tf_topic = "ros_open_site", "/open_test/map", "/open_test/tf"
    scene = three_frames(ROOM_SEED)
    closed = place_site({f.id: estimate_rgbd_layout(f.frame) for f in scene.frames})
    assert closed.floorplan.rooms
    doubted = closed.model_copy(update={"status": "open"})
    settings = make_settings(
        zenoh_service.settings.redis_url, zenoh_ros_map_topic=map_topic, zenoh_ros_tf_topic=tf_topic
    )
    maps = Latest(ros2.decode_occupancy_grid, lambda g: g[3], site)
    transforms = Latest(ros2.decode_tf_message, lambda ts: ts[0].parent_frame if ts else "", site)

    async def publish(session: zenoh.Session, results: list[ResultModel]) -> None:
        backend = await Backend.connect(settings)
        declared = []
        try:
            bridge = RosBridge(backend, session, LoopBridge(asyncio.get_running_loop()))
            declared = bridge.declare()
            for result in results:
                await bridge.publish_result(site, result)
        finally:
            for entity in declared:
                entity.undeclare()
            await backend.aclose()

    with robot_session(zenoh_service) as session:
        map_key = ros2.topic_key(0, map_topic, ros2.MAP_TYPE)
        tf_key = ros2.topic_key(0, tf_topic, ros2.TF_TYPE)
        with (
            session.declare_subscriber(map_key, maps),
            session.declare_subscriber(tf_key, transforms),
        ):
            asyncio.run(publish(session, [doubted, closed]))
            wait_until(
                lambda: transforms.received() == 2 and maps.received() >= 1,
                20,
                describe=lambda: f"{transforms.received()} transforms, {maps.received()} maps",
            )
    assert maps.received() == 1
