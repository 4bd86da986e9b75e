"""Figures of docs/sensing.md: localization error over time (hangar-park-amcl, kidnap-room)
and the hangar map built by map-hangar against the true map.

Run from the repository root: ``python scripts/sensing_figures.py`` (about a minute).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from swarmpark.apps.mapping_run import build_map  # noqa: E402
from swarmpark.apps.run import run_world  # noqa: E402
from swarmpark.core.gridmap import load_map_yaml  # noqa: E402
from swarmpark.world.scenario import build_world, load_scenario  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCN = ROOT / "scenarios"
IMG = ROOT / "docs" / "img"


def error_series(name: str):
    out = run_world(build_world(load_scenario(SCN / name)))
    sup = out.supervisor
    return np.asarray(sup.loc_times), np.stack(sup.loc_errors), sup.ids, out.result


def main() -> int:
    IMG.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    t, err, ids, r = error_series("hangar-park-amcl.yaml")
    for k, rid in enumerate(ids):
        axes[0].plot(t, err[:, k] * 100, lw=1, label=rid)
    loc = r["localization"]
    axes[0].set_title(
        f"hangar-park-amcl: mean {loc['mean_error_m'] * 100:.1f} cm, max {loc['max_error_m'] * 100:.1f} cm"
    )
    axes[0].set_xlabel("t [s]")
    axes[0].set_ylabel("position error [cm]")
    axes[0].legend(ncol=3, fontsize=7)
    t, err, ids, r = error_series("kidnap-room.yaml")
    axes[1].semilogy(t, np.maximum(err[:, 0], 1e-4) * 100, lw=1)
    kid = r["localization"]["kidnaps"][0]
    axes[1].axvline(kid["at_s"], color="r", ls=":", label="carried away")
    axes[1].axhline(10, color="k", ls="--", lw=0.8, label="10 cm")
    axes[1].set_title(f"kidnap-room: found again {kid['recovered_after_s']} s after the kidnapping")
    axes[1].set_xlabel("t [s]")
    axes[1].set_ylabel("position error [cm]")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(IMG / "sensing_localization.png", dpi=110)

    world = build_world(load_scenario(SCN / "map-hangar.yaml"))
    with tempfile.TemporaryDirectory() as tmp:
        summary = build_map(world, "m1", Path(tmp) / "built.yaml")
        built = load_map_yaml(Path(tmp) / "built.yaml")
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
    fig.savefig(IMG / "sensing_map.png", dpi=110)
    print(summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
