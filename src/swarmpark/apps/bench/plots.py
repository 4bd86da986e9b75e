"""Figures drawn from benchmark rows: the fleet scaling plot of ``nav.fleet`` (tick CPU time
against the number of skids, log-log, with the real-time line at the control period)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["scaling_png"]


def scaling_png(rows: list[dict], out: Path, rvo_rows: list[dict] | None = None) -> Path:
    """Draw the ``nav.fleet`` rows to ``out`` (PNG): steady tick mean and p99, the heaviest
    planning tick and the first tick per fleet size, the control period as the real-time
    line, and the targets; with ``rvo_rows`` (``nav.fleet_rvo``) also its steady tick."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = sorted(rows, key=lambda r: r["N"])
    n = [r["N"] for r in rows]
    fig, ax = plt.subplots(figsize=(7.0, 4.6), dpi=110)
    series = (
        ("steady_mean_ms", "steady tick, mean", "o-", "C0"),
        ("steady_p99_ms", "steady tick, p99", "o--", "C0"),
        ("planning_max_ms", "heaviest tick while planning", "s-", "C1"),
        ("first_tick_ms", "first tick (park command)", "^-", "C3"),
    )
    for key, label, style, colour in series:
        pts = [(r["N"], r[key]) for r in rows if r.get(key)]
        if pts:
            ax.plot(*zip(*pts, strict=True), style, color=colour, label=label)
    for key, label, style in (
        ("steady_mean_ms", "steady tick with RVO, mean", "D-"),
        ("steady_p99_ms", "steady tick with RVO, p99", "D--"),
    ):
        pts = sorted((r["N"], r[key]) for r in rvo_rows or () if r.get(key))
        if pts:
            ax.plot(*zip(*pts, strict=True), style, color="C2", label=label)
    period = rows[0].get("control_period_ms", 50.0)
    ax.axhline(period, color="k", lw=1.2, label=f"real time (control period {period:g} ms)")
    ax.plot([200, 1000], [10, 50], "k*", ms=11, label="steady-tick targets")
    ax.plot([100], [200], "*", color="C3", ms=11, label="first-tick target")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks(n, [str(v) for v in n])
    ax.set_xlabel("skids parking at once")
    ax.set_ylabel("CPU time per tick (ms, one core)")
    ax.set_title("swarmpark bench nav.fleet: a park command for the whole fleet")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out
