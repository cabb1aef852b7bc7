"""ROS 2 over zenoh without ROS: rmw_zenoh key expressions and attachments, CDR messages.

As rmw_zenoh documents it (docs/design.md of ros2/rmw_zenoh):

- a topic's data key expression is ``<domain_id>/<fully qualified name>/<type name>/<type
  hash>``, e.g. ``0/robot1/fragments/sensor_msgs::msg::dds_::PointCloud2_/RIHS01_9198...``;
  the type hash is REP-2016's ``RIHS01_<sha256>``, ``TypeHashNotSupported`` on Humble;
- every published sample carries a 33-byte attachment: int64 sequence number and int64
  source timestamp (ns since the UNIX epoch), both little-endian, then the length of the
  publisher GID (one byte, 16) and the 16-byte GID;
- graph discovery uses liveliness tokens ``@ros2_lv/<domain>/<session id>/<node id>/<entity
  id>/<kind>/<enclave>/<namespace>/<node>[/<topic>/<type>/<hash>/<qos>]`` with ``/`` in names
  mangled to ``%`` and ``%`` for an empty namespace or enclave.

Payloads are CDR (little-endian encapsulation), (de)serialized with the ``rosbags`` type store.
Messages: ``sensor_msgs/msg/PointCloud2``, depth ``sensor_msgs/msg/Image`` with its
``sensor_msgs/msg/CameraInfo`` (in), ``geometry_msgs/msg/PoseStamped``,
``nav_msgs/msg/OccupancyGrid`` and ``tf2_msgs/msg/TFMessage`` (out); each has an encoder and
a decoder, so robots and tests speak the same CDR as the service.
"""

from __future__ import annotations

import hashlib
import struct
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore
from scipy.spatial.transform import Rotation

from services.errors import InvalidDepthError, InvalidFragmentError, InvalidIntrinsicsError
from services.occupancy import OccupancyGrid
from services.point_io import encode_ply
from services.types import FloatArray

__all__ = [
    "CAMERA_INFO_TYPE",
    "CLOUD_TYPE",
    "IMAGE_TYPE",
    "MAP_TYPE",
    "POSE_TYPE",
    "TF_TYPE",
    "DecodedCameraInfo",
    "DecodedCloud",
    "DecodedDepth",
    "DecodedTransform",
    "RmwAttachment",
    "cloud_to_ply",
    "dds_type_name",
    "decode_attachment",
    "decode_camera_info",
    "decode_depth_image",
    "decode_occupancy_grid",
    "decode_pointcloud2",
    "decode_pose_stamped",
    "decode_tf_message",
    "encode_attachment",
    "encode_camera_info",
    "encode_image",
    "encode_occupancy_grid",
    "encode_pointcloud2",
    "encode_pose_stamped",
    "encode_tf_message",
    "endpoint_token",
    "entity_gid",
    "mangle",
    "node_token",
    "topic_key",
    "type_hash",
]

CLOUD_TYPE = "sensor_msgs/msg/PointCloud2"
POSE_TYPE = "geometry_msgs/msg/PoseStamped"
IMAGE_TYPE = "sensor_msgs/msg/Image"
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"
MAP_TYPE = "nav_msgs/msg/OccupancyGrid"
TF_TYPE = "tf2_msgs/msg/TFMessage"
DEFAULT_QOS = "::,10:,:,:,,"  # reliable, volatile, keep last 10 (rmw_zenoh's compact form)

_ATTACHMENT = struct.Struct("<qqB16s")
# sensor_msgs/msg/PointField datatype -> numpy type code.
_FIELD_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
# Depth image encodings of REP 118 -> (numpy type code, meters per value).
_DEPTH_ENCODINGS = {"16UC1": ("u2", 1e-3), "32FC1": ("f4", 1.0)}


