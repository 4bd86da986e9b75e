"""The sensing part of ``swarmpark figures`` (docs/sensing.md): localization error over time
(hangar-park-amcl, kidnap-room), the hangar map built by map-hangar against the true map, the
table of measured numbers, and the fidelity rows for the 2018 paper's Sect. 3.5."""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["sensing"]

#: Extra seeds of kidnap-room in the table (full runs only).
KIDNAP_SEEDS = (1, 2)


def _run(scn):
    from swarmpark.apps.run import run_world
    from swarmpark.world.scenario import build_world

    return run_world(build_world(scn))


def _built_map(scn, robot: str):
    """Build a map of ``scn`` with ``robot``; returns the summary and the built grid."""
    from swarmpark.apps.mapping_run import build_map
    from swarmpark.core.gridmap import load_map_yaml
    from swarmpark.world.scenario import build_world

    world = build_world(scn)
    with tempfile.TemporaryDirectory() as tmp:
        summary = build_map(world, robot, Path(tmp) / "built.yaml")
        built = load_map_yaml(Path(tmp) / "built.yaml")
    return world, summary, built


def _plot_localization(path: Path, amcl, kidnap) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    sup, r = amcl.supervisor, amcl.result
    t, err = np.asarray(sup.loc_times), np.stack(sup.loc_errors)
    for k, rid in enumerate(sup.ids):
        axes[0].plot(t, err[:, k] * 100, lw=1, label=rid)
    loc = r["localization"]
    axes[0].set_title(
        f"hangar-park-amcl: mean {loc['mean_error_m'] * 100:.1f} cm, "
        f"max {loc['max_error_m'] * 100:.1f} cm"
    )
    axes[0].set_xlabel("t [s]")
    axes[0].set_ylabel("position error [cm]")
    axes[0].legend(ncol=3, fontsize=7)
    sup, r = kidnap.supervisor, kidnap.result
    t, err = np.asarray(sup.loc_times), np.stack(sup.loc_errors)
    axes[1].semilogy(t, np.maximum(err[:, 0], 1e-4) * 100, lw=1)
    kids = r["localization"].get("kidnaps", [])
    if kids:
        axes[1].axvline(kids[0]["at_s"], color="r", ls=":", label="carried away")
        axes[1].set_title(
            f"kidnap-room: found again {kids[0]['recovered_after_s']} s after the kidnapping"
        )
    axes[1].axhline(10, color="k", ls="--", lw=0.8, label="10 cm")
    axes[1].set_xlabel("t [s]")
    axes[1].set_ylabel("position error [cm]")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_map(path: Path, world, summary: dict, built) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    truth = world.grid
    img = np.full((*truth.shape, 3), 1.0)
    img[built.unknown] = (0.85, 0.85, 0.85)
    img[truth.occupied] = (0.2, 0.2, 0.2)
    img[built.occupied & ~truth.occupied] = (0.85, 0.1, 0.1)
    img[built.occupied & truth.occupied] = (0.1, 0.45, 0.9)
    fig, ax = plt.subplots(figsize=(8, 5.6))
    x0, y0, x1, y1 = truth.bounds
    ax.imshow(img, origin="lower", extent=(x0, x1, y0, y1), interpolation="nearest")
    a = summary["map_agreement"]
    ax.set_title(
        "map-hangar, built map vs truth: blue built wall on a true wall cell, red next to one, "
        f"grey unobserved\nwall precision (within one cell) {a['wall_precision']:.3f}, recall "
        f"{a['wall_recall']:.3f}, observed {a['share_observed']:.2f}; mapping skid's pose error "
        f"<= {summary['slam_error_max_m'] * 100:.1f} cm (odometry drift "
        f"{summary['odometry_drift_final_m']:.2f} m)",
        fontsize=9,
    )
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _parked(r: dict) -> str:
    n = sum(1 for s in r["robots"].values() if s["commanded"])
    parked = sum(1 for s in r["robots"].values() if s["commanded"] and s["parked"])
    head = "all parked" if r["success"] else f"{parked} of {n} parked"
    return f"{head}, {len(r['collisions'])} collisions"


