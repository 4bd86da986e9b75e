"""Pose-graph mapping benchmarks: optimization of a 500-keyframe graph with loop closures, and
the re-render of the occupancy grid from 500 keyframe scans after a loop closes (issue 20).

The route is laps around the 40 m x 30 m bench hangar (:mod:`swarmpark.apps.bench.sensing`),
a keyframe every 0.5 m; odometry edges carry noise and a heading bias, and every
keyframe within 1 m of one at least 30 keyframes older gets a loop-closure edge (the true
relative pose plus noise), as a mapping run that goes round a bay again would.
"""

from __future__ import annotations

import time

import numpy as np

from swarmpark.apps.bench import register, time_call


def _laps(n: int) -> np.ndarray:
    """``n`` poses 0.5 m apart on laps around the hangar (x 5-35 m, y 5-25 m), each lap
    0.5 m inside the last: a pass runs beside the one before it."""
    pts: list[list[float]] = []
    lap = 0
    while len(pts) < n:
        x0, y0, x1, y1 = 5.0 + 0.5 * lap, 5.0 + 0.5 * lap, 35.0 - 0.5 * lap, 25.0 - 0.5 * lap
        corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)]
        for (ax, ay), (bx, by) in zip(corners[:-1], corners[1:], strict=True):
            steps = int(round(np.hypot(bx - ax, by - ay) / 0.5))
            yaw = float(np.arctan2(by - ay, bx - ax))
            for s in range(steps):
                pts.append([ax + (bx - ax) * s / steps, ay + (by - ay) * s / steps, yaw])
        lap += 1
    return np.array(pts[:n])


def _graph(truth: np.ndarray, rng: np.random.Generator):
    from swarmpark.sense.mapping import compose, relative_pose
    from swarmpark.sense.posegraph import PoseGraph

    g = PoseGraph()
    est = truth[0].copy()
    g.add_node(est)
    for k in range(1, len(truth)):
        z = relative_pose(truth[k - 1], truth[k]) + rng.normal(0, [0.01, 0.01, 0.003])
        z[2] += 0.001  # a heading bias: the drift the loops remove
        est = compose(est, z)
        g.add_node(est)
        g.add_edge(k - 1, k, z)
    loops = 0
    for k in range(len(truth)):
        d = np.hypot(*(truth[: max(k - 30, 0), :2] - truth[k, :2]).T)
        for i in np.flatnonzero(d < 1.0)[:2]:
            z = relative_pose(truth[i], truth[k]) + rng.normal(0, [0.01, 0.01, 0.003])
            g.add_edge(int(i), k, z, loop=True)
            loops += 1
    return g, loops


@register(
    "sense.posegraph",
    "pose-graph optimization (Levenberg-Marquardt, sparse direct solve) and map re-render",
    target="optimization < 1 s at 500 keyframes; re-render < 5 s",
)
def bench_posegraph(quick: bool) -> list[dict]:
    from swarmpark.apps.bench.sensing import _hangar
    from swarmpark.sense.lidar import LidarSpec, prepare_grid, scan
    from swarmpark.sense.mapping import GridMapper
    from swarmpark.sense.slam import PoseGraphMapper

    rows = []
    for n in (300, 500) if not quick else (500,):
        truth = _laps(n)
        rng = np.random.default_rng(7)
        g, loops = _graph(truth, rng)
        drift = float(np.hypot(*(g.poses[:, :2] - truth[:, :2]).T).max())
        t0 = time.perf_counter()
        report = g.optimize()
        ms = (time.perf_counter() - t0) * 1e3
        err = float(np.hypot(*(g.poses[:, :2] - truth[:, :2]).T).max())
        rows.append(
            {
                "case": f"optimize {n} keyframes, {loops} loop edges",
                "mean_ms": ms,
                "median_ms": ms,
                "max_ms": ms,
                "evaluations": report["iterations"],
                "error_before_m": drift,
                "error_after_m": err,
                "meets_target": bool(ms < 1000.0),
            }
        )
    # Re-render: every keyframe's 1000-beam scan inserted again at its pose.
    grid = _hangar()
    spec = LidarSpec(range_noise_std_m=0.01)
    truth = _laps(500)
    ranges = scan(spec, truth, prepare_grid(grid), rng=np.random.default_rng(8))
    m = PoseGraphMapper(GridMapper.like(grid, spec=spec))
    for pose, r in zip(truth, ranges, strict=True):
        m.graph.add_node(pose)
        m.ranges.append(r)
    stats = time_call(m.rerender, repeat=1 if quick else 3, warmup=0)
    rows.append(
        {
            "case": "re-render 500 keyframes (40 x 30 m at 5 cm)",
            **stats,
            "meets_target": bool(stats["median_ms"] < 5000.0),
        }
    )
    return rows