@cache
def _store(distro: str = "latest") -> Typestore:
    try:
        return get_typestore(Stores(f"ros2_{distro}"))
    except ValueError:
        return get_typestore(Stores.LATEST)


def dds_type_name(msgtype: str) -> str:
    """The type name rmw_zenoh puts in key expressions.

    >>> dds_type_name("sensor_msgs/msg/PointCloud2")
    'sensor_msgs::msg::dds_::PointCloud2_'
    """
    package, kind, name = msgtype.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def type_hash(msgtype: str, distro: str = "jazzy") -> str:
    """REP-2016 type hash of ``msgtype`` (``TypeHashNotSupported`` for Humble)."""
    if distro == "humble":
        return "TypeHashNotSupported"
    return str(_store(distro).hash_rihs01(msgtype))


def topic_key(domain_id: int, topic: str, msgtype: str, hash_: str = "*") -> str:
    """The data key expression of a topic (``*`` as hash matches every distribution).

    >>> topic_key(0, "/robot1/fragments", "sensor_msgs/msg/PointCloud2")
    '0/robot1/fragments/sensor_msgs::msg::dds_::PointCloud2_/*'
    """
    return f"{domain_id}/{topic.strip('/')}/{dds_type_name(msgtype)}/{hash_}"


def mangle(name: str) -> str:
    """A name as one key chunk (``/`` -> ``%``; empty -> ``%``)."""
    return name.replace("/", "%") or "%"


def node_token(domain_id: int, session_id: str, node: str, namespace: str = "") -> str:
    """Liveliness token of a node (entity kind ``NN``)."""
    return f"@ros2_lv/{domain_id}/{session_id}/0/0/NN/%/{mangle(namespace)}/{node}"


def endpoint_token(
    domain_id: int,
    session_id: str,
    node: str,
    entity_id: int,
    kind: str,
    topic: str,
    msgtype: str,
    hash_: str,
) -> str:
    """Liveliness token of a publisher (``MP``) or subscription (``MS``) of ``node``."""
    base = f"@ros2_lv/{domain_id}/{session_id}/0/{entity_id}/{kind}/%/%/{node}"
    return f"{base}/{mangle(topic)}/{dds_type_name(msgtype)}/{hash_}/{DEFAULT_QOS}"


def entity_gid(token: str) -> bytes:
    """A stable 16-byte GID for the entity of a liveliness token."""
    return hashlib.sha256(token.encode()).digest()[:16]


@dataclass(frozen=True)
class RmwAttachment:
    """The attachment rmw_zenoh sends with every sample."""

    sequence_number: int
    source_timestamp_ns: int
    gid: bytes


def encode_attachment(sequence_number: int, timestamp_ns: int, gid: bytes) -> bytes:
    """The 33-byte rmw_zenoh attachment.

    >>> len(encode_attachment(1, 2, bytes(16)))
    33
    """
    if len(gid) != 16:
        raise ValueError(f"a GID has 16 bytes, not {len(gid)}")
    return _ATTACHMENT.pack(sequence_number, timestamp_ns, 16, gid)


def decode_attachment(data: bytes) -> RmwAttachment:
    """Parse an rmw_zenoh attachment (ValueError when it is not one)."""
    if len(data) != _ATTACHMENT.size:
        raise ValueError(f"an rmw_zenoh attachment has {_ATTACHMENT.size} bytes, not {len(data)}")
    seq, stamp, size, gid = _ATTACHMENT.unpack(data)
    if size != 16:
        raise ValueError(f"GID length {size}, expected 16")
    return RmwAttachment(seq, stamp, gid)


@dataclass(frozen=True)
class DecodedCloud:
    """A PointCloud2's x, y, z and header.

    ``points``: (N, 3) float64, the message's frame, meters; NaN rows kept (the parser drops
    and counts them). ``double``: the message stored coordinates as float64.
    """

    points: FloatArray
    stamp_sec: int
    stamp_nanosec: int
    frame_id: str
    double: bool


