"""Compare two runs of the same sweep, site by site: did a change park more, faster?

    python scripts/sweep_diff.py BEFORE.parquet AFTER.parquet [BEFORE2 AFTER2 ...] [--all]

Both files are ``results.parquet`` of ``swarmpark sweep`` (or the committed
``sweeps/results/*.parquet``). Runs are matched on the site (``kind``: the generated kind
or the scenario's name; ``seed``; the fleet size asked for) and the sweep's parameters
(``param.*`` columns, which must be the same on both sides), so a sweep run on a subset of
the other's sites compares on the sites they share. Printed: runs fully parked, skids
parked, contacts and deadlock episodes on either side; the geometric mean of time to park
(after / before) over the runs parked both ways; runs and skids parked per kind of site;
and the runs whose skids parked or time to
park changed (``--all``: every run). Exits with status 2 if a file is missing or not a
sweep's results, the two sweep different parameters, or they share no site.

Several pairs (say main and a change on the unperturbed held-out sites, then on their
perturbed draws) are compared pair by pair and pooled. The pooled figures end with a paired
test per site: each site's skids parked after less before, summed over its runs (draws),
as a mean over the sites with its standard error, and how many sites gained or lost. One
draw of a large site moves by several skids on its own, so a difference within about two
standard errors of zero is no evidence either way.

This is how each "Tried and left out" entry of docs/navigation.md was judged (there against
main's run of the same sites; large runs are chaotic, so one site moving says little).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

#: Columns every sweep's results carry.
NEEDED = (
    "kind",
    "seed",
    "success",
    "n_robots",
    "n_parked",
    "time_to_park_s",
    "n_collisions",
    "n_deadlocks",
)


def keys(frame: pd.DataFrame) -> list[str]:
    """The columns that name a run: its site (``kind``: the generated kind or the scenario's
    name; ``seed``; ``robots_asked``, the fleet size a sweep asked the generator for, where
    the results have it: one seed makes a site of each size) and the sweep's parameters."""
    site = ["kind", "seed"] + (["robots_asked"] if "robots_asked" in frame.columns else [])
    return site + sorted(c for c in frame.columns if c.startswith("param."))


def diff(before: pd.DataFrame, after: pd.DataFrame) -> tuple[dict, pd.DataFrame]:
    """``(summary, runs)``: the two sides' totals on the runs they share, and one row per
    shared run with both sides' skids parked and time to park (``changed``: either
    differs). Raises ValueError naming what is wrong."""
    for name, frame in (("before", before), ("after", after)):
        missing = [c for c in NEEDED if c not in frame.columns]
        if missing:
            raise ValueError(f"{name}: not a sweep's results (no column {', '.join(missing)})")
    on, on_after = keys(before), keys(after)
    if on != on_after:
        only = sorted(set(on) ^ set(on_after))
        raise ValueError(f"before, after: not the same parameters ({', '.join(only)} on one side)")
    m = before.merge(after, on=on, suffixes=("_before", "_after"))
    if m.empty:
        raise ValueError(f"before, after: no site in common (matched on {', '.join(on)})")
    runs = m[on].copy()
    runs["skids"] = m.n_robots_before
    for side in ("before", "after"):
        runs[f"parked_{side}"] = m[f"n_parked_{side}"]
        runs[f"time_{side}"] = m[f"time_to_park_s_{side}"]
        runs[f"success_{side}"] = m[f"success_{side}"].astype(bool)
        runs[f"contacts_{side}"] = m[f"n_collisions_{side}"]
        runs[f"deadlocks_{side}"] = m[f"n_deadlocks_{side}"]
    same_time = np.isclose(runs.time_before, runs.time_after) | (
        runs.time_before.isna() & runs.time_after.isna()
    )
    runs["changed"] = (runs.parked_before != runs.parked_after) | ~same_time
    return pooled(runs), runs


def pooled(runs: pd.DataFrame) -> dict:
    """Totals of the runs of one or several :func:`diff` calls (``runs`` frames, concatenated),
    and the paired test per site: each site's (``kind``, ``seed``, ``robots_asked`` where
    present) skids parked after less before, summed over its runs; their mean over the
    sites, its standard error, and the sites that gained and lost."""
    site = ["kind", "seed"] + (["robots_asked"] if "robots_asked" in runs.columns else [])
    both = runs[runs.success_before & runs.success_after]
    ratio = both.time_after / both.time_before
    per_site = (
        (runs.parked_after - runs.parked_before)
        .groupby([runs[c] for c in site], dropna=False)
        .sum()
    )
    n = len(per_site)
    return {
        "by_kind": by_kind(runs),
        "runs": len(runs),
        "skids": int(runs.skids.sum()),
        **{
            f"{what}_{side}": int(runs[f"{col}_{side}"].sum())
            for what, col in (
                ("parked_runs", "success"),
                ("parked_skids", "parked"),
                ("contacts", "contacts"),
                ("deadlocks", "deadlocks"),
            )
            for side in ("before", "after")
        },
        "parked_both": len(both),
        "time_ratio": float(np.exp(np.log(ratio).mean())) if len(both) else None,
        "sites": n,
        "site_gain_mean": float(per_site.mean()),
        "site_gain_se": float(per_site.std(ddof=1) / np.sqrt(n)) if n > 1 else None,
        "sites_gained": int((per_site > 0).sum()),
        "sites_lost": int((per_site < 0).sum()),
    }


