"""ROS 2 messages of a run: build them from arrays and serialize them as CDR.

The message definitions come from ``rosbags``' Humble type store, so a recording carries
the same ``ros2msg`` schemas that ``ros2 bag`` and Foxglove expect. Everything here is a
function of arrays (poses ``(N, 3)``, velocities ``(N, 2)``); nothing reads the simulator.
Stamps are simulated time in nanoseconds.
"""

from __future__ import annotations

import functools
import json

import numpy as np
from rosbags.typesys import Stores, get_typestore

__all__ = [
    "TYPES",
    "typestore",
    "msgdef",
    "serialize",
    "deserialize",
    "occupancy_grid",
    "tf_message",
    "odometry",
    "twist",
    "laser_scan",
    "footprint_markers",
    "goal_markers",
    "boundary_markers",
    "world_markers",
    "people_markers",
    "json_string",
    "yaw_quaternion",
    "quaternion_yaw",
]

#: Short names of the message types a recording uses.
TYPES = {
    "map": "nav_msgs/msg/OccupancyGrid",
    "tf": "tf2_msgs/msg/TFMessage",
    "odom": "nav_msgs/msg/Odometry",
    "scan": "sensor_msgs/msg/LaserScan",
    "twist": "geometry_msgs/msg/Twist",
    "markers": "visualization_msgs/msg/MarkerArray",
    "string": "std_msgs/msg/String",
    "path": "nav_msgs/msg/Path",
}
MAP_FRAME = "map"
#: Occupancy values of nav_msgs/OccupancyGrid.
OCC_FREE, OCC_OCCUPIED, OCC_UNKNOWN = 0, 100, -1
#: Marker heights (m): footprints are drawn as flat boxes, people as cylinders.
FOOTPRINT_HEIGHT_M = 0.3
PERSON_HEIGHT_M = 1.7
LINE_WIDTH_M = 0.05


@functools.cache
def typestore():
    """The ROS 2 Humble type store (built once)."""
    return get_typestore(Stores.ROS2_HUMBLE)


def _t(name: str):
    return typestore().types[name]


@functools.cache
def msgdef(typename: str) -> str:
    """The ``ros2msg`` schema text of ``typename`` (with its dependencies)."""
    return typestore().generate_msgdef(typename, ros_version=2)[0]


def serialize(msg, typename: str) -> bytes:
    return bytes(typestore().serialize_cdr(msg, typename))


def deserialize(data: bytes, typename: str):
    return typestore().deserialize_cdr(data, typename)


# ----------------------------------------------------------------------------- small parts


