"""swarmpark's ROS 2 messages: CDR bytes equal rclpy's for the same content, conversions
round-trip, and the DDS types built for Cyclone serialize to the same bytes."""

import math

import numpy as np
import pytest

pytest.importorskip("rosbags")

from helpers import DATA  # noqa: E402

from swarmpark.links import ros2_msgs as rm  # noqa: E402

POSE = (1.25, -2.5, 0.7)
VEL = (0.4, -0.3)


_SIZE = {"bool": 1, "byte": 1, "char": 1, "int8": 1, "uint8": 1, "int16": 2, "uint16": 2}
_SIZE |= {"int32": 4, "uint32": 4, "float32": 4, "int64": 8, "uint64": 8, "float64": 8}


def _padding(typename: str, data: bytes) -> list[int]:
    """Offsets of the alignment padding in CDR ``data`` of ``typename`` (Fast CDR leaves
    padding bytes uninitialized, so they are masked before comparing)."""
    pad: list[int] = []
    pos = 4  # after the encapsulation header; alignment is relative to this

    def align(n):
        nonlocal pos
        while (pos - 4) % n:
            pad.append(pos)
            pos += 1

    def u32():
        nonlocal pos
        align(4)
        v = int.from_bytes(data[pos : pos + 4], "little")
        pos += 4
        return v

    def field(node):
        nonlocal pos
        kind, rest = int(node[0]), node[1]
        if kind == 1:
            if rest[0] == "string":
                n = u32()  # (read before moving pos: u32 moves it)
                pos += n
            else:
                align(_SIZE[rest[0]])
                pos += _SIZE[rest[0]]
        elif kind == 2:
            struct(rest)
        elif kind == 3:
            for _ in range(rest[1]):
                field(rest[0])
        elif kind == 4:
            for _ in range(u32()):
                field(rest[0])

    def struct(name):
        for _, node in rm.TYPESTORE.fielddefs[name][1]:
            field(node)

    struct(typename)
    assert pos == len(data), (pos, len(data))
    return pad


def _same_cdr(ours: bytes, theirs: bytes, typename: str) -> None:
    assert len(ours) == len(theirs)
    theirs = bytearray(theirs)
    for i in _padding(typename, ours):
        assert ours[i] == 0
        theirs[i] = 0
    assert ours == bytes(theirs)


def _rclpy_bytes(msg) -> bytes:
    serialization = pytest.importorskip("rclpy.serialization")
    return bytes(serialization.serialize_message(msg))


def _pad(b: bytes) -> bytes:
    return b.ljust((len(b) + 3) & ~3, b"\0")


def _set_header(h, t, frame):
    h.stamp.sec, h.stamp.nanosec = int(math.floor(t)), round((t - math.floor(t)) * 1e9)
    h.frame_id = frame


def test_twist_bytes_equal_rclpy():
    Twist = pytest.importorskip("geometry_msgs.msg").Twist
    m = Twist()
    m.linear.x, m.angular.z = 0.35, -0.8
    T = "geometry_msgs/msg/Twist"
    _same_cdr(rm.serialize(rm.twist(0.35, -0.8), T), _rclpy_bytes(m), T)
    assert rm.twist_cdr(0.35, -0.8) == rm.serialize(rm.twist(0.35, -0.8), T)  # the fast path


def test_odometry_bytes_equal_rclpy():
    Odometry = pytest.importorskip("nav_msgs.msg").Odometry
    t = 1_700_000_000.125
    m = Odometry()
    _set_header(m.header, t, "s1/odom")
    m.child_frame_id = "s1/base_link"
    m.pose.pose.position.x, m.pose.pose.position.y = POSE[0], POSE[1]
    m.pose.pose.orientation.z = math.sin(POSE[2] / 2)
    m.pose.pose.orientation.w = math.cos(POSE[2] / 2)
    m.twist.twist.linear.x, m.twist.twist.angular.z = VEL
    ours = rm.odometry(t, "s1/odom", "s1/base_link", POSE, VEL)
    _same_cdr(rm.serialize(ours, "nav_msgs/msg/Odometry"), _rclpy_bytes(m), "nav_msgs/msg/Odometry")


