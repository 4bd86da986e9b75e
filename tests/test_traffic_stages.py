"""scripts/traffic_stages.py: its stages account for the time a run reports lost in traffic."""

from __future__ import annotations

import pytest
from helpers import ROOT, load_script

from swarmpark.apps.run import run_world
from swarmpark.world.scenario import build_world, load_scenario


def test_the_stages_add_up_to_the_time_lost_in_traffic():
    mod = load_script("traffic_stages")
    obs = mod.StageObserver()
    world = build_world(load_scenario(ROOT / "scenarios" / "l-shape-obstacle.yaml"))
    result = run_world(world, observers=[obs]).result
    assert set(obs.lost) <= set(mod.STAGES)
    # The same skids and ticks as the run's own 'in_traffic' share, give or take a skid the
    # navigator has docked that the run does not count as parked yet: the totals agree.
    in_traffic = result["time_lost_s"]["in_traffic"]
    assert in_traffic > 5.0
    assert sum(obs.lost.values()) == pytest.approx(in_traffic, rel=0.1)
    # On this site the goal force's turn throttle is the largest share.
    assert max(obs.lost, key=obs.lost.get) == "turn throttle"
