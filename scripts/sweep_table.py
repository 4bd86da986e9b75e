"""Print a sweep's overall and per-kind tables from its Parquet file (as in docs/sweeps.md).

    python scripts/sweep_table.py [sweeps/results/generated-100.parquet]

The committed table came from ``swarmpark sweep sweeps/generated-100.yaml --out DIR``
(``DIR/results.parquet``).
"""

import sys

import pandas as pd

from swarmpark.apps.sweep_report import markdown, summarize

path = sys.argv[1] if len(sys.argv) > 1 else "sweeps/results/generated-100.parquet"
tables = summarize(pd.read_parquet(path))
print(markdown(tables["overall"]))
print(markdown(tables["kind"]), end="")
if "fleet" in tables:  # fleets of more than one size band
    print("\n" + markdown(tables["fleet"]), end="")