def test_laser_scan_bytes_equal_rclpy_and_no_return_is_inf():
    LaserScan = pytest.importorskip("sensor_msgs.msg").LaserScan
    t = 12.5
    angles = np.linspace(-np.pi, np.pi, 8, endpoint=False)
    ranges = np.array([1.0, 2.5, np.nan, 3.25, 0.5, np.nan, 7.0, 1.5])
    m = LaserScan()
    _set_header(m.header, t, "s1/base_scan")
    m.angle_min, m.angle_max = float(angles[0]), float(angles[-1])
    m.angle_increment = float(angles[1] - angles[0])
    m.range_min, m.range_max = 0.0, 8.0
    m.ranges = [float(r) if np.isfinite(r) else math.inf for r in ranges]
    ours = rm.laser_scan(t, "s1/base_scan", angles, ranges, 8.0)
    T = "sensor_msgs/msg/LaserScan"
    _same_cdr(rm.serialize(ours, T), _rclpy_bytes(m), T)
    back = rm.scan_ranges(
        rm.deserialize(rm.serialize(ours, "sensor_msgs/msg/LaserScan"), "sensor_msgs/msg/LaserScan")
    )
    np.testing.assert_allclose(back, ranges.astype(np.float32))


def test_occupancy_grid_bytes_equal_rclpy():
    OccupancyGrid = pytest.importorskip("nav_msgs.msg").OccupancyGrid
    occ = np.zeros((3, 5), bool)
    occ[0, :] = True
    occ[2, 4] = True
    t = 3.0
    m = OccupancyGrid()
    _set_header(m.header, t, "map")
    m.info.map_load_time.sec = 3
    m.info.resolution = 0.05
    m.info.width, m.info.height = 5, 3
    m.info.origin.position.x, m.info.origin.position.y = -1.0, 2.0
    m.info.origin.orientation.w = 1.0
    m.data = [100 if v else 0 for v in occ.ravel()]
    ours = rm.occupancy_grid(t, "map", occ, 0.05, (-1.0, 2.0))
    T = "nav_msgs/msg/OccupancyGrid"
    _same_cdr(rm.serialize(ours, T), _rclpy_bytes(m), T)


def test_tf_message_bytes_equal_an_independent_serializer():
    """There is no tf2_msgs wheel for rclpy: TFMessage is checked against Cyclone's own CDR
    serializer on the DDS type swarmpark builds (a second implementation), and its
    TransformStamped against rclpy."""
    pytest.importorskip("cyclonedds")
    TransformStamped = pytest.importorskip("geometry_msgs.msg").TransformStamped
    t = 5.5
    tfs = [rm.transform(t, "map", "s1/odom", POSE), rm.transform(t, "map", "s2/odom", (3, 4, -1))]
    ours = rm.serialize(rm.tf_message(tfs), "tf2_msgs/msg/TFMessage")

    T = rm.dds_type
    tr = [
        T("geometry_msgs/msg/TransformStamped")(
            header=T("std_msgs/msg/Header")(
                stamp=T("builtin_interfaces/msg/Time")(sec=5, nanosec=500_000_000),
                frame_id="map",
            ),
            child_frame_id=child,
            transform=T("geometry_msgs/msg/Transform")(
                translation=T("geometry_msgs/msg/Vector3")(x=float(x), y=float(y), z=0.0),
                rotation=T("geometry_msgs/msg/Quaternion")(
                    x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
                ),
            ),
        )
        for child, (x, y, yaw) in (("s1/odom", POSE), ("s2/odom", (3, 4, -1)))
    ]
    theirs = T("tf2_msgs/msg/TFMessage")(transforms=tr).serialize(use_version_2=False)
    _same_cdr(ours, bytes(theirs)[: len(ours)], "tf2_msgs/msg/TFMessage")

    m = TransformStamped()
    _set_header(m.header, t, "map")
    m.child_frame_id = "s1/odom"
    m.transform.translation.x, m.transform.translation.y = POSE[0], POSE[1]
    m.transform.rotation.z, m.transform.rotation.w = math.sin(POSE[2] / 2), math.cos(POSE[2] / 2)
    T = "geometry_msgs/msg/TransformStamped"
    _same_cdr(rm.serialize(tfs[0], T), _rclpy_bytes(m), T)


def test_dds_type_names_follow_rmw():
    assert rm.dds_name("nav_msgs/msg/Odometry") == "nav_msgs::msg::dds_::Odometry_"
    pytest.importorskip("cyclonedds")
    assert rm.dds_type("geometry_msgs/msg/Twist").__idl_typename__ == (
        "geometry_msgs::msg::dds_::Twist_"
    )


