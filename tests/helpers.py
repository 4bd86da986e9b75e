"""Helpers for the tests: tiny worlds built from dicts, scripted controllers."""

from __future__ import annotations

import numpy as np

from swarmpark.scenario import build_world, parse_scenario


def make_world(**overrides):
    """A small open world (10 x 6 m) with one robot; keys override the scenario dict."""
    data = {
        "name": "t",
        "duration_s": 20,
        "map": {"size_m": [10, 6], "resolution_m": 0.05},
        "robots": [{"id": "a", "pose": [2.0, 3.0, 0.0]}],
    }
    data.update(overrides)
    return build_world(parse_scenario(data))


class Scripted:
    """A controller that replays a function of time: ``fn(t) -> (N, 2)`` commands."""

    def __init__(self, fn):
        self.fn = fn

    def compute(self, view):
        return np.asarray(self.fn(view.t), float).reshape(-1, 2)