def _xyz_dtype(msg: Any) -> tuple[np.dtype[Any], bool]:
    fields = {f.name: f for f in msg.fields}
    order = ">" if msg.is_bigendian else "<"
    names, formats, offsets = [], [], []
    for axis in "xyz":
        spec = fields.get(axis)
        if spec is None or spec.datatype not in _FIELD_TYPES or spec.count < 1:
            raise InvalidFragmentError(f"PointCloud2 without a usable {axis!r} field")
        code = _FIELD_TYPES[spec.datatype]
        if spec.offset + int(code[1]) > msg.point_step:
            raise InvalidFragmentError(f"PointCloud2 field {axis!r} lies outside point_step")
        names.append(axis)
        formats.append(order + code)
        offsets.append(spec.offset)
    dtype = np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": msg.point_step}
    )
    return dtype, any(f.endswith("f8") for f in formats)


def decode_pointcloud2(cdr: bytes) -> DecodedCloud:
    """Decode a CDR ``sensor_msgs/msg/PointCloud2`` into its points (no loop over points).

    Raises
    ------
    InvalidFragmentError
        Not a PointCloud2, no x/y/z, or data shorter than ``row_step * height``.
    """
    try:
        msg: Any = _store().deserialize_cdr(cdr, CLOUD_TYPE)
    except SerdeError as exc:
        raise InvalidFragmentError(f"not a CDR PointCloud2: {exc}") from exc
    height, width, step, row = msg.height, msg.width, msg.point_step, msg.row_step
    if step < 1 or row < width * step or len(msg.data) < row * height:
        raise InvalidFragmentError(
            f"PointCloud2 of {height}x{width} points, point_step {step}, row_step {row} "
            f"does not fit its {len(msg.data)} data bytes"
        )
    dtype, double = _xyz_dtype(msg)
    data = np.asarray(msg.data, dtype=np.uint8)[: row * height].reshape(height, row)
    records = np.ascontiguousarray(data[:, : width * step]).reshape(-1).view(dtype)
    points = np.column_stack([records[axis].astype(np.float64) for axis in "xyz"])
    stamp = msg.header.stamp
    return DecodedCloud(
        points.reshape(-1, 3), int(stamp.sec), int(stamp.nanosec), msg.header.frame_id, double
    )


def cloud_to_ply(cloud: DecodedCloud) -> bytes:
    """The fragment file of a decoded cloud: binary PLY, float or double as the message had."""
    return encode_ply(cloud.points, double=cloud.double)


def _header(stamp_sec: int, stamp_nanosec: int, frame_id: str) -> Any:
    types = _store().types
    stamp = types["builtin_interfaces/msg/Time"](sec=stamp_sec, nanosec=stamp_nanosec)
    return types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)


def encode_pointcloud2(
    points: ArrayLike,
    stamp_sec: int = 0,
    stamp_nanosec: int = 0,
    frame_id: str = "",
    *,
    double: bool = False,
    height: int = 1,
) -> bytes:
    """A CDR ``sensor_msgs/msg/PointCloud2`` of (N, 3) points, as a ROS 2 driver publishes it:
    x, y, z (float32 or float64) plus a 4-byte intensity field, little-endian."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    code = "<f8" if double else "<f4"
    size = 8 if double else 4
    dtype = np.dtype([("x", code), ("y", code), ("z", code), ("intensity", "<f4")])
    records = np.zeros(len(pts), dtype=dtype)
    for j, axis in enumerate("xyz"):
        records[axis] = pts[:, j]
    types = _store().types
    field = types["sensor_msgs/msg/PointField"]
    fields = [
        field(name=a, offset=j * size, datatype=8 if double else 7, count=1)
        for j, a in enumerate("xyz")
    ]
    fields.append(field(name="intensity", offset=3 * size, datatype=7, count=1))
    width = len(pts) // height
    msg = types[CLOUD_TYPE](
        header=_header(stamp_sec, stamp_nanosec, frame_id),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=False,
        point_step=dtype.itemsize,
        row_step=dtype.itemsize * width,
        data=records.view(np.uint8).reshape(-1),
        is_dense=bool(np.isfinite(pts).all()),
    )
    return bytes(_store().serialize_cdr(msg, CLOUD_TYPE))


def _rotation_quaternion(matrix: FloatArray) -> tuple[float, float, float, float]:
    """(x, y, z, w) unit quaternion of a 4x4 pose's rotation."""
    qx, qy, qz, qw = Rotation.from_matrix(matrix[:3, :3]).as_quat()
    return float(qx), float(qy), float(qz), float(qw)


