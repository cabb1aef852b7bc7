"""The service as a ROS 2 node on rmw_zenoh, without ROS installed.

- Subscribes to each configured ``sensor_msgs/msg/PointCloud2`` topic
  (``FPJ_ZENOH_ROS_CLOUD_TOPICS="/robot1/fragments=lab,..."``), any type hash (so Humble's
  ``TypeHashNotSupported`` and later distributions' RIHS01 hashes both match). Every message
  becomes a fragment of the topic's site: its x, y, z go into a binary PLY that takes the one
  ingest path. Fragment id ``{robot}_{stamp.sec}_{stamp.nanosec:09d}``, where ``robot`` is the
  topic's namespace with ``/`` as ``.`` (``/robot1/fragments`` -> ``robot1``; none: ``ros``).
- Publishes every placed fragment's pose as ``geometry_msgs/msg/PoseStamped`` on
  ``FPJ_ZENOH_ROS_POSE_TOPIC`` after each placement: ``header.frame_id`` is the site id (the
  site frame), ``header.stamp`` the stamp of the PointCloud2 the fragment came from (for other
  fragments: their upload time), so a robot matches poses to its clouds by stamp.
- Declares the node's, subscriptions' and publisher's graph liveliness tokens, so
  ``ros2 node list`` / ``ros2 topic list`` show them.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import math
import time
from functools import partial
from typing import Any

import zenoh

from api.backend import Backend
from api.store import load_site_status
from api.zenoh.bridge import LoopBridge, error_of
from api.zenoh.ingest import ingest_with_sender
from api.zenoh.presence import load_senders
from api.zenoh.ros2 import (
    CLOUD_TYPE,
    POSE_TYPE,
    DecodedCloud,
    cloud_to_ply,
    decode_pointcloud2,
    encode_attachment,
    encode_pose_stamped,
    endpoint_token,
    entity_gid,
    node_token,
    topic_key,
    type_hash,
)
from schemas.result import ResultModel
from schemas.zenoh import POSE_STATUSES, SenderRecord

__all__ = ["RosBridge", "cloud_fragment_id", "topic_robot"]

log = logging.getLogger(__name__)


def topic_robot(topic: str) -> str:
    """The robot a topic belongs to: its namespace (``/a/b/cloud`` -> ``a.b``), else ``ros``.

    >>> topic_robot("/robot1/fragments"), topic_robot("/fragments")
    ('robot1', 'ros')
    """
    namespace = topic.strip("/").split("/")[:-1]
    return ".".join(namespace)[:40] or "ros"


def cloud_fragment_id(robot: str, cloud: DecodedCloud) -> str:
    """``{robot}_{sec}_{nanosec:09d}`` (at most 61 characters of the id alphabet)."""
    return f"{robot}_{cloud.stamp_sec}_{cloud.stamp_nanosec:09d}"


class RosBridge:
    """PointCloud2 subscriptions in, PoseStamped publications out."""

    def __init__(self, backend: Backend, session: zenoh.Session, bridge: LoopBridge) -> None:
        settings = backend.settings
        self.backend, self.session, self.bridge = backend, session, bridge
        self.domain = settings.zenoh_ros_domain_id
        self.node = settings.zenoh_ros_node
        self.distro = settings.zenoh_ros_distro
        self.topics = settings.ros_cloud_topics()
        self.pose_topic = settings.zenoh_ros_pose_topic
        self.session_id = str(session.zid())
        self._publisher: zenoh.Publisher | None = None
        self._gid = bytes(16)
        self._sequence = itertools.count(1)
        self._order: dict[str, asyncio.Lock] = {}

    @property
    def pose_key(self) -> str:
        """Key expression of the PoseStamped topic (with this distribution's type hash)."""
        return topic_key(self.domain, self.pose_topic, POSE_TYPE, type_hash(POSE_TYPE, self.distro))

    def declare(self) -> list[Any]:
        """Declare subscriptions, the publisher and their graph tokens; returns them all."""
        live = self.session.liveliness()
        declared: list[Any] = [
            live.declare_token(node_token(self.domain, self.session_id, self.node))
        ]
        cloud_hash = type_hash(CLOUD_TYPE, self.distro)
        for entity_id, (topic, site_id) in enumerate(self.topics.items(), start=10):
            key = topic_key(self.domain, topic, CLOUD_TYPE)
            declared.append(
                self.session.declare_subscriber(key, partial(self._on_cloud, topic, site_id))
            )
            token = self._token(entity_id, "MS", topic, CLOUD_TYPE, cloud_hash)
            declared.append(live.declare_token(token))
            log.info("PointCloud2 topic %s -> site %s (%s)", topic, site_id, key)
        if self.pose_topic:
            self._publisher = self.session.declare_publisher(
                self.pose_key, congestion_control=zenoh.CongestionControl.BLOCK
            )
            token = self._token(
                9, "MP", self.pose_topic, POSE_TYPE, type_hash(POSE_TYPE, self.distro)
            )
            self._gid = entity_gid(token)
            declared += [self._publisher, live.declare_token(token)]
            log.info("PoseStamped topic %s (%s)", self.pose_topic, self.pose_key)
        return declared

    def _token(self, entity_id: int, kind: str, topic: str, msgtype: str, hash_: str) -> str:
        return endpoint_token(
            self.domain, self.session_id, self.node, entity_id, kind, topic, msgtype, hash_
        )

    def _on_cloud(self, topic: str, site_id: str, sample: zenoh.Sample) -> None:  # zenoh thread
        if sample.kind != zenoh.SampleKind.PUT:
            return
        self.bridge.submit(self.ingest_cloud(topic, site_id, sample.payload.to_bytes()))

    async def ingest_cloud(self, topic: str, site_id: str, cdr: bytes) -> None:
        """Turn one PointCloud2 into a fragment of ``site_id`` (errors are logged).

        Messages of one topic are stored in the order they arrived (the site's fragment order).
        """
        async with self._order.setdefault(topic, asyncio.Lock()):
            await self._ingest_cloud(topic, site_id, cdr)

    async def _ingest_cloud(self, topic: str, site_id: str, cdr: bytes) -> None:
        try:
            cloud = await asyncio.to_thread(decode_pointcloud2, cdr)
            robot = topic_robot(topic)
            fragment_id = cloud_fragment_id(robot, cloud)
            ply = await asyncio.to_thread(cloud_to_ply, cloud)
            sender = SenderRecord(
                robot_id=robot,
                via="ros2",
                topic=topic,
                stamp_sec=cloud.stamp_sec,
                stamp_nanosec=cloud.stamp_nanosec,
                frame_id=cloud.frame_id,
            )
            reply = await ingest_with_sender(self.backend, site_id, fragment_id, ply, sender)
        except Exception as exc:  # every failure is logged; a subscriber has nobody to tell
            code, message = error_of(exc)
            log.warning("PointCloud2 on %s rejected: %s: %s", topic, code, message)
            if code == "internal_error":
                log.exception("PointCloud2 on %s", topic, exc_info=exc)
            return
        log.info(
            "PointCloud2 on %s -> fragment %s/%s (%s)",
            topic,
            site_id,
            fragment_id,
            "new" if reply.created else "already stored",
        )

    async def publish_poses(self, site_id: str, result: ResultModel) -> None:
        """Publish a PoseStamped per placed fragment of a closed, ambiguous or open result."""
        if self._publisher is None or result.status not in POSE_STATUSES:
            return
        placed = [f for f in result.fragments if f.placed and f.pose is not None]
        if not placed:
            return
        stamps = await self._stamps(site_id)
        messages = [
            encode_pose_stamped(f.pose, *stamps.get(f.id, (0, 0)), site_id)
            for f in placed
            if f.pose is not None
        ]
        await asyncio.to_thread(self._put_all, messages)

    async def _stamps(self, site_id: str) -> dict[str, tuple[int, int]]:
        """Fragment id -> (sec, nanosec): the source cloud's stamp, else the upload time."""
        status = await load_site_status(self.backend, site_id)
        stamps = {}
        for fragment in status.fragments:
            frac, whole = math.modf(fragment.created_at.timestamp())
            stamps[fragment.fragment_id] = (int(whole), int(frac * 1e9))
        for fid, sender in (await load_senders(self.backend, site_id)).items():
            if sender.stamp_sec is not None and sender.stamp_nanosec is not None:
                stamps[fid] = (sender.stamp_sec, sender.stamp_nanosec)
        return stamps

    def _put_all(self, messages: list[bytes]) -> None:
        assert self._publisher is not None
        for cdr in messages:
            attachment = encode_attachment(next(self._sequence), time.time_ns(), self._gid)
            self._publisher.put(cdr, attachment=attachment)
