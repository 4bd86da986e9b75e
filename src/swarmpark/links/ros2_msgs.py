"""ROS 2 messages without a ROS install: types, CDR bytes and conversions to the link's.

The message definitions and the CDR (de)serializer are ``rosbags``' (its ROS 2 Jazzy type
store; the messages swarmpark uses are the same in every ROS 2 release since Humble). For
the DDS transport (``cyclonedds``) a topic needs a type with the ROS 2 DDS name
(``geometry_msgs::msg::dds_::Twist_``): :func:`dds_type` builds it from the same definition,
so the type information Cyclone announces describes the real fields. The samples on the wire
are the bytes :func:`serialize` gives (rosbags' CDR), written and taken raw.

Conversions follow REP-103 (SI units, yaw counter-clockwise about +z) and turn stamped ROS
messages into :mod:`swarmpark.links.base` messages and back.
"""

from __future__ import annotations

import math
import struct
from functools import cache

import numpy as np

from swarmpark.core.geometry import wrap_angle

#: The CDR encapsulation header of little-endian plain CDR (XCDR1).
_CDR_LE = b"\x00\x01\x00\x00"

__all__ = [
    "twist_cdr",
    "TYPESTORE",
    "msg",
    "serialize",
    "deserialize",
    "dds_type",
    "dds_name",
    "stamp_of",
    "time_msg",
    "header",
    "yaw_of",
    "quaternion",
    "pose_msg",
    "twist",
    "twist_stamped",
    "odometry",
    "laser_scan",
    "occupancy_grid",
    "transform",
    "tf_message",
    "pose_array",
]


@cache
def _store():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


class _Store:
    """Lazy access to the rosbags type store (importing it costs ~0.3 s)."""

    def __getattr__(self, name):
        return getattr(_store(), name)


TYPESTORE = _Store()


def msg(typename: str):
    """The rosbags message class of ``typename`` (``"geometry_msgs/msg/Twist"``)."""
    try:
        return _store().types[typename]
    except KeyError:
        raise ValueError(f"ros2: unknown message type {typename!r}") from None


def serialize(message, typename: str) -> bytes:
    """CDR bytes (little endian, with the 4-byte encapsulation header) of ``message``."""
    return bytes(_store().serialize_cdr(message, typename))


def deserialize(data: bytes, typename: str):
    """The rosbags message of ``typename`` in ``data`` (CDR with its encapsulation header).

    DDS pads samples to 4 bytes; the padding is ignored."""
    return _store().deserialize_cdr(data, typename)


def dds_name(typename: str) -> str:
    """``pkg/msg/T`` -> ``pkg::msg::dds_::T_`` (the type name rmw gives a ROS 2 type)."""
    pkg, kind, name = typename.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


_BASE = {
    "bool": "bool",
    "byte": "uint8",
    "char": "uint8",
    "int8": "int8",
    "uint8": "uint8",
    "int16": "int16",
    "uint16": "uint16",
    "int32": "int32",
    "uint32": "uint32",
    "int64": "int64",
    "uint64": "uint64",
    "float32": "float32",
    "float64": "float64",
}


def _idl_field(node):
    import cyclonedds.idl.types as T

    kind, rest = node
    kind = int(kind)
    if kind == 1:  # BASE: (name, string bound)
        name, bound = rest
        if name == "string":
            return T.bounded_str[bound] if bound else str
        if name == "bool":
            return bool
        return getattr(T, _BASE[name])
    if kind == 2:  # NAME: a nested message
        return dds_type(rest)
    if kind == 3:  # ARRAY: (element, length)
        return T.array[_idl_field(rest[0]), rest[1]]
    if kind == 4:  # SEQUENCE: (element, bound)
        elem, bound = rest
        return T.sequence[_idl_field(elem), bound] if bound else T.sequence[_idl_field(elem)]
    raise ValueError(f"ros2: unsupported field kind {kind}")


@cache
def dds_type(typename: str):
    """A ``cyclonedds`` IDL struct named as rmw names ``typename``, with its fields."""
    from cyclonedds.idl import make_idl_struct

    _, fields = _store().fielddefs[typename]
    if not fields:  # an empty ROS message carries one uint8 in DDS
        import cyclonedds.idl.types as T

        spec = {"structure_needs_at_least_one_member": T.uint8}
    else:
        spec = {name: _idl_field(node) for name, node in fields}
    return make_idl_struct(typename.replace("/", "_"), dds_name(typename), spec)


# ----------------------------------------------------------------------------- building blocks


def time_msg(t: float):
    """``builtin_interfaces/Time`` of ``t`` seconds (epoch)."""
    sec = math.floor(t)
    nsec = min(int(round((t - sec) * 1e9)), 999_999_999)
    return msg("builtin_interfaces/msg/Time")(sec=int(sec), nanosec=nsec)


def stamp_of(m) -> float:
    """Seconds of a message's ``header.stamp``."""
    s = m.header.stamp
    return s.sec + s.nanosec * 1e-9


def header(t: float, frame_id: str):
    return msg("std_msgs/msg/Header")(stamp=time_msg(t), frame_id=frame_id)


def quaternion(yaw: float):
    """The rotation ``yaw`` about +z."""
    return msg("geometry_msgs/msg/Quaternion")(
        x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
    )


def yaw_of(q) -> float:
    """Yaw (about +z) of a quaternion (its roll and pitch are ignored: planar robots)."""
    return float(math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z)))


