"""Keep a sweep's results in the repository: its table, its summary and its figures.

    python scripts/publish_sweep.py OUT_DIR NAME    # after swarmpark sweep ... --out OUT_DIR
    python scripts/publish_sweep.py --figures NAME  # figures of a table already committed

The first copies ``OUT_DIR/results.parquet`` and ``OUT_DIR/summary.md`` to
``sweeps/results/NAME.parquet`` and ``NAME.md``; both forms then draw the summary's figures
from ``NAME.parquet`` (:func:`swarmpark.apps.sweep_report.write_plots`) as
``sweeps/results/NAME-success.png`` and so on, and point the summary's figure links at them
(a summary written in the sweep's output directory links ``success.png`` beside it).
"""

import argparse
import re
import shutil
import sys
from pathlib import Path

import pandas as pd

from swarmpark.apps.sweep_report import figure_links, write_plots

RESULTS = Path(__file__).resolve().parent.parent / "sweeps" / "results"
#: A figure link of a summary (:func:`~swarmpark.apps.sweep_report.figure_links`), with or
#: without a name prefix.
FIGURE = re.compile(r"\n!\[[^\]]*\]\([^)\s]*\.png\)\n")


def publish(name: str, out_dir: Path | None = None, results: Path = RESULTS) -> list[Path]:
    """Copy a sweep's table and summary (from ``out_dir``, if given) into ``results`` as
    ``name``, draw its figures there and link them from the summary; returns the figures."""
    table, summary = results / f"{name}.parquet", results / f"{name}.md"
    if out_dir is not None:
        for src in (out_dir / "results.parquet", out_dir / "summary.md"):
            if not src.is_file():
                raise SystemExit(f"publish_sweep: {src} not found (run the sweep first)")
        shutil.copyfile(out_dir / "results.parquet", table)
        shutil.copyfile(out_dir / "summary.md", summary)
    if not table.is_file() or not summary.is_file():
        raise SystemExit(f"publish_sweep: {table} or {summary} not found")
    plots = write_plots(pd.read_parquet(table), results, prefix=f"{name}-")
    text = FIGURE.sub("", summary.read_text()).rstrip("\n") + "\n"
    text += figure_links(plots)
    summary.write_text(text)
    return plots


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("args", nargs="+", help="OUT_DIR NAME, or NAME with --figures")
    ap.add_argument("--figures", action="store_true", help="only draw a committed table's figures")
    a = ap.parse_args(argv)
    if a.figures != (len(a.args) == 1) or len(a.args) > 2:
        ap.error("give OUT_DIR NAME, or --figures NAME")
    name = a.args[-1]
    out_dir = None if a.figures else Path(a.args[0])
    for p in publish(name, out_dir):
        print(f"wrote {p}")


if __name__ == "__main__":
    main(sys.argv[1:])
