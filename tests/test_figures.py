"""`swarmpark figures`: one command writes every docs figure and table and fidelity.md."""

import re

import pytest

from swarmpark.apps.cli import main
from swarmpark.apps.figures import replace_block

PNGS = [
    "formation_errors.png",
    "formation_paths.png",
    "formation_velocity.png",
    "layout_methods.png",
    "hangar-park.png",
    "sensing_localization.png",
    "sensing_map.png",
]


@pytest.mark.slow
def test_figures_quick_writes_every_file_and_a_table_with_numbers(tmp_path, capsys):
    (tmp_path / "formation.md").write_text(
        "intro\n<!-- figures:formation-table -->\nstale\n<!-- /figures:formation-table -->\nend\n"
    )
    assert main(["figures", "--quick", "--out", str(tmp_path)]) == 0
    for name in PNGS:
        f = tmp_path / "img" / name
        assert f.is_file() and f.stat().st_size > 10_000, name
    for name in ("formation_table.md", "sensing_table.md"):
        assert "|" in (tmp_path / "img" / name).read_text()
    assert "| hallway-fig7 | euclidean |" in (tmp_path / "assignment-comparison.md").read_text()
    page = (tmp_path / "formation.md").read_text()
    assert "stale" not in page and "Table 1" in page and page.endswith("end\n")
    table = (tmp_path / "fidelity.md").read_text()
    assert "--quick" in table  # says its numbers are not the docs'
    rows = [ln for ln in table.splitlines() if ln.startswith("| ") and "---" not in ln][1:]
    assert len(rows) >= 12
    for ln in rows:
        cells = [c.strip() for c in ln.strip("|").split(" | ")]
        assert len(cells) == 4, ln
        assert re.search(r"\d", cells[3]), ln  # swarmpark's value is a computed number
    text = "\n".join(rows)
    for item in ("Fig. 7", "Fig. 8", "Fig. 11", "Fig. 9", "Fig. 6", "AMCL", "capacity", "spread"):
        assert item in text, item
    printed = capsys.readouterr().out
    assert str(tmp_path / "fidelity.md") in printed


def test_replace_block_only_touches_the_marked_block(tmp_path):
    page = tmp_path / "p.md"
    page.write_text("a\n<!-- figures:t -->\nold\n<!-- /figures:t -->\nb\n")
    assert replace_block(page, "t", "new 1\nnew 2\n")
    assert page.read_text() == "a\n<!-- figures:t -->\nnew 1\nnew 2\n<!-- /figures:t -->\nb\n"
    assert not replace_block(page, "other", "x")
    assert not replace_block(tmp_path / "missing.md", "t", "x")