def pose_msg(pose) -> object:
    """``geometry_msgs/Pose`` of ``(x, y, yaw)``."""
    x, y, yaw = (float(v) for v in pose)
    p = msg("geometry_msgs/msg/Point")(x=x, y=y, z=0.0)
    return msg("geometry_msgs/msg/Pose")(position=p, orientation=quaternion(yaw))


def pose_of(p) -> np.ndarray:
    """``(x, y, yaw)`` of a ``geometry_msgs/Pose``."""
    return np.array([p.position.x, p.position.y, yaw_of(p.orientation)])


def _vec3(x=0.0, y=0.0, z=0.0):
    return msg("geometry_msgs/msg/Vector3")(x=float(x), y=float(y), z=float(z))


# ----------------------------------------------------------------------------- messages


def twist(v: float, omega: float):
    """``geometry_msgs/Twist``: forward ``v`` (m/s), yaw rate ``omega`` (rad/s)."""
    return msg("geometry_msgs/msg/Twist")(linear=_vec3(v), angular=_vec3(z=omega))


def twist_cdr(v: float, omega: float) -> bytes:
    """The CDR bytes of :func:`twist` without building the message (the hot path: one per
    robot per control period). A Twist is six float64, little endian, after the header."""
    return _CDR_LE + struct.pack("<6d", v, 0.0, 0.0, 0.0, 0.0, omega)


def twist_stamped(t: float, frame_id: str, v: float, omega: float):
    return msg("geometry_msgs/msg/TwistStamped")(header=header(t, frame_id), twist=twist(v, omega))


def odometry(t: float, frame_id: str, child: str, pose, vel) -> object:
    """``nav_msgs/Odometry``: ``pose`` ``(x, y, yaw)`` in ``frame_id``, ``vel`` ``(v, omega)``
    in ``child`` (the body frame)."""
    cov = np.zeros(36)
    pwc = msg("geometry_msgs/msg/PoseWithCovariance")(pose=pose_msg(pose), covariance=cov)
    twc = msg("geometry_msgs/msg/TwistWithCovariance")(
        twist=twist(float(vel[0]), float(vel[1])), covariance=cov.copy()
    )
    return msg("nav_msgs/msg/Odometry")(
        header=header(t, frame_id), child_frame_id=child, pose=pwc, twist=twc
    )


def laser_scan(t: float, frame_id: str, angles: np.ndarray, ranges: np.ndarray, max_range: float):
    """``sensor_msgs/LaserScan`` over evenly spaced ``angles``; ``nan`` ranges (no return)
    become ``+inf`` (REP-117: beyond range)."""
    angles = np.asarray(angles, float)
    inc = float(angles[1] - angles[0]) if len(angles) > 1 else 0.0
    r = np.asarray(ranges, np.float32)
    r = np.where(np.isfinite(r), r, np.float32(np.inf)).astype(np.float32)
    return msg("sensor_msgs/msg/LaserScan")(
        header=header(t, frame_id),
        angle_min=float(angles[0]),
        angle_max=float(angles[-1]),
        angle_increment=inc,
        time_increment=0.0,
        scan_time=0.0,
        range_min=0.0,
        range_max=float(max_range),
        ranges=r,
        intensities=np.zeros(0, np.float32),
    )


def scan_ranges(m) -> np.ndarray:
    """Ranges of a LaserScan with the link's convention: ``nan`` where there is no return."""
    r = np.asarray(m.ranges, float)
    ok = np.isfinite(r) & (r >= m.range_min) & (r <= m.range_max)
    return np.where(ok, r, np.nan)


def occupancy_grid(t: float, frame_id: str, occupied: np.ndarray, resolution: float, origin_xy):
    """``nav_msgs/OccupancyGrid`` of a boolean grid (row 0 at ``origin_xy``'s y, x along
    columns): 100 occupied, 0 free."""
    occ = np.asarray(occupied, bool)
    rows, cols = occ.shape
    meta = msg("nav_msgs/msg/MapMetaData")(
        map_load_time=time_msg(t),
        resolution=float(resolution),
        width=int(cols),
        height=int(rows),
        origin=pose_msg((origin_xy[0], origin_xy[1], 0.0)),
    )
    data = np.where(occ, 100, 0).astype(np.int8).ravel()
    return msg("nav_msgs/msg/OccupancyGrid")(header=header(t, frame_id), info=meta, data=data)


def transform(t: float, parent: str, child: str, pose) -> object:
    """``geometry_msgs/TransformStamped``: ``child`` at ``pose`` ``(x, y, yaw)`` in ``parent``."""
    x, y, yaw = (float(v) for v in pose)
    tr = msg("geometry_msgs/msg/Transform")(translation=_vec3(x, y), rotation=quaternion(yaw))
    return msg("geometry_msgs/msg/TransformStamped")(
        header=header(t, parent), child_frame_id=child, transform=tr
    )


def tf_message(transforms: list) -> object:
    return msg("tf2_msgs/msg/TFMessage")(transforms=list(transforms))


def pose_array(t: float, frame_id: str, poses) -> object:
    return msg("geometry_msgs/msg/PoseArray")(
        header=header(t, frame_id), poses=[pose_msg(p) for p in poses]
    )


def compose(a, b) -> np.ndarray:
    """Pose ``b`` (in the frame at ``a``) expressed in ``a``'s parent frame: ``a ⊕ b``."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array(
        [a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap_angle(a[2] + b[2])]
    )


def inverse(a) -> np.ndarray:
    """The pose ``a⁻¹`` with ``a ⊕ a⁻¹ = 0``."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([-c * a[0] - s * a[1], s * a[0] - c * a[1], wrap_angle(-a[2])])
