"""A fake ROS 2 fleet: N simulated skids behind real rclpy, for tests and demos.

Run it as a separate process::

    python -m swarmpark.links.fake_fleet --scenario scenarios/x.yaml --robots 6

Each skid ``<id>`` (the scenario's robots, at their start poses) is driven in real time with
swarmpark's kinematics (:func:`~swarmpark.core.geometry.integrate_unicycle`, the scenario's
speed and acceleration limits) and LIDAR (:func:`~swarmpark.sense.lidar.scan`). Like a real
robot base it

- subscribes ``/<id>/cmd_vel`` (``geometry_msgs/Twist``, reliable),
- publishes ``/<id>/odom`` (``nav_msgs/Odometry``, frame ``<id>/odom`` whose origin is the
  start pose, child ``<id>/base_link``) every period and ``/<id>/scan``
  (``sensor_msgs/LaserScan``, sensor-data QoS) at ``--scan-hz``,
- stops by itself when no ``cmd_vel`` arrived for ``--deadman`` seconds (the robot-side
  dead-man: a dead supervisor or a broken link leaves no robot driving), and
- stops every skid while ``/swarmpark/estop`` (``std_msgs/Bool``, reliable, transient
  local: a late joiner hears the last value) is true, whoever published it.

``--drop ROBOT:FROM:TO`` loses every message to and from one skid in a window (seconds
after the first ``cmd_vel`` of the run). The fleet knows the truth: it reports collisions
between skids, with static obstacles and with the map's walls, and its events (first
command, dead-man stops, e-stops, drops; wall-clock times) as JSON in ``--report``.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["main", "FakeFleet", "STOP_DECEL_FACTOR"]

#: Braking on a dead-man or e-stop stop, as a multiple of the skid's acceleration limits.
STOP_DECEL_FACTOR = 3.0


class FakeFleet:
    """The skids' state and the rclpy node that carries their topics."""

    def __init__(self, world, n: int, args) -> None:
        import rclpy
        from geometry_msgs.msg import Twist
        from nav_msgs.msg import Odometry
        from rclpy.qos import (
            DurabilityPolicy,
            QoSProfile,
            ReliabilityPolicy,
            qos_profile_sensor_data,
        )
        from sensor_msgs.msg import LaserScan
        from std_msgs.msg import Bool

        from swarmpark.core.geometry import body_corners
        from swarmpark.sense.lidar import LidarSpec, beam_angles, prepare_grid

        self.world, self.args = world, args
        robots = world.robots[:n]
        self.ids = [r.id for r in robots]
        self.start = np.stack([r.start for r in robots]).astype(float)
        self.poses = self.start.copy()
        self.vel = np.zeros((n, 2))
        self.cmd = np.zeros((n, 2))
        self.cmd_t = np.full(n, -math.inf)
        self.vmax = np.array([r.max_speed_mps for r in robots])
        self.wmax = np.array([r.max_yaw_rate_radps for r in robots])
        self.acc = np.stack([[r.max_accel_mps2, r.max_yaw_accel_radps2] for r in robots])
        self.corners_body = body_corners([r.footprint for r in robots])
        cfg = world.scenario.sensing
        self.lidar = LidarSpec(num_beams=cfg.lidar_beams, max_range_m=cfg.lidar_range_m)
        self.angles = beam_angles(self.lidar)
        self.field = prepare_grid(world.grid)
        self.drops = [_parse_drop(d, self.ids) for d in args.drop]
        self.t_first_cmd: float | None = None
        self.estop = False
        self.events: list[dict] = []
        self.collisions: set[tuple[str, str]] = set()
        self._driving = np.zeros(n, dtype=bool)
        self._dropping = np.zeros(n, dtype=bool)
        self._moving = np.zeros(n, dtype=bool)
        self.callbacks = 0
        self.Odometry, self.LaserScan = Odometry, LaserScan

        rclpy.init()
        self.node = rclpy.create_node("swarmpark_fake_fleet")
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        self.odom_pub = [self.node.create_publisher(Odometry, f"/{r}/odom", 10) for r in self.ids]
        self.scan_pub = [
            self.node.create_publisher(LaserScan, f"/{r}/scan", qos_profile_sensor_data)
            for r in self.ids
        ]
        for i, rid in enumerate(self.ids):
            self.node.create_subscription(
                Twist, f"/{rid}/cmd_vel", lambda m, i=i: self._on_cmd(i, m), 10
            )
        self.node.create_subscription(Bool, "/swarmpark/estop", self._on_estop, latched)

    # ------------------------------------------------------------------ inputs

    def _event(self, kind: str, robot: str | None = None, **extra) -> None:
        self.events.append({"t": time.time(), "kind": kind, "robot": robot, **extra})

    def _run_time(self) -> float:
        return -math.inf if self.t_first_cmd is None else time.time() - self.t_first_cmd

    def _dropped(self, i: int) -> bool:
        t = self._run_time()
        return any(j == i and t0 <= t < t1 for j, t0, t1 in self.drops)

    def _on_cmd(self, i: int, m) -> None:
        self.callbacks += 1
        if self.t_first_cmd is None:
            self.t_first_cmd = time.time()
            self._event("first_cmd", self.ids[i])
        if self._dropped(i):
            return  # lost on the way
        self.cmd[i] = (m.linear.x, m.angular.z)
        self.cmd_t[i] = time.monotonic()

    def _on_estop(self, m) -> None:
        self.callbacks += 1
        if bool(m.data) != self.estop:
            self.estop = bool(m.data)
            self._event("estop" if self.estop else "estop_released")

    # ------------------------------------------------------------------ one period

    def step(self, dt: float) -> None:
        from swarmpark.core.geometry import integrate_unicycle

        n = len(self.ids)
        fresh = time.monotonic() - self.cmd_t <= self.args.deadman
        for i in range(n):
            dropping = self._dropped(i)
            if dropping != self._dropping[i]:
                self._event("drop_start" if dropping else "drop_end", self.ids[i])
                self._dropping[i] = dropping
            driving = bool(fresh[i] and np.any(self.cmd[i] != 0))
            if self._driving[i] and not fresh[i]:
                self._event("deadman", self.ids[i])
            self._driving[i] = driving
        go = fresh & (not self.estop)
        lim = np.stack([self.vmax, self.wmax], 1)
        target = np.clip(np.where(go[:, None], self.cmd, 0.0), -lim, lim)
        # A dead-man or e-stop stop brakes at STOP_DECEL_FACTOR times the normal limits.
        acc = self.acc * np.where(go, 1.0, STOP_DECEL_FACTOR)[:, None]
        self.vel += np.clip(target - self.vel, -acc * dt, acc * dt)
        for i in np.flatnonzero(~go & self._moving & np.all(self.vel == 0, 1)):
            self._event("standstill", self.ids[i])
        self._moving = np.any(self.vel != 0, 1)
        self.poses = integrate_unicycle(self.poses, self.vel[:, 0], self.vel[:, 1], dt)
        self._check_collisions()

    def _check_collisions(self) -> None:
        from shapely.geometry import Polygon

        from swarmpark.core.geometry import footprint_corners

        corners = footprint_corners(self.poses, self.corners_body)
        # Broad phase: only skids whose corner boxes overlap can touch.
        lo, hi = corners.min(1), corners.max(1)
        near = np.all((lo[:, None] <= hi[None]) & (lo[None] <= hi[:, None]), axis=2)
        polys = [Polygon(c) for c in corners]
        for a, b in zip(*np.nonzero(np.triu(near, 1)), strict=True):
            if polys[a].intersection(polys[b]).area > 1e-6:
                self._collide(self.ids[a], self.ids[b])
        for k, ob in enumerate(self.world.static_obstacles):
            x0, y0, x1, y1 = ob.bounds
            cand = (hi[:, 0] >= x0) & (lo[:, 0] <= x1) & (hi[:, 1] >= y0) & (lo[:, 1] <= y1)
            for a in np.flatnonzero(cand):
                if polys[a].intersection(ob).area > 1e-6:
                    self._collide(self.ids[a], f"obstacle{k}")
        walls = self.world.grid.is_occupied(corners.reshape(-1, 2)).reshape(len(corners), 4)
        for a in np.flatnonzero(walls.any(1)):
            self._collide(self.ids[a], "wall")

    def _collide(self, a: str, b: str) -> None:
        if (a, b) not in self.collisions:
            self.collisions.add((a, b))
            self._event("collision", a, other=b)

    def publish(self, scan: bool) -> None:
        from swarmpark.links.ros2_msgs import compose, inverse
        from swarmpark.sense.lidar import scan as lidar_scan

        stamp = self.node.get_clock().now().to_msg()
        ranges = None
        if scan:
            ranges = lidar_scan(
                self.lidar,
                self.poses,
                self.field,
                polygons=footprint_polygons(self.poses, self.corners_body),
                polygon_owner=np.arange(len(self.ids)),
            )
        for i, rid in enumerate(self.ids):
            if self._dropped(i):
                continue
            o = self.Odometry()
            o.header.stamp, o.header.frame_id = stamp, f"{rid}/odom"
            o.child_frame_id = f"{rid}/base_link"
            x, y, yaw = compose(inverse(self.start[i]), self.poses[i])
            o.pose.pose.position.x, o.pose.pose.position.y = float(x), float(y)
            o.pose.pose.orientation.z, o.pose.pose.orientation.w = (
                math.sin(yaw / 2),
                math.cos(yaw / 2),
            )
            o.twist.twist.linear.x, o.twist.twist.angular.z = (float(v) for v in self.vel[i])
            self.odom_pub[i].publish(o)
            if ranges is not None:
                s = self.LaserScan()
                s.header.stamp, s.header.frame_id = stamp, f"{rid}/base_scan"
                s.angle_min, s.angle_max = float(self.angles[0]), float(self.angles[-1])
                s.angle_increment = float(self.angles[1] - self.angles[0])
                s.range_min, s.range_max = 0.0, float(self.lidar.max_range_m)
                s.ranges = [float(r) if np.isfinite(r) else math.inf for r in ranges[i]]
                self.scan_pub[i].publish(s)

    def report(self) -> dict:
        return {
            "robots": self.ids,
            "poses": self.poses.round(4).tolist(),
            "collisions": [{"a": a, "b": b} for a, b in sorted(self.collisions)],
            "events": self.events,
        }

    def close(self) -> None:
        import rclpy

        try:
            self.node.destroy_node()
        finally:
            if rclpy.ok():
                rclpy.shutdown()


