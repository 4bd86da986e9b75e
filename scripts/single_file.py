"""A single file of skids driven straight at a door: how fast a line crosses it and parks
(docs/navigation.md, "Tried and left out (2026-12-05, session 31)").

    python scripts/single_file.py SCENARIO.yaml [--skids 8] [--gap 0.4] [--door X Y]
                                                [--heading DEG]

The scenario's map and first park command are kept; its skids are replaced by ``--skids``
skids of its default footprint in a line that ends 1 m before the door, heading
``--heading`` (degrees, the way through the door; default 0, east, as on generated door and
elevator sites), ``--gap`` metres nose to tail. The door is ``--door`` or else the centre of
the map's first bottleneck zone (:mod:`swarmpark.control.nav.traffic`). Prints when each
skid crosses the line through the door (across the heading), the intervals, and when each
parked.
"""

from __future__ import annotations

import argparse
import copy
import sys
from pathlib import Path

import numpy as np
import yaml

from swarmpark.apps.run import run_world
from swarmpark.control.nav.params import TrafficParams
from swarmpark.control.nav.traffic import zones_for
from swarmpark.world.scenario import build_world, parse_scenario


def door_centre(data: dict, base: Path) -> np.ndarray:
    """Centre of the first bottleneck zone of the scenario's map, as the navigator finds it."""
    world = build_world(parse_scenario(data, base))
    zones = zones_for(world.grid, [r.footprint for r in world.robots], TrafficParams())
    if zones.count == 0:
        raise SystemExit("single_file: the map has no door or narrow corridor; give --door X Y")
    c = zones.polygons[0].centroid
    return np.array([c.x, c.y])


def line_scenario(
    data: dict, door: np.ndarray, heading_rad: float, skids: int, gap_m: float
) -> dict:
    """``data`` with its skids replaced by a line of ``skids`` ending 1 m before ``door``."""
    fp = data["robot_defaults"]["footprint"]
    length, rear = fp["length_m"], fp.get("pivot_from_rear_m", 0.5 * fp["length_m"])
    u = np.array([np.cos(heading_rad), np.sin(heading_rad)])
    front = door - u * (1.0 + length - rear)  # the first pivot: its nose 1 m before the door
    out = copy.deepcopy(data)
    robots = []
    for k in range(skids):
        x, y = front - u * k * (length + gap_m)
        robots.append(
            {"id": f"f{k + 1}", "pose": [float(x), float(y), float(np.degrees(heading_rad))]}
        )
    out["robots"] = robots
    park = next(c for c in out["commands"] if "park" in c)
    park["park"]["robots"] = [r["id"] for r in robots]
    out["commands"] = [park]
    out["name"] = f"{data.get('name', 'scenario')}-single-file-{skids}"
    return out


def crossings(poses: np.ndarray, times: np.ndarray, door, heading_rad: float) -> np.ndarray:
    """First time each skid's pivot passes the line through ``door`` across the heading
    (NaN: never), from trajectories ``poses`` ``(T, N, 3)``."""
    u = np.array([np.cos(heading_rad), np.sin(heading_rad)])
    along = (poses[:, :, :2] - np.asarray(door)) @ u  # (T, N)
    out = np.full(poses.shape[1], np.nan)
    for i in range(poses.shape[1]):
        k = np.flatnonzero((along[:-1, i] < 0.0) & (along[1:, i] >= 0.0))
        if len(k):
            out[i] = times[k[0] + 1]
    return out


def run(path: Path, skids: int, gap_m: float, door=None, heading_deg: float = 0.0):
    """Run the single file; returns (result, crossing times per skid in line order)."""
    data = yaml.safe_load(path.read_text())
    heading = np.radians(heading_deg)
    door = door_centre(data, path.parent) if door is None else np.asarray(door, float)
    out = run_world(
        build_world(parse_scenario(line_scenario(data, door, heading, skids, gap_m), path.parent))
    )
    return out.result, crossings(out.poses, out.times, door, heading)


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario", type=Path)
    ap.add_argument("--skids", type=int, default=8)
    ap.add_argument("--gap", type=float, default=0.4, help="nose to tail, metres")
    ap.add_argument("--door", type=float, nargs=2, metavar=("X", "Y"))
    ap.add_argument("--heading", type=float, default=0.0, help="degrees")
    a = ap.parse_args(argv)
    if not a.scenario.is_file():
        ap.error(f"scenario: no such file ({a.scenario})")
    if a.skids < 1 or a.gap < 0:
        ap.error(f"--skids must be at least 1 and --gap at least 0 (got {a.skids}, {a.gap})")
    result, cross = run(a.scenario, a.skids, a.gap, a.door, a.heading)
    parked = [r["parked_at_s"] for r in result["robots"].values()]
    print("skid | crosses (s) | parked (s)")
    for k, (c, p) in enumerate(zip(cross, parked, strict=True)):
        print(f"f{k + 1} | {c:.1f} | {p if p is None else f'{p:.1f}'}")
    print(f"crossing intervals (s): {np.round(np.diff(cross), 1).tolist()}")
    print(f"time to park: {result['time_to_park_s']} s, lower bound {result['lower_bound_s']} s")


if __name__ == "__main__":
    main(sys.argv[1:])