def _loc(r: dict) -> str:
    loc = r.get("localization") or {}
    if "mean_error_m" not in loc:
        return "no localization data"
    return f"mean error {loc['mean_error_m'] * 100:.1f} cm, max {loc['max_error_m'] * 100:.1f} cm"


def _map_cell(summary: dict) -> str:
    a = summary["map_agreement"]
    return (
        f"wall precision {a['wall_precision']:.2f}, recall {a['wall_recall']:.2f}, "
        f"{100 * a['share_observed']:.0f} % observed; pose error at most "
        f"{summary['slam_error_max_m'] * 100:.1f} cm while the odometry drifts "
        f"{summary['odometry_drift_final_m']:.2f} m"
    )


def _recovered(r: dict) -> str:
    kids = (r.get("localization") or {}).get("kidnaps", [])
    if not kids:
        return "not kidnapped yet"
    s = kids[0]["recovered_after_s"]
    return "never found again" if s is None else f"found again after {s} s"


def sensing(img: Path, quick: bool, scenario: Callable) -> list[dict]:
    """Write the sensing figures and ``img/sensing_table.md``; return the fidelity rows.

    ``scenario(name, quick, **update)`` loads a scenario (cut short when ``quick``).
    """
    amcl = _run(scenario("hangar-park-amcl", quick))
    kidnap = _run(scenario("kidnap-room", quick))
    _plot_localization(img / "sensing_localization.png", amcl, kidnap)
    world, hangar, built = _built_map(scenario("map-hangar", quick), "m1")
    _plot_map(img / "sensing_map.png", world, hangar, built)
    _, room, _ = _built_map(scenario("map-room", quick), "m1")
    park_built = _run(scenario("room-park-built", quick)).result
    detect = _run(scenario("room-detect", quick)).result
    seeds = (
        ""
        if quick
        else " (seeds "
        + ", ".join(
            f"{s}: {_recovered(_run(scenario('kidnap-room', quick, seed=s)).result)}"
            for s in KIDNAP_SEEDS
        )
        + ")"
    )
    a, k = amcl.result, kidnap.result
    table = [
        "| scenario | what | result |",
        "|---|---|---|",
        "| `hangar-park-amcl` | hangar-park's six skids localizing onboard in a hangar with rack "
        f"uprights by the parking rows | {_parked(a)}; {_loc(a)} |",
        "| `kidnap-room` | a parked skid carried 5.2 m away and turned; then sent on | "
        f"{_recovered(k)}{seeds}; {_parked(k)} |",
        "| `map-room` + `room-park-built` | m1 maps a room; three skids localize and park in the "
        f"built map | map: {_map_cell(room)}; park: {_parked(park_built)}, {_loc(park_built)} |",
        "| `room-detect` | two skids park past a crate the map lacks and a person who stands in "
        f"the way, then leaves | {_parked(detect)} |",
        f"| `map-hangar` | m1 maps the staging-bay hangar on a loop | {_map_cell(hangar)} |",
    ]
    note = f" (quick: cut at {a['sim_time_s']:g} s)" if quick else ""
    (img / "sensing_table.md").write_text(
        f"Seed 0; made by `swarmpark figures`{note}.\n\n" + "\n".join(table) + "\n"
    )
    mod = "sense/ (lidar, localize (AMCL), mapping, costmap)"
    return [
        {
            "item": "Hing 2018 Sect. 3.5.1: AMCL localization against a known map",
            "module": mod,
            "paper": "skids localize onboard with AMCL in a known map (no error reported)",
            "swarmpark": f"hangar-park-amcl: {_loc(a)}; {_parked(a)}",
        },
        {
            "item": "Hing 2018 Sect. 3.5.1: GMapping builds the map",
            "module": "sense/mapping.py, sense/posegraph.py",
            "paper": "a map built onboard (GMapping), shared as the common frame",
            "swarmpark": f"map-hangar: {_map_cell(hangar)}",
        },
    ]
