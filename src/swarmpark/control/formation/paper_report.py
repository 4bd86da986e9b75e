"""Report of the Liu, Sun & Zhu (2010) reproduction (:mod:`.paper`): :func:`run_paper` solves
Table 1 with the three methods and runs the moving-obstacle experiment, then writes the
figures (cf. the paper's Figs. 5, 6 and 9) and a markdown table."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from swarmpark.control.formation import (
    METHODS,
    FormationPlan,
    FormationProblem,
    formation_error,
    plan_velocities,
    sample_reference,
)
from swarmpark.control.formation.paper import (
    OBSTACLE_APPEARS_S,
    TABLE2_OFFSETS_M,
    obstacle_position,
    paper_problem,
    run_obstacle_experiment,
)

__all__ = ["run_paper"]


def _compare_methods(problem: FormationProblem) -> dict[str, FormationPlan]:
    return {m: plan_velocities(problem, m) for m in METHODS}


_LABELS = {
    "formation": "velocity optimization with formation (proposed)",
    "no_formation": "velocity optimization without formation",
    "leader_follower": "leader-follower",
}


def _plot_errors(plans: dict[str, FormationPlan], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    problem = next(iter(plans.values())).problem
    fig, axes = plt.subplots(2, 3, figsize=(12, 6.5), sharex=True)
    styles = {"formation": "-", "no_formation": "--", "leader_follower": "-."}
    for m, plan in plans.items():
        fe = formation_error(plan, np.arange(0.0, plan.duration_s + 1e-9, 0.1))
        for e, (i, j) in enumerate(problem.edges.tolist()):
            ax = axes.flat[e]
            ax.plot(fe.times_s, 1e3 * fe.pair_error_m[e], styles[m], label=_LABELS[m])
            ax.set_title(f"$\\|q^e_{{{i + 1},{j + 1}}}(t)\\|$")
        sq = np.sum(fe.pair_error_m**2, axis=0)
        axes.flat[5].plot(fe.times_s, 1e6 * sq, styles[m], label=_LABELS[m])
    for ax in axes.flat[:5]:
        ax.set_ylabel("error (mm)")
    axes.flat[5].set_title("$\\sum_{ij} \\|q^e_{ij}(t)\\|^2$")
    axes.flat[5].set_ylabel("mm$^2$")
    for ax in axes[1]:
        ax.set_xlabel("t (s)")
    for ax in axes.flat:
        ax.grid(alpha=0.3)
    axes.flat[0].legend(fontsize=7, loc="upper left")
    fig.suptitle("Formation errors of the six-robot problem (Table 1), cf. Liu et al. Fig. 6")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_paths(plan: FormationPlan, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    problem = plan.problem
    fig, ax = plt.subplots(figsize=(9, 4.2))
    for i, p in enumerate(problem.paths):
        xy = p.position(np.linspace(0.0, p.length_m, 200))
        ax.plot(1e3 * xy[:, 0], 1e3 * xy[:, 1], color=f"C{i}", lw=0.8, alpha=0.6)
    snaps = np.linspace(0.0, problem.M * problem.dt_s, 6)
    ref = sample_reference(plan, snaps)
    for k, t in enumerate(snaps):
        xy = 1e3 * ref.poses[k, :, :2]
        for i, j in problem.edges.tolist():
            ax.plot(*xy[[i, j]].T, color="0.5", lw=0.7)
        for i in range(problem.n_robots):
            ax.plot(*xy[i], "o", color=f"C{i}", ms=6, mfc="white" if k == 0 else f"C{i}")
        ax.annotate(f"{t:.0f} s", xy[0] + [0, -60], ha="center", fontsize=8)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title("Planned motion with formation constraint (robot 1 at the rear apex), cf. Fig. 5")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_velocity(exp: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plan, executed = exp["plan"], exp["executed"]
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    t = exp["times_s"]
    ref0 = sample_reference(plan, t)
    for i in range(executed.problem.n_robots):
        ax.plot(t, 1e3 * exp["reference"].v[:, i], color=f"C{i}", label=f"robot {i + 1}")
        ax.plot(
            t, 1e3 * ref0.v[:, i], color=f"C{i}", ls=":", lw=0.8, label=f"robot {i + 1}, offline"
        )
    events = [(OBSTACLE_APPEARS_S, "obstacle appears")]
    for adj in exp["adjustments"]:
        events.append((adj.t_obs_s, f"{adj.decision}"))
        if adj.decision == "reverse":
            events.append((adj.t_obs_s + adj.reverse_s + adj.wait_s, "resume"))
        elif adj.decision == "wait":
            events.append((adj.t_obs_s + adj.wait_s, "resume"))
    for te, label in events:
        for a in (ax, ax2):
            a.axvline(te, color="0.4", lw=0.7, ls="--")
        ax.annotate(label, (te, ax.get_ylim()[1]), rotation=90, va="top", ha="right", fontsize=8)
    ax.set_ylabel("v (mm/s)")
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3)
    obs = obstacle_position(t)
    dist = np.linalg.norm(exp["reference"].poses[..., :2] - obs[:, None, :], axis=-1)
    seen = t >= OBSTACLE_APPEARS_S
    for i in range(executed.problem.n_robots):
        ax2.plot(t[seen], dist[seen, i], color=f"C{i}", label=f"robot {i + 1}")
    ax2.axhline(exp["d_obs_m"], color="k", lw=0.8, label="$D_{obs}$")
    ax2.set_ylabel("distance to obstacle (m)")
    ax2.set_xlabel("t (s)")
    ax2.set_ylim(0, 4)
    ax2.legend(fontsize=8)
    ax2.grid(alpha=0.3)
    fig.suptitle("Velocity profiles with a moving obstacle appearing at 5 s, cf. Liu et al. Fig. 9")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_paper(out_dir: Path) -> dict:
    """Reproduce Table 1 / Fig. 6 and Table 2 / Fig. 9; write figures and a table to ``out_dir``.

    Writes ``formation_errors.png`` (pair errors over time, three methods),
    ``formation_paths.png`` (the planned motion), ``formation_velocity.png`` (velocity
    profiles with the moving obstacle) and ``formation_table.md``. Returns the numbers:
    ``{"table1": {method: {...}}, "best_method": str, "experiment": {...}, "files": [...]}``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    problem = paper_problem()
    plans = _compare_methods(problem)
    table1 = {}
    for m, plan in plans.items():
        dense = formation_error(plan, np.arange(0.0, plan.duration_s + 1e-9, 0.05))
        table1[m] = {
            "q_e_m2": plan.q_e_m2,
            "integral_m2s": dense.integral_m2s,
            "max_pair_error_m": dense.max_pair_error_m,
            "min_pair_distance_m": plan.min_pair_distance_m,
            "duration_s": plan.duration_s,
            "success": plan.success,
            "status": plan.status,
            "iterations": plan.iterations,
        }
    best = min(table1, key=lambda m: table1[m]["integral_m2s"])

    exp = run_obstacle_experiment()
    adj = exp["adjustments"]
    ex_fe = formation_error(exp["executed"], np.arange(0.0, exp["executed"].duration_s, 0.05))
    experiment = {
        "offsets_m": TABLE2_OFFSETS_M[0].tolist(),
        "obstacle_appears_s": OBSTACLE_APPEARS_S,
        "decisions": [
            {
                "t_obs_s": a.t_obs_s,
                "decision": a.decision,
                "reverse_s": a.reverse_s,
                "wait_s": a.wait_s,
                "min_predicted_distance_m": a.min_distance_m,
            }
            for a in adj
        ],
        "min_obstacle_distance_m": exp["min_obstacle_distance_m"],
        "d_obs_m": exp["d_obs_m"],
        "offline_duration_s": exp["plan"].duration_s,
        "executed_duration_s": exp["executed"].duration_s,
        "offline_q_e_m2": exp["plan"].q_e_m2,
        "executed_max_pair_error_m": ex_fe.max_pair_error_m,
        "plan_status": exp["plan"].status,
    }

    files = {
        "errors": out / "formation_errors.png",
        "paths": out / "formation_paths.png",
        "velocity": out / "formation_velocity.png",
        "table": out / "formation_table.md",
    }
    _plot_errors(plans, files["errors"])
    _plot_paths(plans["formation"], files["paths"])
    _plot_velocity(exp, files["velocity"])
    files["table"].write_text(_markdown(table1, experiment))
    return {
        "table1": table1,
        "best_method": best,
        "experiment": experiment,
        "files": [str(f) for f in files.values()],
    }