def _stamp(t_ns: int):
    return _t("builtin_interfaces/msg/Time")(sec=int(t_ns // 10**9), nanosec=int(t_ns % 10**9))


def _header(t_ns: int, frame: str):
    return _t("std_msgs/msg/Header")(stamp=_stamp(t_ns), frame_id=frame)


def yaw_quaternion(yaw: np.ndarray) -> np.ndarray:
    """Quaternions ``(N, 4)`` as ``(x, y, z, w)`` of rotations by ``yaw`` about +z."""
    yaw = np.asarray(yaw, float)
    h = 0.5 * yaw
    z = np.zeros_like(h)
    return np.stack([z, z, np.sin(h), np.cos(h)], axis=-1)


def quaternion_yaw(q: np.ndarray) -> np.ndarray:
    """Yaw of quaternions ``(..., 4)`` ``(x, y, z, w)`` that rotate about +z."""
    q = np.asarray(q, float)
    return 2.0 * np.arctan2(q[..., 2], q[..., 3])


def _pose(x: float, y: float, yaw: float, z: float = 0.0):
    q = yaw_quaternion(yaw)
    return _t("geometry_msgs/msg/Pose")(
        position=_t("geometry_msgs/msg/Point")(x=float(x), y=float(y), z=float(z)),
        orientation=_t("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=float(q[2]), w=float(q[3])),
    )


def _vec(x: float = 0.0, y: float = 0.0, z: float = 0.0):
    return _t("geometry_msgs/msg/Vector3")(x=float(x), y=float(y), z=float(z))


def _colour(rgba) -> object:
    r, g, b, a = (float(c) for c in rgba)
    return _t("std_msgs/msg/ColorRGBA")(r=r, g=g, b=b, a=a)


# ----------------------------------------------------------------------------- messages


def occupancy_grid(t_ns: int, occupied: np.ndarray, unknown: np.ndarray, resolution_m, origin):
    """nav_msgs/OccupancyGrid of a grid whose row 0 is the lowest y (as ROS's)."""
    h, w = occupied.shape
    data = np.full((h, w), OCC_FREE, np.int8)
    data[unknown] = OCC_UNKNOWN
    data[occupied] = OCC_OCCUPIED
    info = _t("nav_msgs/msg/MapMetaData")(
        map_load_time=_stamp(t_ns),
        resolution=float(resolution_m),
        width=int(w),
        height=int(h),
        origin=_pose(origin[0], origin[1], 0.0),
    )
    return _t("nav_msgs/msg/OccupancyGrid")(
        header=_header(t_ns, MAP_FRAME), info=info, data=data.ravel()
    )


def tf_message(t_ns: int, parent: str | list[str], children: list[str], poses: np.ndarray):
    """tf2_msgs/TFMessage: ``parent`` (one frame, or one per child) -> each child at its
    pose ``(x, y, yaw)``."""
    Tf = _t("geometry_msgs/msg/TransformStamped")
    Transform = _t("geometry_msgs/msg/Transform")
    Quat = _t("geometry_msgs/msg/Quaternion")
    parents = [parent] * len(children) if isinstance(parent, str) else list(parent)
    headers = {p: _header(t_ns, p) for p in set(parents)}
    q = yaw_quaternion(poses[:, 2])
    out = []
    rows = zip(parents, children, poses.tolist(), q.tolist(), strict=True)
    for par, child, (x, y, _), (qx, qy, qz, qw) in rows:
        out.append(
            Tf(
                header=headers[par],
                child_frame_id=child,
                transform=Transform(translation=_vec(x, y), rotation=Quat(x=qx, y=qy, z=qz, w=qw)),
            )
        )
    return _t("tf2_msgs/msg/TFMessage")(transforms=out)


_ZERO_COV = np.zeros(36)


def odometry(t_ns: int, child: str, pose, vel):
    """nav_msgs/Odometry in the map frame; ``vel`` is ``(v, omega)`` in the body frame."""
    return _t("nav_msgs/msg/Odometry")(
        header=_header(t_ns, MAP_FRAME),
        child_frame_id=child,
        pose=_t("geometry_msgs/msg/PoseWithCovariance")(
            pose=_pose(pose[0], pose[1], pose[2]), covariance=_ZERO_COV
        ),
        twist=_t("geometry_msgs/msg/TwistWithCovariance")(
            twist=twist(vel[0], vel[1]), covariance=_ZERO_COV
        ),
    )


def twist(v: float, omega: float):
    """geometry_msgs/Twist: forward speed ``v`` and yaw rate ``omega``."""
    return _t("geometry_msgs/msg/Twist")(linear=_vec(v), angular=_vec(0.0, 0.0, omega))


def laser_scan(
    t_ns: int, frame: str, ranges: np.ndarray, *, angle_min, angle_increment, range_max, scan_time
):
    """sensor_msgs/LaserScan; a beam without a return (``inf``/``nan``) is ``inf``, as REP-117
    asks for "no return within range"."""
    r = np.asarray(ranges, np.float32)
    r = np.where(np.isfinite(r), r, np.float32(np.inf))
    n = len(r)
    return _t("sensor_msgs/msg/LaserScan")(
        header=_header(t_ns, frame),
        angle_min=float(angle_min),
        angle_max=float(angle_min + angle_increment * (n - 1)),
        angle_increment=float(angle_increment),
        time_increment=0.0,
        scan_time=float(scan_time),
        range_min=0.0,
        range_max=float(range_max),
        ranges=r,
        intensities=np.zeros(0, np.float32),
    )


def _marker(
    t_ns,
    ns,
    mid,
    mtype,
    *,
    pose=(0.0, 0.0, 0.0),
    scale=(1, 1, 1),
    rgba=(1, 1, 1, 1),
    points=(),
    text="",
    action=0,
    z=0.0,
):
    M = _t("visualization_msgs/msg/Marker")
    P = _t("geometry_msgs/msg/Point")
    return M(
        header=_header(t_ns, MAP_FRAME),
        ns=ns,
        id=int(mid),
        type=mtype,
        action=action,
        pose=_pose(pose[0], pose[1], pose[2], z),
        scale=_vec(*scale),
        color=_colour(rgba),
        lifetime=_t("builtin_interfaces/msg/Duration")(sec=0, nanosec=0),
        frame_locked=False,
        points=[P(x=float(x), y=float(y), z=0.0) for x, y in points],
        colors=[],
        texture_resource="",
        texture=_t("sensor_msgs/msg/CompressedImage")(
            header=_header(0, ""), format="", data=np.zeros(0, np.uint8)
        ),
        uv_coordinates=[],
        text=text,
        mesh_resource="",
        mesh_file=_t("visualization_msgs/msg/MeshFile")(filename="", data=np.zeros(0, np.uint8)),
        mesh_use_embedded_materials=False,
    )


def _array(markers):
    return _t("visualization_msgs/msg/MarkerArray")(markers=markers)


CUBE, ARROW, LINE_STRIP, CYLINDER, DELETE = 1, 0, 4, 3, 2
#: Colours (RGBA) of the drawn parts.
SKID_RGBA = (0.24, 0.65, 1.0, 0.8)
GOAL_RGBA = (0.3, 0.85, 0.4, 0.9)
BOUNDARY_RGBA = (1.0, 0.8, 0.1, 1.0)
WALL_RGBA = (0.35, 0.35, 0.35, 1.0)
PERSON_RGBA = (1.0, 0.45, 0.2, 0.9)


def footprint_markers(
    t_ns: int, ids, poses: np.ndarray, dims: np.ndarray, centre_offset: np.ndarray
):
    """A box per skid (``dims``: ``(N, 2)`` length, width; the box centre is
    ``centre_offset`` ahead of the pivot), namespace ``footprints``, id = robot index."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    cx = poses[:, 0] + c * centre_offset
    cy = poses[:, 1] + s * centre_offset
    return _array(
        [
            _marker(
                t_ns, "footprints", i, CUBE,
                pose=(cx[i], cy[i], poses[i, 2]),
                scale=(dims[i, 0], dims[i, 1], FOOTPRINT_HEIGHT_M),
                rgba=SKID_RGBA, text=ids[i], z=0.5 * FOOTPRINT_HEIGHT_M,
            )
            for i in range(len(ids))
        ]
    )  # fmt: skip


def goal_markers(t_ns: int, ids, goals: np.ndarray, has_goal: np.ndarray):
    """An arrow per goal (namespace ``goals``, id = robot index; a skid without a goal gets a
    DELETE for its id)."""
    out = []
    for i, rid in enumerate(ids):
        if has_goal[i]:
            out.append(
                _marker(t_ns, "goals", i, ARROW, pose=tuple(goals[i]), scale=(0.6, 0.1, 0.1), rgba=GOAL_RGBA, text=rid)
            )  # fmt: skip
        else:
            out.append(_marker(t_ns, "goals", i, ARROW, action=DELETE, text=rid))
    return _array(out)


def boundary_markers(t_ns: int, groups: list[dict], previous: int = 0):
    """A closed line strip per park group (namespace ``boundary``); ``text`` holds the
    group's robots and method as JSON. Groups gone since the last message (``previous``
    of them) are deleted."""
    out = []
    for k, g in enumerate(groups):
        ring = list(g["boundary"]) + [g["boundary"][0]]
        text = json.dumps({"robots": g["robots"], "method": g["method"]})
        out.append(
            _marker(t_ns, "boundary", k, LINE_STRIP, scale=(LINE_WIDTH_M, 0, 0), rgba=BOUNDARY_RGBA, points=ring, text=text)
        )  # fmt: skip
    for k in range(len(groups), previous):
        out.append(_marker(t_ns, "boundary", k, LINE_STRIP, action=DELETE))
    return _array(out)


def world_markers(t_ns: int, walls: list, obstacles: list):
    """Walls (namespace ``walls``) and static obstacles (``obstacles``) as closed strips."""
    out = []
    for ns, rings in (("walls", walls), ("obstacles", obstacles)):
        for k, ring in enumerate(rings):
            pts = list(ring) + [ring[0]]
            out.append(
                _marker(
                    t_ns, ns, k, LINE_STRIP, scale=(LINE_WIDTH_M, 0, 0), rgba=WALL_RGBA, points=pts
                )
            )
    return _array(out)


def people_markers(t_ns: int, ids, xy: np.ndarray, radii: np.ndarray):
    """A cylinder per person (namespace ``people``, id = person index, ``text`` = its id)."""
    return _array(
        [
            _marker(
                t_ns, "people", k, CYLINDER,
                pose=(xy[k, 0], xy[k, 1], 0.0),
                scale=(2 * radii[k], 2 * radii[k], PERSON_HEIGHT_M),
                rgba=PERSON_RGBA, text=ids[k], z=0.5 * PERSON_HEIGHT_M,
            )
            for k in range(len(ids))
        ]
    )  # fmt: skip


def json_string(obj) -> object:
    """std_msgs/String holding ``obj`` as compact JSON."""
    return _t("std_msgs/msg/String")(data=json.dumps(obj, separators=(",", ":")))
