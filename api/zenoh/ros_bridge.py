"""The service as a ROS 2 node on rmw_zenoh, without ROS installed.

In (topics of any type hash, so Humble's ``TypeHashNotSupported`` and later distributions'
RIHS01 hashes both match; every message becomes a fragment of the topic's site through the
one ingest path):

- ``sensor_msgs/msg/PointCloud2`` topics (``FPJ_ZENOH_ROS_CLOUD_TOPICS="/robot1/fragments=lab,
  ..."``): x, y, z go into a binary PLY;
- depth ``sensor_msgs/msg/Image`` topics, 16UC1 (mm) or 32FC1 (m), each with its
  ``sensor_msgs/msg/CameraInfo`` topic (``FPJ_ZENOH_ROS_DEPTH_TOPICS="/robot1/depth/image_raw
  =lab"``, CameraInfo on ``/robot1/depth/camera_info``): an image and the CameraInfo of the
  same stamp and frame id become an RGB-D frame archive (:mod:`api.zenoh.ros_depth`); an
  image left unpaired for ``FPJ_ZENOH_ROS_DEPTH_WAIT_S``, or pushed out by newer ones
  (``FPJ_ZENOH_ROS_DEPTH_PENDING``), is dropped with a log line. Outcomes are counted in
  ``fpj_ros_depth_images_total`` (``/metrics``).

Fragment id ``{robot}_{stamp.sec}_{stamp.nanosec:09d}``, where ``robot`` is the topic's
namespace with ``/`` as ``.`` (``/robot1/fragments`` -> ``robot1``; none: ``ros``). Bad
messages are logged with the upload error code; the bridge never stops for one.

Out, after each placement:

- ``geometry_msgs/msg/PoseStamped`` per placed fragment on ``FPJ_ZENOH_ROS_POSE_TOPIC``:
  ``header.frame_id`` is the site id (the site frame), ``header.stamp`` the stamp of the
  message the fragment came from (for other fragments: their upload time), so a robot matches
  poses to its scans by stamp;
- ``tf2_msgs/msg/TFMessage`` on ``FPJ_ZENOH_ROS_TF_TOPIC``: one transform per placed fragment,
  parent frame the site id, child frame the fragment id, so rviz shows every scan in place;
- ``nav_msgs/msg/OccupancyGrid`` of the floorplan on ``FPJ_ZENOH_ROS_MAP_TOPIC`` (frame the
  site id, cells of ``FPJ_ZENOH_ROS_MAP_RESOLUTION`` m; :mod:`services.occupancy`).

Poses and transforms go out for results closed, ambiguous or open (an open result's poses
are its best partial guess, as on ``fpj/sites/*/poses``), the map only for closed and
ambiguous ones (an open result's room, if any, is a guess not to navigate by). Transforms
and map are stamped with the time of publication: tf2 ignores a transform sent again with an
unchanged stamp (TF_REPEATED_DATA), and a placement may move a fragment. Graph liveliness
tokens of the node and of every subscription and publisher make them show in
``ros2 node list`` / ``ros2 topic list``.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any, Protocol

import numpy as np
import zenoh

from api.metrics import ROS_DEPTH_IMAGES
from api.site_data import load_site_status
from api.zenoh.bridge import LoopBridge, error_of
from api.zenoh.ingest import ingest_with_sender
from api.zenoh.ros2 import (
    CAMERA_INFO_TYPE,
    CLOUD_TYPE,
    IMAGE_TYPE,
    MAP_TYPE,
    POSE_TYPE,
    TF_TYPE,
    DecodedCloud,
    DecodedDepth,
    cloud_to_ply,
    decode_camera_info,
    decode_depth_image,
    decode_pointcloud2,
    encode_attachment,
    encode_occupancy_grid,
    encode_pose_stamped,
    encode_tf_message,
    endpoint_token,
    entity_gid,
    node_token,
    topic_key,
    type_hash,
)
from api.zenoh.ros_depth import DepthPair, DepthPairer, frame_archive
from schemas.result import ResultModel
from schemas.settings import DepthTopic
from schemas.zenoh import POSE_STATUSES, SenderRecord
from services.occupancy import rasterize_floorplan
from store.backend import Backend
from store.presence import load_senders

__all__ = ["MAP_STATUSES", "RosBridge", "cloud_fragment_id", "topic_robot"]

log = logging.getLogger(__name__)

MAP_STATUSES = ("closed", "ambiguous")  # results whose room is one to navigate by


class _Stamped(Protocol):
    """A decoded message's header."""

    @property
    def stamp_sec(self) -> int: ...
    @property
    def stamp_nanosec(self) -> int: ...
    @property
    def frame_id(self) -> str: ...