def footprint_polygons(poses: np.ndarray, corners_body: np.ndarray) -> np.ndarray:
    """World corners ``(N, 4, 2)`` of the skids (what their neighbours' LIDARs see)."""
    from swarmpark.core.geometry import footprint_corners

    return footprint_corners(poses, corners_body)


def _parse_drop(text: str, ids: list[str]) -> tuple[int, float, float]:
    try:
        rid, t0, t1 = text.split(":")
        t0, t1 = float(t0), float(t1)
    except ValueError:
        raise SystemExit(f"fake_fleet: --drop must be ROBOT:FROM:TO (got {text!r})") from None
    if rid not in ids:
        raise SystemExit(f"fake_fleet: --drop: unknown robot {rid!r} (have {ids})")
    if not t1 > t0 >= 0:
        raise SystemExit(f"fake_fleet: --drop: need 0 <= FROM < TO (got {text!r})")
    return ids.index(rid), t0, t1


def _args(argv):
    p = argparse.ArgumentParser(
        prog="python -m swarmpark.links.fake_fleet", description=__doc__.split("\n")[0]
    )
    p.add_argument("--scenario", required=True, help="scenario YAML (map, robots, limits)")
    p.add_argument("--robots", type=int, default=None, help="use the first N robots (default all)")
    p.add_argument("--rate", type=float, default=25.0, help="integration and odometry rate (Hz)")
    p.add_argument("--scan-hz", type=float, default=5.0, help="LIDAR rate (Hz, 0: none)")
    p.add_argument(
        "--deadman", type=float, default=0.5, help="stop after this long without cmd_vel (s)"
    )
    p.add_argument("--drop", action="append", default=[], metavar="ROBOT:FROM:TO")
    p.add_argument("--report", metavar="FILE", help="write collisions and events as JSON")
    p.add_argument("--duration", type=float, default=None, help="exit after this long (s)")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    import rclpy

    from swarmpark.world.scenario import ScenarioError, build_world, load_scenario

    args = _args(argv)
    try:
        world = build_world(load_scenario(args.scenario))
    except ScenarioError as exc:
        sys.stderr.write(f"fake_fleet: {args.scenario}: {exc}\n")
        return 2
    n = len(world.robots) if args.robots is None else args.robots
    if not 1 <= n <= len(world.robots):
        sys.stderr.write(f"fake_fleet: --robots must be 1..{len(world.robots)} (got {n})\n")
        return 2
    if args.rate <= 0 or args.deadman <= 0:
        sys.stderr.write("fake_fleet: --rate and --deadman must be > 0\n")
        return 2
    stop = {"now": False}
    signal.signal(signal.SIGTERM, lambda *_: stop.update(now=True))
    fleet = FakeFleet(world, n, args)
    period = 1.0 / args.rate
    scan_every = max(1, round(args.rate / args.scan_hz)) if args.scan_hz > 0 else 0
    t_end = None if args.duration is None else time.monotonic() + args.duration
    last = time.monotonic()
    next_tick, k, next_report = last + period, 0, last + 1.0
    try:
        while not stop["now"] and rclpy.ok() and (t_end is None or time.monotonic() < t_end):
            rclpy.spin_once(fleet.node, timeout_sec=max(0.0, next_tick - time.monotonic()))
            now = time.monotonic()
            if now < next_tick:
                continue
            # Behind schedule spin_once would take one message per period: drain the queue
            # (until a call runs no callback; an empty wait costs as much as a full one).
            for _ in range(4 * n + 4):
                before = fleet.callbacks
                rclpy.spin_once(fleet.node, timeout_sec=0.0)
                if fleet.callbacks == before:
                    break
            fleet.step(min(now - last, 5 * period))  # a stalled process does not teleport
            last, k = now, k + 1
            next_tick = max(next_tick + period, now)
            fleet.publish(scan=bool(scan_every) and k % scan_every == 0)
            if args.report and now >= next_report:
                Path(args.report).write_text(json.dumps(fleet.report()))
                next_report = now + 1.0
    except KeyboardInterrupt:
        pass
    finally:
        if args.report:
            Path(args.report).write_text(json.dumps(fleet.report()))
        fleet.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