def test_pose_composition_round_trips():
    a, b = np.array([1.0, 2.0, 0.5]), np.array([-0.3, 0.8, 2.9])
    np.testing.assert_allclose(rm.compose(a, rm.inverse(a)), 0, atol=1e-12)
    c = rm.compose(a, b)
    np.testing.assert_allclose(rm.compose(rm.inverse(a), c), b, atol=1e-12)
    assert rm.yaw_of(rm.quaternion(2.9)) == pytest.approx(2.9)


def test_unknown_type_is_refused_by_name():
    with pytest.raises(ValueError, match="no_msgs/msg/Nope"):
        rm.msg("no_msgs/msg/Nope")


def _world():
    from swarmpark.world.scenario import build_world, load_scenario

    return build_world(load_scenario(DATA / "ros2-open.yaml"))


def test_odometry_is_placed_in_the_map_from_the_start_pose():
    """No DDS: the link's conversion of a robot's odometry (its odom frame starts wherever
    the base booted) into the map pose the supervisor decides from."""
    from swarmpark.links.base import Odometry, PoseReport
    from swarmpark.links.ros2 import Ros2Link

    world = _world()
    link = Ros2Link(world)
    link._start = np.stack([r.start for r in world.robots])
    link.t0 = 100.0
    odom0 = (5.0, -1.0, 1.0)  # the first report: the robot stands at its start pose
    m = rm.odometry(101.5, "s2/odom", "s2/base_link", odom0, (0.0, 0.0))
    first = link._from_odom(1, "s2", m)
    assert isinstance(first[0], Odometry) and first[0].stamp == pytest.approx(1.5)
    assert isinstance(first[1], PoseReport)
    np.testing.assert_allclose(first[1].pose, world.robots[1].start, atol=1e-12)
    # 1 m forward in the odom frame (heading 1 rad there) is 1 m along the start heading.
    ahead = rm.compose(odom0, (1.0, 0.0, 0.0))
    m = rm.odometry(102.0, "s2/odom", "s2/base_link", ahead, (0.5, 0.0))
    later = link._from_odom(1, "s2", m)
    x, y, yaw = world.robots[1].start
    np.testing.assert_allclose(later[1].pose, (x + np.cos(yaw), y + np.sin(yaw), yaw), atol=1e-9)
    np.testing.assert_allclose(later[0].vel, (0.5, 0.0))


def test_link_options_are_checked_by_name():
    import argparse

    from swarmpark.links.ros2 import link_from_args

    args = argparse.Namespace(
        link="ros2", domain_id=500, loopback=True, cmd_stamped=False, amcl_pose=False
    )
    with pytest.raises(ValueError, match="--domain-id must be 0..232 \\(got 500\\)"):
        link_from_args(_world(), args)
    assert link_from_args(_world(), argparse.Namespace(link="sim")) is None


def test_duplicated_and_reordered_ros_messages_are_ignored_by_stamp():
    from swarmpark.links.base import Inbox
    from swarmpark.links.ros2 import Ros2Link

    world = _world()
    link = Ros2Link(world)
    link._start = np.stack([r.start for r in world.robots])
    inbox = Inbox(tuple(world.ids))
    new = rm.odometry(2.0, "s1/odom", "s1/base_link", (1.0, 0, 0), (0.2, 0))
    old = rm.odometry(1.0, "s1/odom", "s1/base_link", (0.5, 0, 0), (0.1, 0))
    for m in (new, new, old):  # a duplicate, then a late one
        inbox.absorb(link._from_odom(0, "s1", m))
    assert inbox.ignored == 4  # (odometry and the pose derived from it) x 2
    assert inbox.odom[0, 0] == 1.0 and inbox.odom_stamp[0] == 2.0


def test_markers_show_footprints_goals_boundary_and_paths():
    from swarmpark.links.ros2_viz import markers
    from swarmpark.supervisor.core import Supervisor

    sup = Supervisor(_world())
    for _ in range(3):
        sup.tick()
    arr = markers(sup, 10.0)
    data = rm.serialize(arr, "visualization_msgs/msg/MarkerArray")
    back = rm.deserialize(data, "visualization_msgs/msg/MarkerArray").markers
    ns = [m.ns for m in back]
    assert back[0].action == 3  # DELETEALL first
    assert ns.count("footprints") == 6 and ns.count("goals") == 6
    assert ns.count("boundary") == 1 and ns.count("paths") >= 1
    ring = np.array([(p.x, p.y) for p in back[ns.index("footprints")].points])
    assert len(ring) == 5 and np.allclose(ring[0], ring[-1])
