"""Reports of a run: the localization summary and the state snapshot for the operator.

Reports may see the truth (the simulator behind a :class:`~swarmpark.sim.link.SimLink`):
localization errors are measured against it, and the snapshot shows where the skids really
are. Nothing here feeds back into decisions.
"""

from __future__ import annotations

import numpy as np

__all__ = ["localization_summary", "map_agreement_summary", "snapshot", "RECOVERED_ERROR_M"]

#: A kidnapped skid counts as found again once its error is below this (and stays).
RECOVERED_ERROR_M = 0.1


def localization_summary(sup) -> dict:
    """Localization error over the run (position, m) and, per kidnapping, how long the
    skid took to be found again (error below :data:`RECOVERED_ERROR_M` for good)."""
    if not sup.loc_errors:
        return {}
    err = np.stack(sup.loc_errors)
    t = np.asarray(sup.loc_times)
    out = {
        "method": "amcl",
        "recovery": bool(sup.world.scenario.sensing.recovery),
        "mean_error_m": round(float(err.mean()), 4),
        "max_error_m": round(float(err.max()), 4),
        "final_max_error_m": round(float(err[-1].max()), 4),
        "per_robot_mean_error_m": {
            rid: round(float(e), 4) for rid, e in zip(sup.ids, err.mean(axis=0), strict=True)
        },
    }
    if sup.world.believed_grid is not None:
        out["map_agreement"] = map_agreement_summary(sup.world)
    if sup.kidnapped:
        events = []
        for k, (i, t0) in enumerate(sup.kidnapped):
            later = [t1 for j, t1 in sup.kidnapped[k + 1 :] if j == i]
            window = (t > t0) & (t < (later[0] if later else np.inf))
            e, tw = err[window, i], t[window]
            bad = np.flatnonzero(e >= RECOVERED_ERROR_M)
            if len(e) == 0 or (len(bad) and bad[-1] == len(e) - 1):
                found = None  # still lost at the end of the window
            else:
                found = float(tw[bad[-1] + 1] - t0) if len(bad) else float(tw[0] - t0)
            events.append(
                {
                    "robot": sup.ids[i],
                    "at_s": round(t0, 3),
                    "error_after_m": round(float(e[0]), 4) if len(e) else None,
                    "recovered_after_s": None if found is None else round(found, 3),
                }
            )
        out["kidnaps"] = events
    return out


def map_agreement_summary(world) -> dict | None:
    """Agreement of the map the skids localize in (``sensing.map``) with the true map,
    when the two share a grid (a map built by ``swarmpark map`` in the same world does)."""
    from swarmpark.sense.mapping import map_agreement

    try:
        agree = map_agreement(world.believed_grid, world.grid, tolerance_cells=1)
    except ValueError:
        return None  # a map of another extent or resolution: no cell-by-cell comparison
    return {k: round(float(v), 4) for k, v in agree.items()}


def snapshot(sup) -> dict:
    """The state streamed to the operator interface (JSON-ready, SI units, radians): where the
    skids are (the truth when the link is the simulator), their goals and states."""
    poses, vel = sup.truth_poses(), sup.truth_vel()
    fps = sup.info.footprints
    return {
        "t_s": round(sup.t, 3),
        "estop": sup.estopped,
        "robots": [
            {
                "id": rid,
                "pose": [round(float(v), 4) for v in poses[i]],
                "vel": [round(float(v), 4) for v in vel[i]],
                "state": m,
                "goal": [round(float(v), 4) for v in sup.goals[i]] if sup.has_goal[i] else None,
                "priority": float(sup.priority[i]),
                "footprint": {
                    "length_m": fps[i].length_m,
                    "width_m": fps[i].width_m,
                    "pivot_from_rear_m": fps[i].pivot,
                },
            }
            for i, (rid, m) in enumerate(zip(sup.ids, sup.modes(), strict=True))
        ],
        "people": _people(sup),
    }


def _people(sup) -> list[dict]:
    sim = sup.sim
    if sim is not None:
        return [
            {"id": p.id, "xy": [round(float(v), 4) for v in xy], "radius_m": p.radius_m}
            for p, xy in zip(sim.people, sim.person_positions(), strict=False)
        ]
    seen = sup.inbox.people
    if seen is None:
        return []
    return [
        {"id": f"person{k}", "xy": [round(float(v), 4) for v in xy], "radius_m": float(r)}
        for k, (xy, r) in enumerate(zip(seen.xy, seen.radius_m, strict=True))
    ]