def topic_robot(topic: str) -> str:
    """The robot a topic belongs to: its namespace (``/a/b/cloud`` -> ``a.b``), else ``ros``.

    >>> topic_robot("/robot1/fragments"), topic_robot("/fragments")
    ('robot1', 'ros')
    """
    namespace = topic.strip("/").split("/")[:-1]
    return ".".join(namespace)[:40] or "ros"


def cloud_fragment_id(robot: str, message: _Stamped) -> str:
    """``{robot}_{sec}_{nanosec:09d}`` of a message's stamp (at most 61 characters of the id
    alphabet)."""
    return f"{robot}_{message.stamp_sec}_{message.stamp_nanosec:09d}"


@dataclass(frozen=True)
class _Output:
    """A publisher of the node with its rmw_zenoh GID and sequence numbers."""

    publisher: zenoh.Publisher
    gid: bytes
    sequence: itertools.count[int]


class RosBridge:
    """PointCloud2 and depth Image subscriptions in; PoseStamped, TFMessage and OccupancyGrid
    publications out."""

    def __init__(self, backend: Backend, session: zenoh.Session, bridge: LoopBridge) -> None:
        settings = backend.settings
        self.backend, self.session, self.bridge = backend, session, bridge
        self.domain = settings.zenoh_ros_domain_id
        self.node = settings.zenoh_ros_node
        self.distro = settings.zenoh_ros_distro
        self.topics = settings.ros_cloud_topics()
        self.depth_topics = settings.ros_depth_topics()
        self.pose_topic = settings.zenoh_ros_pose_topic
        self.tf_topic = settings.zenoh_ros_tf_topic
        self.map_topic = settings.zenoh_ros_map_topic
        self.map_resolution = settings.zenoh_ros_map_resolution
        self.session_id = str(session.zid())
        self._pairers = {
            t.image: DepthPairer(settings.zenoh_ros_depth_wait_s, settings.zenoh_ros_depth_pending)
            for t in self.depth_topics
        }
        self._outputs: dict[str, _Output] = {}  # message type -> its publisher
        self._entity_ids = itertools.count(1)
        self._order: dict[str, asyncio.Lock] = {}

    def declare(self) -> list[Any]:
        """Declare subscriptions, publishers and their graph tokens; returns them all."""
        live = self.session.liveliness()
        declared: list[Any] = [
            live.declare_token(node_token(self.domain, self.session_id, self.node))
        ]
        for topic, site_id in self.topics.items():
            declared += self._subscribe(topic, CLOUD_TYPE, partial(self._on_cloud, topic, site_id))
            log.info("PointCloud2 topic %s -> site %s", topic, site_id)
        for depth in self.depth_topics:
            declared += self._subscribe(depth.image, IMAGE_TYPE, partial(self._on_image, depth))
            on_info = partial(self._on_camera_info, depth)
            declared += self._subscribe(depth.camera_info, CAMERA_INFO_TYPE, on_info)
            log.info("depth Image topic %s + %s -> site %s", *depth)
        for topic, msgtype in (
            (self.pose_topic, POSE_TYPE),
            (self.tf_topic, TF_TYPE),
            (self.map_topic, MAP_TYPE),
        ):
            if topic:
                declared += self._advertise(topic, msgtype)
        return declared

    def _subscribe(
        self, topic: str, msgtype: str, callback: Callable[[zenoh.Sample], None]
    ) -> list[Any]:
        """A subscription of ``topic`` (any type hash) and its liveliness token."""
        subscriber = self.session.declare_subscriber(
            topic_key(self.domain, topic, msgtype), callback
        )
        token = self._token("MS", topic, msgtype)
        return [subscriber, self.session.liveliness().declare_token(token)]

    def _advertise(self, topic: str, msgtype: str) -> list[Any]:
        """A publisher of ``topic`` and its liveliness token."""
        key = topic_key(self.domain, topic, msgtype, type_hash(msgtype, self.distro))
        publisher = self.session.declare_publisher(
            key, congestion_control=zenoh.CongestionControl.BLOCK
        )
        token = self._token("MP", topic, msgtype)
        self._outputs[msgtype] = _Output(publisher, entity_gid(token), itertools.count(1))
        log.info("%s topic %s (%s)", msgtype.rsplit("/", 1)[-1], topic, key)
        return [publisher, self.session.liveliness().declare_token(token)]

    def _token(self, kind: str, topic: str, msgtype: str) -> str:
        return endpoint_token(
            self.domain,
            self.session_id,
            self.node,
            next(self._entity_ids),
            kind,
            topic,
            msgtype,
            type_hash(msgtype, self.distro),
        )

    # ------------------------------------------------------------ in

    def _on_cloud(self, topic: str, site_id: str, sample: zenoh.Sample) -> None:  # zenoh thread
        if sample.kind == zenoh.SampleKind.PUT:
            self.bridge.submit(self.ingest_cloud(topic, site_id, sample.payload.to_bytes()))

    def _on_image(self, depth: DepthTopic, sample: zenoh.Sample) -> None:  # zenoh thread
        if sample.kind == zenoh.SampleKind.PUT:
            self.bridge.submit(self.receive_image(depth, sample.payload.to_bytes()))

    def _on_camera_info(self, depth: DepthTopic, sample: zenoh.Sample) -> None:  # zenoh thread
        if sample.kind == zenoh.SampleKind.PUT:
            self.bridge.submit(self.receive_camera_info(depth, sample.payload.to_bytes()))

    async def ingest_cloud(self, topic: str, site_id: str, cdr: bytes) -> None:
        """Turn one PointCloud2 into a fragment of ``site_id`` (errors are logged).

        Messages of one topic are stored in the order they arrived (the site's fragment order).
        """

        def convert() -> tuple[DecodedCloud, bytes]:
            cloud = decode_pointcloud2(cdr)
            return cloud, cloud_to_ply(cloud)

        async with self._order.setdefault(topic, asyncio.Lock()):
            await self._ingest("PointCloud2", topic, site_id, convert)

    async def receive_image(self, depth: DepthTopic, cdr: bytes) -> None:
        """Decode a depth image; ingest it once its CameraInfo is there (errors are logged
        and counted). One camera's messages are handled in the order they arrived."""
        async with self._order.setdefault(depth.image, asyncio.Lock()):
            try:
                image = await asyncio.to_thread(decode_depth_image, cdr)
            except Exception as exc:  # a bad image is logged and counted, like any rejection
                ROS_DEPTH_IMAGES.labels(self._rejected("depth Image", depth.image, exc)).inc()
                return
            pair, dropped = self._pairers[depth.image].add_image(image)
            self._drop_unpaired(depth, dropped)
            if pair is not None:
                await self._ingest_pair(depth, pair)
                return
            # No later message may come to expire it: look again once its wait is over.
            wait = self._pairers[depth.image].wait_s
            asyncio.get_running_loop().call_later(wait * 1.01, self._expire, depth)

    async def receive_camera_info(self, depth: DepthTopic, cdr: bytes) -> None:
        """Decode a CameraInfo and ingest the image waiting for it, if any."""
        async with self._order.setdefault(depth.image, asyncio.Lock()):
            try:
                info = decode_camera_info(cdr)
            except Exception as exc:  # its image will be dropped unpaired, and counted then
                code, message = error_of(exc)
                log.warning("CameraInfo on %s rejected: %s: %s", depth.camera_info, code, message)
                return
            pair, dropped = self._pairers[depth.image].add_info(info)
            self._drop_unpaired(depth, dropped)
            if pair is not None:
                await self._ingest_pair(depth, pair)

    def _expire(self, depth: DepthTopic) -> None:  # event loop, between handlers
        self._drop_unpaired(depth, self._pairers[depth.image].expire())

    def _drop_unpaired(self, depth: DepthTopic, images: list[DecodedDepth]) -> None:
        for image in images:
            ROS_DEPTH_IMAGES.labels("unpaired").inc()
            log.warning(
                "depth Image on %s (stamp %d.%09d, frame %r) dropped: no CameraInfo of the "
                "same stamp and frame on %s",
                depth.image,
                image.stamp_sec,
                image.stamp_nanosec,
                image.frame_id,
                depth.camera_info,
            )

    async def _ingest_pair(self, depth: DepthTopic, pair: DepthPair) -> None:
        def convert() -> tuple[DecodedDepth, bytes]:
            return pair.image, frame_archive(pair)

        outcome = await self._ingest("depth Image", depth.image, depth.site_id, convert)
        ROS_DEPTH_IMAGES.labels(outcome).inc()

    async def _ingest(
        self,
        kind: str,
        topic: str,
        site_id: str,
        convert: Callable[[], tuple[_Stamped, bytes]],
    ) -> str:
        """Store what ``convert`` (run off the loop) makes of a message as a fragment.

        Returns the outcome: ``accepted``, ``duplicate`` or the error code (logged).
        """
        try:
            message, data = await asyncio.to_thread(convert)
            robot = topic_robot(topic)
            fragment_id = cloud_fragment_id(robot, message)
            sender = SenderRecord(
                robot_id=robot,
                via="ros2",
                topic=topic,
                stamp_sec=message.stamp_sec,
                stamp_nanosec=message.stamp_nanosec,
                frame_id=message.frame_id,
            )
            reply = await ingest_with_sender(self.backend, site_id, fragment_id, data, sender)
        except Exception as exc:  # every failure is logged; a subscriber has nobody to tell
            return self._rejected(kind, topic, exc)
        log.info(
            "%s on %s -> fragment %s/%s (%s)",
            kind,
            topic,
            site_id,
            fragment_id,
            "new" if reply.created else "already stored",
        )
        return "accepted" if reply.created else "duplicate"

    @staticmethod
    def _rejected(kind: str, topic: str, exc: Exception) -> str:
        """Log a refused message; returns its error code."""
        code, message = error_of(exc)
        log.warning("%s on %s rejected: %s: %s", kind, topic, code, message)
        if code == "internal_error":
            log.exception("%s on %s", kind, topic, exc_info=exc)
        return code

    # ------------------------------------------------------------ out

    async def publish_result(self, site_id: str, result: ResultModel) -> None:
        """Publish what is configured of a placement's result: poses and transforms of the
        placed fragments (closed, ambiguous or open), the floorplan's grid (closed or
        ambiguous)."""
        if not self._outputs or result.status not in POSE_STATUSES:
            return
        placed = {f.id: np.asarray(f.pose) for f in result.fragments if f.placed and f.pose}
        messages: list[tuple[str, bytes]] = []
        if POSE_TYPE in self._outputs and placed:
            stamps = await self._stamps(site_id)
            messages += [
                (POSE_TYPE, encode_pose_stamped(pose, *stamps.get(fid, (0, 0)), site_id))
                for fid, pose in placed.items()
            ]
        now = divmod(time.time_ns(), 1_000_000_000)
        if TF_TYPE in self._outputs and placed:
            messages.append((TF_TYPE, encode_tf_message(placed, site_id, *now)))
        if MAP_TYPE in self._outputs and result.status in MAP_STATUSES:
            rooms = [room.polygon for room in result.floorplan.rooms]
            try:
                grid = await asyncio.to_thread(rasterize_floorplan, rooms, self.map_resolution)
            except ValueError as exc:  # a degenerate floorplan: no map, the rest goes out
                log.warning("no OccupancyGrid of site %s: %s", site_id, exc)
            else:
                if grid.width:
                    messages.append((MAP_TYPE, encode_occupancy_grid(grid, *now, site_id)))
        await asyncio.to_thread(self._put_all, messages)

    async def _stamps(self, site_id: str) -> dict[str, tuple[int, int]]:
        """Fragment id -> (sec, nanosec): the source message's stamp, else the upload time."""
        status = await load_site_status(self.backend, site_id)
        stamps = {}
        for fragment in status.fragments:
            frac, whole = math.modf(fragment.created_at.timestamp())
            stamps[fragment.fragment_id] = (int(whole), int(frac * 1e9))
        for fid, sender in (await load_senders(self.backend, site_id)).items():
            if sender.stamp_sec is not None and sender.stamp_nanosec is not None:
                stamps[fid] = (sender.stamp_sec, sender.stamp_nanosec)
        return stamps

    def _put_all(self, messages: list[tuple[str, bytes]]) -> None:
        for msgtype, cdr in messages:
            output = self._outputs[msgtype]
            attachment = encode_attachment(next(output.sequence), time.time_ns(), output.gid)
            output.publisher.put(cdr, attachment=attachment)
