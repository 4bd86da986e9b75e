"""Which stage of the navigator's tick slows skids in traffic (docs/navigation.md, "What slows
skids in traffic").

    python scripts/traffic_stages.py SCENARIO.yaml [...]

For each skid on its way (more than ``LOST_NEAR_M``, 2 m, from its goal, not held on
purpose) with another skid within 2 m (the run result's ``in_traffic``), the speed after each
stage is recorded: the potential field with the goal force alone, with the walls, with the
other skids (the field's command), after docking and manoeuvres, give way, the people yield,
the collision monitor, the holds and queues, and the speed reached. Each stage is charged ``dt * (previous - next) / max speed``; the seconds are
summed over the skids and printed per scenario (default monitor stack only: the stages are
the navigator's own methods, wrapped for the run).
"""

from __future__ import annotations

import dataclasses
import sys
from collections import Counter
from pathlib import Path

import numpy as np

from swarmpark.apps.run import run_world
from swarmpark.control.nav.field import PotentialField
from swarmpark.metrics import LOST_NEAR_M
from swarmpark.world.scenario import build_world, load_scenario

STAGES = (
    "turn throttle",
    "walls",
    "other skids",
    "docking, manoeuvres",
    "give way",
    "people yield",
    "monitor",
    "holds, queues",
    "acceleration",
)


class StageObserver:
    """Run observer: wraps the navigator's stages on start, charges them each tick."""

    def on_start(self, sup) -> None:
        nav = self.nav = sup.controller
        self.lost: Counter = Counter()
        self.prev = sup.truth_poses().copy()
        rec = self.rec = {}
        bare = PotentialField(dataclasses.replace(nav.params.apf, k_static=0.0), dynamic=False)
        walls = PotentialField(nav.params.apf, dynamic=False)

        def wrap(obj, name, key, take=lambda out: out):
            inner = getattr(obj, name)

            def call(*a, **k):
                out = inner(*a, **k)
                rec[key] = np.abs(take(out)[:, 0])
                return out

            setattr(obj, name, call)

        drive = nav.field.drive

        def field(view, idx, scene, *a, **k):
            rec.clear()
            rec["idx"] = idx.copy()
            rec[0] = np.abs(bare.drive(view, idx, scene, *a, **k)[0][:, 0])
            rec[1] = np.abs(walls.drive(view, idx, scene, *a, **k)[0][:, 0])
            out = drive(view, idx, scene, *a, **k)
            rec[2] = np.abs(out[0][:, 0])
            return out

        nav.field.drive = field
        wrap(nav.docking, "step", 3)
        wrap(nav.give_way, "step", 4)
        wrap(nav, "_yield", 5, lambda out: out[0])
        wrap(nav, "_monitor", 6)
        compute = nav.compute

        def tick(view):
            out = compute(view)
            if "idx" in rec:
                rec[7] = np.abs(out[rec["idx"], 0])
            return out

        nav.compute = tick

    def on_tick(self, sup) -> None:
        view, rec = sup.view(), self.rec
        poses = sup.truth_poses()
        speed = np.linalg.norm(poses[:, :2] - self.prev[:, :2], axis=1) / view.dt
        self.prev = poses.copy()
        if 7 not in rec:
            return
        to_goal = np.hypot(*(poses[:, :2] - view.goals[:, :2]).T)
        for k, i in enumerate(rec["idx"]):
            if self.nav.robots[i].dock.docked or self.nav.activity[i] or to_goal[i] < LOST_NEAR_M:
                continue
            gap = np.hypot(*(poses[:, :2] - poses[i, :2]).T)
            gap[i] = np.inf
            if gap.min() >= LOST_NEAR_M:
                continue
            vmax = view.max_speed[i]
            sp = [vmax] + [min(rec[s][k], vmax) for s in range(8)] + [min(speed[i], vmax)]
            for s, name in enumerate(STAGES):
                self.lost[name] += view.dt * (sp[s] - sp[s + 1]) / vmax

    def on_end(self, sup, result) -> None:
        pass


def main(paths: list[str]) -> None:
    print("scenario | " + " | ".join(STAGES) + " | total")
    for path in paths:
        obs = StageObserver()
        run_world(build_world(load_scenario(Path(path))), observers=[obs])
        cells = " | ".join(f"{obs.lost[name]:.1f}" for name in STAGES)
        print(f"{path} | {cells} | {sum(obs.lost.values()):.1f}")


if __name__ == "__main__":
    main(sys.argv[1:])
