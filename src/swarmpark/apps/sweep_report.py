"""A sweep's records as a Parquet table and a Markdown summary with plots.

One row per job: the job's parameters (``param.<key>`` columns), its ``error`` and wall time,
and the run's result JSON flattened (nested mappings joined with dots; lists and the
per-robot mappings kept as JSON text, with counts beside them). The summary gives, overall,
per kind and per value of every swept parameter: jobs, errors, success rate (an errored job
counts as not parked), runs with a collision, time-to-park over the lower bound (median and
90th percentile of the parked runs) and deadlocks, and how many of those were reported within
:data:`PARKING_M` of the skid's goal (parking: the rest held it up on its way).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from swarmpark.control.nav.params import FollowerParams

__all__ = ["flatten_result", "records_table", "summarize", "write_report", "print_summary"]

#: Result entries kept whole as JSON text (one entry per robot: not columns).
_AS_JSON = ("robots", "path_length_m", "expect")
_COUNTED = ("collisions", "deadlocks", "recoveries", "expect_failures", "commands")
#: A deadlock reported this close to the skid's goal is one of parking (the path follower's
#: final approach); farther off, the skid was held up on its way.
PARKING_M = FollowerParams().approach_m


def flatten_result(result: dict | None, prefix: str = "") -> dict:
    """Scalars as columns, nested mappings joined with dots, lists as JSON text plus counts.

    >>> flatten_result({"success": True, "tick_ms": {"mean": 1.0}, "collisions": [{}]})
    {'success': True, 'tick_ms.mean': 1.0, 'collisions': '[{}]', 'n_collisions': 1}
    """
    out: dict = {}
    for k, v in (result or {}).items():
        key = prefix + k
        if isinstance(v, dict) and k not in _AS_JSON:
            out.update(flatten_result(v, key + "."))
        elif isinstance(v, (list, dict)):
            out[key] = json.dumps(v)
            if k in _COUNTED:
                out[prefix + "n_" + k] = len(v)
        else:
            out[key] = v
    return out


def _row(rec: dict) -> dict:
    job = rec["job"]
    row = {
        "job_id": job["job_id"],
        "kind": job["kind"],
        "source": job["source"],
        "seed": job["seed"],
        "robots_asked": job["robots"],
        "duration_override_s": job["duration_s"],
        **{f"param.{k}": (v if isinstance(v, (int, float, str)) else json.dumps(v))
           for k, v in job["params"].items()},
        "error": rec["error"],
        "wall_s": rec["wall_s"],
        "attempts": rec["attempts"],
    }  # fmt: skip
    res = rec.get("result")
    row.update(flatten_result(res))
    if res:
        robots = [r for r in res.get("robots", {}).values() if r.get("commanded")]
        row["n_robots"] = len(res.get("robots", {}))
        row["n_parked"] = sum(bool(r.get("parked")) for r in robots)
        tp, lb = res.get("time_to_park_s"), res.get("lower_bound_s")
        row["time_over_bound"] = tp / lb if tp is not None and lb else None
        dls = res.get("deadlocks") or []
        far = [d.get("goal_distance_m") for d in dls]
        # Episodes reported within PARKING_M of the goal (parking) rather than on the way;
        # None for results from before deadlocks carried their distance.
        row["n_deadlocks_parking"] = (
            None if any(f is None for f in far) else sum(f <= PARKING_M for f in far)
        )
    return row


def records_table(out_dir: Path, job_ids: list[str]) -> pd.DataFrame:
    """The records of ``job_ids`` (those that exist) as a DataFrame, in spec order."""
    rows = []
    for jid in job_ids:
        p = out_dir / "records" / f"{jid}.json"
        if p.is_file():
            rows.append(_row(json.loads(p.read_text())))
    df = pd.DataFrame(rows)
    if not df.empty and "success" in df:
        df["parked"] = df["success"].astype("boolean").fillna(False) & df["error"].isna()
    elif not df.empty:
        df["parked"] = False
    return df


def _group_stats(g: pd.DataFrame) -> dict:
    ok = g[g["error"].isna()]
    ratio = g.loc[g["parked"], "time_over_bound"].dropna() if "time_over_bound" in g else []
    coll = ok["n_collisions"] if "n_collisions" in ok else pd.Series(dtype=float)
    dead = ok["n_deadlocks"] if "n_deadlocks" in ok else pd.Series(dtype=float)
    parking = ok["n_deadlocks_parking"] if "n_deadlocks_parking" in ok else pd.Series(dtype=float)
    skids = ok["n_robots"].sum() if "n_robots" in ok else 0
    return {
        "jobs": len(g),
        "errors": int(g["error"].notna().sum()),
        "success_rate": float(g["parked"].mean()) if len(g) else float("nan"),
        # Of the skids of the runs that have a result, the share parked.
        "skids_parked": float(ok["n_parked"].sum() / skids) if skids else None,
        "runs_with_collision": int((coll > 0).sum()),
        "collisions": int(coll.sum()),
        "ratio_p50": float(np.median(ratio)) if len(ratio) else None,
        "ratio_p90": float(np.percentile(ratio, 90)) if len(ratio) else None,
        "ratio_p95": float(np.percentile(ratio, 95)) if len(ratio) else None,
        "deadlocks": int(dead.sum()),
        # Of those, reported within PARKING_M of the goal (None if a result lacks it).
        "deadlocks_parking": int(parking.sum()) if len(parking) and parking.notna().all() else None,
        "wall_s_mean": float(g["wall_s"].mean()),
    }


#: Fleet-size bands of the ``fleet`` table (upper ends, inclusive).
FLEET_BANDS = (10, 20, 30)


def _fleet_band(n) -> str | None:
    """The band of a fleet of ``n`` skids, as "1-10" style text (None for no result)."""
    if n is None or pd.isna(n):
        return None
    lo = 1
    for hi in FLEET_BANDS:
        if n <= hi:
            return f"{lo}-{hi}"
        lo = hi + 1
    return f"{lo}+"


def summarize(df: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """Summary tables: ``overall``, ``kind``, ``fleet`` (per band of fleet sizes,
    :data:`FLEET_BANDS`, when the runs span more than one) and one per swept parameter."""
    if df.empty:
        return {}
    tables = {"overall": pd.DataFrame([{"group": "all", **_group_stats(df)}])}
    cols = ["kind"]
    if "n_robots" in df:
        df = df.assign(fleet=df["n_robots"].map(_fleet_band))
        if df["fleet"].nunique() > 1:
            cols.append("fleet")
    for col in cols + [c for c in df.columns if c.startswith("param.")]:
        rows = [{col: k, **_group_stats(g)} for k, g in df.groupby(col, sort=True, dropna=False)]
        tables[col] = pd.DataFrame(rows)
    return tables


def time_lost(df: pd.DataFrame) -> pd.DataFrame | None:
    """Seconds each skid lost against its top speed on the way to its goal, by what it was
    doing (the results' ``time_lost_s``), averaged over the skids of each kind's runs; None
    if no result has them."""
    cols = [c for c in df.columns if c.startswith("time_lost_s.")]
    if not cols or "n_robots" not in df or "kind" not in df:
        return None
    ok = df[df[cols].notna().all(axis=1) & (df["n_robots"] > 0)]
    if ok.empty:
        return None
    rows = []
    for kind, g in ok.groupby("kind", sort=True):
        per_skid = g[cols].sum() / g["n_robots"].sum()
        rows.append({"kind": kind, **{c.split(".", 1)[1]: float(v) for c, v in per_skid.items()}})
    return pd.DataFrame(rows)


def _cell(v) -> str:
    if v is None or (isinstance(v, float) and np.isnan(v)):
        return "-"
    if isinstance(v, float):
        return f"{v:.2f}"
    return str(v)


def markdown(df: pd.DataFrame) -> str:
    cols = list(df.columns)
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(_cell(v) for v in row) + " |" for row in df.itertuples(False)]
    return "\n".join(lines) + "\n"


def _plots(df: pd.DataFrame, tables: dict, out_dir: Path, prefix: str = "") -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    keys = [k for k in tables if k != "overall"]
    fig, axes = plt.subplots(1, len(keys), figsize=(4.5 * len(keys), 3.6), squeeze=False)
    for ax, key in zip(axes[0], keys, strict=True):
        t = tables[key]
        ax.bar([str(v) for v in t[key]], t["success_rate"], color="tab:green")
        ax.set_ylim(0, 1)
        ax.set_title(f"success rate per {key}")
        ax.tick_params(axis="x", rotation=45)
    fig.tight_layout()
    paths.append(out_dir / f"{prefix}success.png")
    fig.savefig(paths[-1], dpi=90)
    plt.close(fig)
    if "time_over_bound" in df:
        parked = df[df["parked"]]
        groups = [(k, g["time_over_bound"].dropna()) for k, g in parked.groupby("kind")]
        groups = [(k, v) for k, v in groups if len(v)]
        if groups:
            fig, ax = plt.subplots(figsize=(1.2 * len(groups) + 3, 3.6))
            ax.boxplot([v for _, v in groups], tick_labels=[k for k, _ in groups])
            ax.set_ylabel("time to park / lower bound")
            ax.tick_params(axis="x", rotation=45)
            fig.tight_layout()
            paths.append(out_dir / f"{prefix}time_over_bound.png")
            fig.savefig(paths[-1], dpi=90)
            plt.close(fig)
    return paths


def _lost_plot(lost: pd.DataFrame, out_dir: Path, prefix: str = "") -> Path:
    """A stacked bar per kind of :func:`time_lost`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cats = [c for c in lost.columns if c != "kind"]
    fig, ax = plt.subplots(figsize=(1.2 * len(lost) + 4, 3.6))
    bottom = np.zeros(len(lost))
    for c in cats:
        ax.bar(lost["kind"].astype(str), lost[c], bottom=bottom, label=c)
        bottom += lost[c].to_numpy()
    ax.set_ylabel("time lost per skid (s)")
    ax.tick_params(axis="x", rotation=45)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    path = out_dir / f"{prefix}time_lost.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def figure_links(plots: list[Path]) -> str:
    """Markdown links to ``plots``, one paragraph each, as a summary ends with them."""
    return "".join(f"\n![{p.stem}]({p.name})\n" for p in plots)


def write_plots(df: pd.DataFrame, out_dir: Path, prefix: str = "") -> list[Path]:
    """The summary's figures of a sweep's table ``df`` (success rates, time over the bound,
    time lost), written to ``out_dir`` as ``{prefix}success.png`` and so on."""
    if df.empty:
        return []
    return _write_plots(df, summarize(df), time_lost(df), out_dir, prefix)


def _write_plots(df, tables: dict, lost, out_dir: Path, prefix: str = "") -> list[Path]:
    """:func:`write_plots` from the tables and time lost already summarized."""
    plots = _plots(df, tables, out_dir, prefix) if tables else []
    if lost is not None:
        plots.append(_lost_plot(lost, out_dir, prefix))
    return plots


def write_report(out_dir: Path, job_ids: list[str], name: str) -> dict:
    """Write ``results.parquet``, ``summary.md`` and plots; return the tables and paths."""
    df = records_table(out_dir, job_ids)
    table = out_dir / "results.parquet"
    df.to_parquet(table, engine="pyarrow", index=False)
    tables = summarize(df)
    md = [f"# Sweep {name}\n", f"{len(df)} of {len(job_ids)} jobs have a record.\n"]
    for key, t in tables.items():
        md += [f"\n## {'per ' + key if key != 'overall' else 'overall'}\n\n", markdown(t)]
    errors = df[df["error"].notna()] if not df.empty else df
    if len(errors):
        md.append("\n## errors\n\n")
        md += [
            f"- `{r.job_id}`: {str(r.error).splitlines()[-1][:300]}\n" for r in errors.itertuples()
        ]
    lost = time_lost(df) if not df.empty else None
    if lost is not None:
        md += [
            "\n## time lost per skid (s) against top speed, by what it was doing\n\n",
            markdown(lost),
        ]
    plots = _write_plots(df, tables, lost, out_dir)
    md.append(figure_links(plots))
    summary = out_dir / "summary.md"
    summary.write_text("".join(md))
    return {"table": table, "summary": summary, "plots": plots, "tables": tables, "rows": len(df)}


def print_summary(rep: dict) -> None:
    """Print the summary tables and where the files are."""
    for key, t in rep["tables"].items():
        print(f"\n{key}\n" + markdown(t), end="")
    print(
        f"\nran {rep['ran']} job(s), skipped {rep['skipped']} finished, {rep['rows']} rows, "
        f"{rep['wall_s']} s; "
        f"wrote {rep['table']} and {rep['summary']}"
    )
