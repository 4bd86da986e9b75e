"""Pictures of runs: the map, footprints over time, goals, boundaries and people (matplotlib Agg)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402

from swarmpark.core.geometry import footprint_corners  # noqa: E402
from swarmpark.core.gridmap import OccupancyGrid  # noqa: E402

__all__ = ["plot_run", "draw_grid"]

#: Footprint snapshots drawn along each trajectory.
SNAPSHOTS = 12


def draw_grid(ax, grid: OccupancyGrid) -> None:
    """Occupied cells black, unknown grey, free white; world coordinates."""
    img = np.ones(grid.shape)
    img[grid.unknown] = 0.75
    img[grid.occupied] = 0.0
    xmin, ymin, xmax, ymax = grid.bounds
    ax.imshow(
        img,
        origin="lower",
        extent=(xmin, xmax, ymin, ymax),
        cmap="gray",
        vmin=0,
        vmax=1,
        interpolation="nearest",
    )


def plot_run(out, path: str | Path) -> Path:
    """Draw a finished run to ``path``."""
    sup = out.supervisor
    world = sup.world
    fig, ax = plt.subplots(
        figsize=(10, 10 * world.grid.size_m[1] / max(world.grid.size_m[0], 1e-9) + 0.8)
    )
    draw_grid(ax, world.grid)
    for poly in world.static_obstacles:
        x, y = poly.exterior.xy
        ax.fill(x, y, color="#8b5a2b", alpha=0.8, label="obstacle (not in map)")
    for g in sup.groups:
        x, y = g.boundary.exterior.xy
        ax.plot(x, y, "--", color="tab:blue", lw=1.5, label="parking boundary")
    n = sup.sim.n
    colors = plt.cm.tab20(np.linspace(0, 1, max(n, 2)))
    T = len(out.times)
    snaps = np.unique(np.linspace(0, T - 1, SNAPSHOTS).astype(int))
    cb = sup.sim.corners_body
    for k in snaps:
        corners = footprint_corners(out.poses[k], cb)
        alpha = 0.08 + 0.5 * k / max(T - 1, 1)
        ax.add_collection(
            PolyCollection(corners, facecolors=colors[:n], alpha=alpha, edgecolors="none")
        )
    for i in range(n):
        ax.plot(out.poses[:, i, 0], out.poses[:, i, 1], "-", color=colors[i], lw=1)
    final = footprint_corners(out.poses[-1], cb)
    ax.add_collection(
        PolyCollection(final, facecolors="none", edgecolors=colors[:n], linewidths=1.5)
    )
    for i, rid in enumerate(sup.ids):
        p = out.poses[-1, i]
        ax.annotate(rid, p[:2], fontsize=7, ha="center", va="center")
    if sup.has_goal.any():
        goal_c = footprint_corners(sup.goals[sup.has_goal], cb[sup.has_goal])
        ax.add_collection(
            PolyCollection(
                goal_c, facecolors="none", edgecolors="k", linestyles=":", linewidths=1.0
            )
        )
    if out.people.shape[1]:
        for j, person in enumerate(sup.sim.people):
            ax.plot(out.people[:, j, 0], out.people[:, j, 1], ":", color="tab:red", lw=1.2)
            ax.add_patch(plt.Circle(out.people[-1, j], person.radius_m, color="tab:red", alpha=0.6))
    for c in out.result.get("collisions", []):
        i = sup.index.get(c["a"])
        if i is not None:
            k = int(np.searchsorted(out.times, c["t_s"]))
            k = min(k, T - 1)
            ax.plot(*out.poses[k, i, :2], "x", color="red", ms=10, mew=2)
    r = out.result
    status = "parked" if r["success"] else "NOT parked"
    ttp = r["time_to_park_s"]
    ax.set_title(
        f"{world.scenario.name}: {status}"
        + (f" in {ttp:.1f} s" if ttp is not None else "")
        + f", {len(r['collisions'])} collisions, min clearance {r['min_clearance_m']} m"
    )
    handles, labels = ax.get_legend_handles_labels()
    uniq = dict(zip(labels, handles, strict=False))
    if uniq:
        ax.legend(uniq.values(), uniq.keys(), loc="upper right", fontsize=8)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    xmin, ymin, xmax, ymax = world.grid.bounds
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