def _pose_matrix(translation: Any, quaternion: Any) -> FloatArray:
    """4x4 pose of a message's translation (x, y, z) and quaternion (x, y, z, w)."""
    q, t = quaternion, translation
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    matrix[:3, 3] = [t.x, t.y, t.z]
    return matrix


def _header_of(msg: Any) -> tuple[int, int, str]:
    stamp = msg.header.stamp
    return int(stamp.sec), int(stamp.nanosec), str(msg.header.frame_id)


def _pose_msg(matrix: FloatArray) -> Any:
    types = _store().types
    position = types["geometry_msgs/msg/Point"](
        x=float(matrix[0, 3]), y=float(matrix[1, 3]), z=float(matrix[2, 3])
    )
    qx, qy, qz, qw = _rotation_quaternion(matrix)
    orientation = types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw)
    return types["geometry_msgs/msg/Pose"](position=position, orientation=orientation)


def encode_pose_stamped(
    pose: ArrayLike, stamp_sec: int, stamp_nanosec: int, frame_id: str
) -> bytes:
    """A CDR ``geometry_msgs/msg/PoseStamped`` of a 4x4 pose (rotation as a unit quaternion)."""
    matrix = np.asarray(pose, dtype=np.float64).reshape(4, 4)
    msg = _store().types[POSE_TYPE](
        header=_header(stamp_sec, stamp_nanosec, frame_id), pose=_pose_msg(matrix)
    )
    return bytes(_store().serialize_cdr(msg, POSE_TYPE))


def decode_pose_stamped(cdr: bytes) -> tuple[FloatArray, int, int, str]:
    """``(pose 4x4, stamp sec, stamp nanosec, frame_id)`` of a CDR PoseStamped."""
    msg: Any = _store().deserialize_cdr(cdr, POSE_TYPE)
    return (_pose_matrix(msg.pose.position, msg.pose.orientation), *_header_of(msg))


# ------------------------------------------------------------------ depth images in


@dataclass(frozen=True)
class DecodedDepth:
    """A depth ``sensor_msgs/msg/Image`` and its header.

    ``depth``: (H, W) float32, meters along the optical axis, 0 where there is no reading
    (REP 118's NaN and infinities, and negative values, become 0).
    """

    depth: NDArray[np.float32]
    stamp_sec: int
    stamp_nanosec: int
    frame_id: str
    encoding: str


