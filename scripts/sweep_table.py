"""Print a sweep's per-kind success table from its Parquet file (the table in docs/sweeps.md).

python scripts/sweep_table.py sweeps/out/generated-100/results.parquet
"""

import sys

import pandas as pd

from swarmpark.apps.sweep_report import markdown, summarize

df = pd.read_parquet(
    sys.argv[1] if len(sys.argv) > 1 else "sweeps/out/generated-100/results.parquet"
)
tables = summarize(df)
print(markdown(tables["overall"]))
print(markdown(tables["kind"]), end="")