def _markdown(table1: dict, experiment: dict) -> str:
    lines = [
        "### Six robots, Table 1 (M = 15, dt = 1 s, V_max = 120 mm/s, a_max = 120 mm/s^2, "
        "D_safe = 90 mm)",
        "",
        "| method | Q^e (m², eq. 10) | ∫ Σ‖q^e‖² dt (m² s) | max pair error (mm) "
        "| min pair distance (mm) | duration (s) | solver status |",
        "|---|---:|---:|---:|---:|---:|---|",
    ]
    for m, r in table1.items():
        lines.append(
            f"| {_LABELS[m]} | {r['q_e_m2']:.3g} | {r['integral_m2s']:.3g} | "
            f"{1e3 * r['max_pair_error_m']:.1f} | {1e3 * r['min_pair_distance_m']:.1f} | "
            f"{r['duration_s']:.0f} | {r['status']} ({r['iterations']} it) |"
        )
    lines += [
        "",
        "### Moving obstacle, Table 2 (two robots, obstacle appears at 5 s)",
        "",
        "| t_obs (s) | decision | retreat dt_r (s) | wait (s) | resume (s) |",
        "|---:|---|---:|---:|---:|",
    ]
    for d in experiment["decisions"]:
        resume = d["t_obs_s"] + d["reverse_s"] + d["wait_s"]
        lines.append(
            f"| {d['t_obs_s']:.0f} | {d['decision']} | {d['reverse_s']:.0f} | "
            f"{d['wait_s']:.0f} | {resume:.0f} |"
        )
    lines += [
        "",
        f"Smallest robot-obstacle distance {experiment['min_obstacle_distance_m']:.3f} m "
        f"(D_obs = {experiment['d_obs_m']:.2f} m); offline plan {experiment['offline_duration_s']:.0f} s, "
        f"executed {experiment['executed_duration_s']:.0f} s; largest formation error while "
        f"executing {1e3 * experiment['executed_max_pair_error_m']:.1f} mm.",
        "",
    ]
    return "\n".join(lines)
