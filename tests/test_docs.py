"""The written record: every relative link of the README, the docs and the committed sweep
results points at a file that is there; a sweep's summary is published with its figures."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from helpers import ROOT, load_script

from swarmpark.apps.sweep_report import records_table

LINK = re.compile(r"\]\(([^)\s]+)\)")


def _relative_links(path: Path) -> list[str]:
    out = []
    for target in LINK.findall(path.read_text()):
        if re.match(r"[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
            continue  # a web address, mailto:, or an anchor in the same page
        out.append(target.split("#")[0])
    return out


def _pages() -> list[Path]:
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    return pages + sorted((ROOT / "sweeps" / "results").glob("*.md"))


@pytest.mark.parametrize("page", _pages(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_points_at_a_file(page):
    missing = [t for t in _relative_links(page) if not (page.parent / t).exists()]
    assert not missing, f"{page.relative_to(ROOT)}: links to missing files {missing}"


def test_a_published_summary_links_its_own_figures(tmp_path):
    out, results = tmp_path / "out", tmp_path / "results"
    out.mkdir()
    results.mkdir()
    for jid, kind, n, parked in (("a", "door", 4, 4), ("b", "hangar", 10, 7)):
        robots = {f"r{k}": {"commanded": True, "parked": k < parked} for k in range(n)}
        res = {"success": parked == n, "collisions": [], "deadlocks": [], "robots": robots,
               "time_to_park_s": 15.0 if parked == n else None, "lower_bound_s": 10.0,
               "time_lost_s": {"queued": 3.0 * n}}  # fmt: skip
        job = {"job_id": jid, "kind": kind, "source": f"generate:{kind}", "seed": 0,
               "robots": None, "duration_s": None, "params": {}}  # fmt: skip
        rec = {"job": job, "error": None, "wall_s": 1.0, "attempts": 1, "result": res}
        (out / "records").mkdir(exist_ok=True)
        (out / "records" / f"{jid}.json").write_text(json.dumps(rec))
    table = records_table(out, ["a", "b"])
    table.to_parquet(out / "results.parquet", index=False)
    (out / "summary.md").write_text("# Sweep s\n\n![success](success.png)\n")
    plots = load_script("publish_sweep").publish("s", out, results)
    names = sorted(p.name for p in plots)
    assert names == ["s-success.png", "s-time_lost.png", "s-time_over_bound.png"]
    assert all((results / n).is_file() for n in names)
    text = (results / "s.md").read_text()
    assert "](success.png)" not in text
    linked = ["s-success.png", "s-time_over_bound.png", "s-time_lost.png"]
    assert _relative_links(results / "s.md") == linked
    assert (results / "s.parquet").is_file()
    # Again, from the committed table alone: the same figures, linked once.
    load_script("publish_sweep").publish("s", None, results)
    assert _relative_links(results / "s.md") == linked