def decode_depth_image(cdr: bytes) -> DecodedDepth:
    """Decode a CDR depth image: ``16UC1`` (millimetres) or ``32FC1`` (meters), REP 118.

    Raises
    ------
    InvalidDepthError
        Not a CDR Image, another encoding (colour, 8-bit, ...), or a size that does not fit
        its data (``step * height`` bytes, ``step`` at least a row of pixels).
    """
    try:
        msg: Any = _store().deserialize_cdr(cdr, IMAGE_TYPE)
    except SerdeError as exc:
        raise InvalidDepthError(f"not a CDR Image: {exc}") from exc
    spec = _DEPTH_ENCODINGS.get(msg.encoding)
    if spec is None:
        raise InvalidDepthError(
            f"Image encoding {msg.encoding[:40]!r}: a depth image is 16UC1 (millimetres) "
            "or 32FC1 (meters)"
        )
    code, meters_per_value = spec
    dtype = np.dtype(code).newbyteorder(">" if msg.is_bigendian else "<")
    height, width, step = msg.height, msg.width, msg.step
    row_bytes = width * dtype.itemsize
    if height < 1 or width < 1 or step < row_bytes or len(msg.data) < step * height:
        raise InvalidDepthError(
            f"Image of {width}x{height} {msg.encoding}, step {step}, does not fit its "
            f"{len(msg.data)} data bytes"
        )
    rows = np.asarray(msg.data, dtype=np.uint8)[: step * height].reshape(height, step)
    values = np.ascontiguousarray(rows[:, :row_bytes]).view(dtype).reshape(height, width)
    depth = values.astype(np.float32) * np.float32(meters_per_value)
    depth[~np.isfinite(depth) | (depth < 0)] = 0.0  # REP 118: NaN and +-inf are no reading
    return DecodedDepth(depth, *_header_of(msg), str(msg.encoding))


def encode_image(
    pixels: ArrayLike, encoding: str, stamp_sec: int = 0, stamp_nanosec: int = 0, frame_id: str = ""
) -> bytes:
    """A CDR ``sensor_msgs/msg/Image`` of (H, W) or (H, W, C) pixel values, little-endian,
    rows unpadded; ``encoding`` as in ``sensor_msgs/image_encodings`` (``16UC1``, ``32FC1``,
    ``mono8``, ``rgb8``, ...). For a depth image: millimetres as uint16 in ``16UC1``, meters
    as float32 in ``32FC1``."""
    array = np.asarray(pixels)
    height, width = array.shape[:2]
    little = np.ascontiguousarray(array, dtype=array.dtype.newbyteorder("<"))
    types = _store().types
    msg = types[IMAGE_TYPE](
        header=_header(stamp_sec, stamp_nanosec, frame_id),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=little[0].nbytes if height else 0,
        data=little.view(np.uint8).reshape(-1),
    )
    return bytes(_store().serialize_cdr(msg, IMAGE_TYPE))


@dataclass(frozen=True)
class DecodedCameraInfo:
    """What a ``sensor_msgs/msg/CameraInfo`` says of the pinhole camera (pixels)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    stamp_sec: int
    stamp_nanosec: int
    frame_id: str


def decode_camera_info(cdr: bytes) -> DecodedCameraInfo:
    """Size and ``K`` (row-major ``[fx, 0, cx, 0, fy, cy, 0, 0, 1]``) of a CDR CameraInfo.

    Raises
    ------
    InvalidIntrinsicsError
        Not a CDR CameraInfo.
    """
    try:
        msg: Any = _store().deserialize_cdr(cdr, CAMERA_INFO_TYPE)
    except SerdeError as exc:
        raise InvalidIntrinsicsError(f"not a CDR CameraInfo: {exc}") from exc
    k = [float(v) for v in msg.k]
    return DecodedCameraInfo(
        int(msg.width), int(msg.height), k[0], k[4], k[2], k[5], *_header_of(msg)
    )


def encode_camera_info(
    width: int,
    height: int,
    k: tuple[float, float, float, float],
    stamp_sec: int = 0,
    stamp_nanosec: int = 0,
    frame_id: str = "",
) -> bytes:
    """A CDR ``sensor_msgs/msg/CameraInfo`` of an undistorted pinhole camera;
    ``k`` is (fx, fy, cx, cy) in pixels."""
    fx, fy, cx, cy = k
    types = _store().types
    msg = types[CAMERA_INFO_TYPE](
        header=_header(stamp_sec, stamp_nanosec, frame_id),
        height=height,
        width=width,
        distortion_model="plumb_bob",
        d=np.zeros(5),
        k=np.array([fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]),
        r=np.eye(3).reshape(-1),
        p=np.array([fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]),
        binning_x=0,
        binning_y=0,
        roi=types["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        ),
    )
    return bytes(_store().serialize_cdr(msg, CAMERA_INFO_TYPE))


# ------------------------------------------------------------------ maps and transforms out


def encode_occupancy_grid(
    grid: OccupancyGrid, stamp_sec: int, stamp_nanosec: int, frame_id: str
) -> bytes:
    """A CDR ``nav_msgs/msg/OccupancyGrid``: the grid's cells row-major from its origin
    (``info.origin`` at floor height, not rotated), ``map_load_time`` the header's stamp."""
    types = _store().types
    stamp = types["builtin_interfaces/msg/Time"](sec=stamp_sec, nanosec=stamp_nanosec)
    origin = np.eye(4)
    origin[:2, 3] = grid.origin
    info = types["nav_msgs/msg/MapMetaData"](
        map_load_time=stamp,
        resolution=grid.resolution,
        width=grid.width,
        height=grid.height,
        origin=_pose_msg(origin),
    )
    msg = types[MAP_TYPE](
        header=_header(stamp_sec, stamp_nanosec, frame_id),
        info=info,
        data=np.ascontiguousarray(grid.cells, dtype=np.int8).reshape(-1),
    )
    return bytes(_store().serialize_cdr(msg, MAP_TYPE))