def by_kind(runs: pd.DataFrame) -> pd.DataFrame:
    """Per kind of site: its runs and skids, and on either side the runs fully parked and
    the skids parked (a change that wins on doors and loses on corridors shows here)."""
    g = runs.groupby("kind", sort=True)
    return pd.DataFrame(
        {
            "runs": g.size(),
            "skids": g.skids.sum(),
            "full_before": g.success_before.sum(),
            "full_after": g.success_after.sum(),
            "parked_before": g.parked_before.sum(),
            "parked_after": g.parked_after.sum(),
        }
    ).astype(int)


def _read(ap: argparse.ArgumentParser, name: str, path: Path) -> pd.DataFrame:
    if not path.is_file():
        ap.error(f"{name}: no such file ({path})")
    try:
        return pd.read_parquet(path)
    except Exception as exc:  # pyarrow raises several kinds for a file that is not Parquet
        ap.error(f"{name}: not a Parquet file ({path}: {exc})")


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", type=Path, nargs="+", metavar="BEFORE AFTER")
    ap.add_argument("--all", action="store_true", help="list every run, not only those changed")
    a = ap.parse_args(argv)
    if len(a.files) % 2:
        ap.error(f"files: give BEFORE AFTER pairs (got {len(a.files)} files)")
    pairs = []
    for k in range(0, len(a.files), 2):
        tag = "" if len(a.files) == 2 else f" (pair {k // 2 + 1})"
        before = _read(ap, "before" + tag, a.files[k])
        after = _read(ap, "after" + tag, a.files[k + 1])
        try:
            pairs.append(diff(before, after))
        except ValueError as exc:
            ap.error(f"{exc}{tag}")
    for k, (s, runs) in enumerate(pairs):
        if len(pairs) > 1:
            print(f"== pair {k + 1}: {a.files[2 * k]} -> {a.files[2 * k + 1]}")
        _report(s, runs, a.all)
    allruns = pd.concat([runs for _, runs in pairs], ignore_index=True)
    p = pooled(allruns)
    if len(pairs) > 1:
        print(f"\n== pooled: {p['runs']} runs, {p['skids']} skids")
        _totals(p)
    if p["by_kind"].index.nunique() > 1:
        print("\nper kind of site:")
        print(p["by_kind"].to_string())
    se = "-" if p["site_gain_se"] is None else f"{p['site_gain_se']:.2f}"
    print(
        f"skids parked per site, after less before, summed over its {p['runs']} runs: "
        f"mean {p['site_gain_mean']:+.2f} (standard error {se}) over {p['sites']} sites; "
        f"{p['sites_gained']} gained, {p['sites_lost']} lost"
    )


def _totals(s: dict) -> None:
    print(f"runs fully parked: {s['parked_runs_before']} before, {s['parked_runs_after']} after")
    print(f"skids parked:      {s['parked_skids_before']} before, {s['parked_skids_after']} after")
    print(f"contacts:          {s['contacts_before']} before, {s['contacts_after']} after")
    print(f"deadlock episodes: {s['deadlocks_before']} before, {s['deadlocks_after']} after")
    if s["time_ratio"] is not None:
        print(
            f"time to park, the {s['parked_both']} runs parked both ways: "
            f"after / before {s['time_ratio']:.3f} (geometric mean)"
        )


def _report(s: dict, runs: pd.DataFrame, show_all: bool) -> None:
    print(f"{s['runs']} runs in common, {s['skids']} skids")
    _totals(s)
    shown = runs if show_all else runs[runs.changed]
    print(f"\n{int(runs.changed.sum())} of {len(runs)} runs changed")
    if len(shown):
        extra = [c for c in runs.columns if c.startswith(("success_", "contacts_", "deadlocks_"))]
        print(shown.drop(columns=["changed", *extra]).to_string(index=False))


if __name__ == "__main__":
    main(sys.argv[1:])
