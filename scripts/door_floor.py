"""How near the lower bound a park through a door can come in single file (docs/navigation.md,
"A door in single file against the issue's targets", session 43).

    python scripts/door_floor.py SCENARIO.yaml [...] [--gap 0.0]

For each scenario whose map has one bottleneck zone (a door or a narrow corridor, as the
navigator finds them: :func:`swarmpark.control.nav.traffic.zones_for`), the first park
command is laid out and assigned as in a run (one supervisor tick), and two times are
printed: the run's lower bound (:func:`swarmpark.metrics.lower_bound_s`) and the *single-file
floor*: the least makespan if the skids pass the zone's centre one at a time, at least one
body length plus ``--gap`` apart at top speed, each driving straight to the door and from it
straight to its spot at top speed, never turning or braking. Skid k (in order of distance
to the door) passes the door no sooner than ``max(t[k-1] + (L + gap) / v, S[k] / v)``, ``S``
the sorted straight-line distances from the starts to the door; the spots are handed out
farthest first, which minimises the latest arrival (pairing sorted times with reverse-sorted
distances). Straight lines are no longer than any path through the door, so a single file
(one skid behind another, nose to tail along the way through the door) takes at least this
long; a faster park needs skids through the door side by side, or crossing it at angles
that let them pass closer than a body length apart. Sites without exactly one zone are
skipped and listed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from swarmpark.control.nav.params import TrafficParams
from swarmpark.control.nav.traffic import zones_for
from swarmpark.supervisor.core import Supervisor
from swarmpark.world.scenario import build_world, load_scenario


def single_file_floor(
    to_door_m: np.ndarray, from_door_m: np.ndarray, length_m: float, speed_mps: float, gap_m: float
) -> float:
    """Least makespan of skids that pass a door one at a time: ``to_door_m`` ``(N,)`` the
    straight-line distances from the starts to the door, ``from_door_m`` ``(N,)`` from the door
    to the spots (any order), bodies ``length_m`` long, ``gap_m`` apart, at ``speed_mps``."""
    arrive = np.sort(np.asarray(to_door_m, float)) / speed_mps
    headway = (length_m + gap_m) / speed_mps
    passes = np.empty_like(arrive)
    for k, t in enumerate(arrive):
        passes[k] = t if k == 0 else max(passes[k - 1] + headway, t)
    after = np.sort(np.asarray(from_door_m, float))[::-1] / speed_mps
    return float(np.max(passes + after))


def site(path: Path, gap_m: float) -> dict | None:
    """The door's width, the lower bound and the single-file floor of one scenario (None:
    its map has no single bottleneck zone)."""
    world = build_world(load_scenario(path))
    zones = zones_for(world.grid, [r.footprint for r in world.robots], TrafficParams())
    if zones.count != 1:
        return None
    sup = Supervisor(world)
    sup.tick()  # the park command at t = 0: layout and assignment
    has = sup.has_goal
    door = np.array(zones.polygons[0].centroid.coords[0])
    starts, goals = sup.truth_poses()[has, :2], sup.goals[has, :2]
    robots = [r for r, h in zip(world.robots, has, strict=True) if h]
    floor = single_file_floor(
        np.linalg.norm(starts - door, axis=1),
        np.linalg.norm(goals - door, axis=1),
        min(r.footprint.length_m for r in robots),
        max(r.max_speed_mps for r in robots),
        gap_m,
    )
    bound = sup.metrics.lower_bound
    return {
        "site": world.scenario.name,
        "skids": int(has.sum()),
        "door_m": round(float(zones.widths_m[0]), 2),
        "bound_s": None if bound is None else round(bound, 1),
        "floor_s": round(floor, 1),
        "floor_over_bound": None if bound is None else round(floor / bound, 2),
    }


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", type=Path, nargs="+")
    ap.add_argument("--gap", type=float, default=0.0, help="nose to tail, metres (default 0)")
    a = ap.parse_args(argv)
    missing = [str(p) for p in a.scenarios if not p.is_file()]
    if missing:
        ap.error(f"scenarios: no such file ({', '.join(missing)})")
    if a.gap < 0:
        ap.error(f"--gap must be at least 0 (got {a.gap})")
    rows, skipped = [], []
    print("| site | skids | door (m) | lower bound (s) | single-file floor (s) | floor / bound |")
    print("|---|---|---|---|---|---|")
    for p in a.scenarios:
        r = site(p, a.gap)
        if r is None:
            skipped.append(p.name)
            continue
        rows.append(r)
        print("| " + " | ".join(str(v) for v in r.values()) + " |", flush=True)
    ratios = np.array([r["floor_over_bound"] for r in rows if r["floor_over_bound"] is not None])
    if len(ratios):
        print(
            f"\n{len(ratios)} sites: floor / bound median {np.median(ratios):.2f}, "
            f"above 1.3 on {int((ratios > 1.3).sum())}, above 2.0 on {int((ratios > 2.0).sum())}"
        )
    if skipped:
        print(f"skipped (not one bottleneck zone): {', '.join(skipped)}")


if __name__ == "__main__":
    main(sys.argv[1:])