def decode_occupancy_grid(cdr: bytes) -> tuple[OccupancyGrid, int, int, str]:
    """``(grid, stamp sec, stamp nanosec, frame_id)`` of a CDR OccupancyGrid (the origin's
    rotation is not applied: the service never rotates it)."""
    msg: Any = _store().deserialize_cdr(cdr, MAP_TYPE)
    info = msg.info
    cells = np.asarray(msg.data, dtype=np.int8).reshape(info.height, info.width)
    origin = (float(info.origin.position.x), float(info.origin.position.y))
    return OccupancyGrid(cells, float(info.resolution), origin), *_header_of(msg)


@dataclass(frozen=True)
class DecodedTransform:
    """One ``geometry_msgs/msg/TransformStamped``: ``pose`` (4x4) maps ``child_frame``
    coordinates to ``parent_frame`` ones."""

    parent_frame: str
    child_frame: str
    pose: FloatArray
    stamp_sec: int
    stamp_nanosec: int


def encode_tf_message(
    poses: dict[str, FloatArray], parent_frame: str, stamp_sec: int, stamp_nanosec: int
) -> bytes:
    """A CDR ``tf2_msgs/msg/TFMessage``: one transform per child frame (``poses``: child
    frame -> 4x4 pose mapping the child's points into ``parent_frame``), one stamp."""
    types = _store().types
    transforms = []
    for child, pose in poses.items():
        matrix = np.asarray(pose, dtype=np.float64).reshape(4, 4)
        qx, qy, qz, qw = _rotation_quaternion(matrix)
        x, y, z = (float(v) for v in matrix[:3, 3])
        transform = types["geometry_msgs/msg/Transform"](
            translation=types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
            rotation=types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
        )
        transforms.append(
            types["geometry_msgs/msg/TransformStamped"](
                header=_header(stamp_sec, stamp_nanosec, parent_frame),
                child_frame_id=child,
                transform=transform,
            )
        )
    return bytes(_store().serialize_cdr(types[TF_TYPE](transforms=transforms), TF_TYPE))


def decode_tf_message(cdr: bytes) -> list[DecodedTransform]:
    """The transforms of a CDR TFMessage, in message order."""
    msg: Any = _store().deserialize_cdr(cdr, TF_TYPE)
    decoded = []
    for item in msg.transforms:
        sec, nanosec, parent = _header_of(item)
        pose = _pose_matrix(item.transform.translation, item.transform.rotation)
        decoded.append(DecodedTransform(parent, str(item.child_frame_id), pose, sec, nanosec))
    return decoded
