"""Build a map with one skid's LIDAR while a scenario runs (2018 paper Sect. 3.5.2).

The chosen skid's scans and drifting odometry go into a log-odds grid mapper with scan
matching; the map is saved as ROS map_server YAML + PGM and compared with the ground truth.
The map frame is the skid's starting pose as odometry reports it, which is where the world
frame has it: other skids that later localize in this map share that frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from swarmpark.core.geometry import pad_polygons, triangulate
from swarmpark.core.gridmap import save_map_yaml
from swarmpark.sense.agreement import map_agreement
from swarmpark.sense.lidar import LidarSpec, prepare_grid, scan
from swarmpark.sense.mapping import GridMapper
from swarmpark.sim.odometry import OdometryDrift
from swarmpark.supervisor.core import Supervisor
from swarmpark.world.scenario import World

__all__ = ["build_map"]


def build_map(world: World, robot: str, out: str | Path, *, progress=None) -> dict:
    """Run ``world`` while ``robot`` maps it; save the map to ``out`` and return a summary."""
    sup = Supervisor(world)
    if robot not in sup.index:
        raise ValueError(f"map --robot: unknown robot {robot!r} (have {', '.join(sup.ids)})")
    i = sup.index[robot]
    cfg = world.scenario.sensing
    spec = LidarSpec(
        num_beams=cfg.lidar_beams,
        max_range_m=cfg.lidar_range_m,
        range_noise_std_m=cfg.range_noise_std_m,
        dropout_prob=cfg.dropout_prob,
    )
    field = prepare_grid(world.grid)
    tris = [t for poly in world.static_obstacles for t in triangulate(poly)]
    obstacle_tris = pad_polygons(tris, 4) if tris else np.zeros((0, 4, 2))
    seed = np.random.SeedSequence(world.scenario.seed).spawn(3)[2]
    scan_rng, odom_rng = (np.random.default_rng(s) for s in seed.spawn(2))
    odometry = OdometryDrift(sup.sim.poses[i : i + 1], rng=odom_rng)
    mapper = GridMapper.like(world.grid, spec=spec)
    n_ticks = int(round(world.scenario.duration_s / world.scenario.dt_s))
    drift, corrected = [], []
    for _ in range(n_ticks):
        sup.tick()
        sim = sup.sim
        polys = np.concatenate([sim.corners(), obstacle_tris])
        owner = np.concatenate([np.arange(sim.n), np.full(len(obstacle_tris), -1)])
        ranges = scan(
            spec,
            sim.poses[i : i + 1],
            field,
            polygons=polys,
            polygon_owner=np.where(owner == i, 0, -1),
            discs=sim.person_positions(),
            disc_radii=sim.person_radius,
            rng=scan_rng,
        )
        odom = odometry.step(sim.poses[i : i + 1])[0]
        mapper.update(odom, ranges[0])
        drift.append(np.hypot(*(odom[:2] - sim.poses[i, :2])))
        corrected.append(np.hypot(*(mapper.pose[:2] - sim.poses[i, :2])))
        if progress is not None:
            progress(sim.t, world.scenario.duration_s)
        if sup.settled():
            break
    built = mapper.to_occupancy_grid()
    path = save_map_yaml(built, out)
    agree = map_agreement(built, world.grid, tolerance_cells=1)
    return {
        "robot": robot,
        "map": str(path),
        "scans": len(drift),
        "keyframes": mapper.scans,
        "sim_time_s": round(sup.t, 3),
        "odometry_drift_final_m": round(float(drift[-1]), 4) if drift else None,
        "slam_error_final_m": round(float(corrected[-1]), 4) if corrected else None,
        "slam_error_max_m": round(float(max(corrected)), 4) if corrected else None,
        "map_agreement": {k: round(float(v), 4) for k, v in agree.items()},
    }
