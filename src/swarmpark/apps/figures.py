"""``swarmpark figures``: regenerate the figures and tables of the docs, and ``fidelity.md``.

One command makes everything the docs show from runs, so the docs cannot drift from the code:

- ``img/formation_*.png``, ``img/formation_table.md``: Liu, Sun & Zhu (2010) Table 1 / Fig. 6
  and the Table 2 / Fig. 9 experiment (:func:`~swarmpark.control.formation.paper_report.run_paper`);
- ``img/layout_methods.png``: the three layout methods on the L-shaped bay of docs/layout.md;
- ``img/hangar-park.png``: the README's demo run;
- ``img/sensing_localization.png``, ``img/sensing_map.png``, ``img/sensing_table.md``: the
  localization and mapping runs of docs/sensing.md (:mod:`.figures_sensing`);
- ``assignment-comparison.md``: every park scenario once per assignment cost (as
  ``swarmpark compare``);
- ``fidelity.md``: for each item the three papers give a number or a behaviour for, where it
  is implemented, the paper's value and swarmpark's, computed here.

Generated tables are also written into the docs pages of ``out`` that mark a block with
``<!-- figures:NAME -->`` ... ``<!-- /figures:NAME -->``. ``docs/img/ui.png`` is a browser
screenshot (tests/test_browser.py) and is not made here.

``quick`` runs every scenario for :data:`QUICK_DURATION_S` of simulated time and compares
three costs on the Fig. 6 and Fig. 7 scenarios only: the files and tables are all written, the numbers are not the
docs' (the table says so).
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from swarmpark.world.scenario import Scenario, build_world, load_scenario

__all__ = ["FidelityRow", "run_figures", "fidelity_markdown", "replace_block"]

#: Simulated time of every scenario run with ``quick``.
QUICK_DURATION_S = 4.0
#: The scenarios directory of the repository.
SCENARIOS = Path(__file__).resolve().parents[3] / "scenarios"
#: 2018 Sect. 3.2 / 2015 Sect. 3.1 comparison: boundaries (m) and skid count (None: capacity).
LAYOUT_CASES = {
    "box 8 x 6 m, 9 skids": ([[0, 0], [8, 0], [8, 6], [0, 6]], 9),
    "triangle 8 m base, 6 m high": ([[0, 0], [8, 0], [4, 6]], None),
    "diamond 8 x 8 m": ([[4, 0], [8, 4], [4, 8], [0, 4]], None),
}
#: The L-shaped bay of docs/layout.md (24 skids of 1.2 x 0.8 m).
L_BAY = [[0, 0], [14, 0], [14, 5], [9, 5], [9, 11], [0, 11]]
LAYOUT_METHODS = ("stacking", "potential", "convex")


#: Fixed notes under the table (what the table is not).
NOTES = (
    "Notes. Where the two value columns disagree the gap is open (issue 21) unless the linked "
    "page explains it (Liu Fig. 9: docs/formation.md). Liu, Sun & Zhu have no Fig. 10: their "
    "formation errors are Fig. 6 and the timing Fig. 9. The paper values are the papers' "
    "words where they give no number. `docs/img/ui.png` is a browser screenshot "
    "(tests/test_browser.py) and is not made by this command.",
)


@dataclass(frozen=True)
class FidelityRow:
    """One line of ``fidelity.md``."""

    item: str
    module: str
    paper: str
    swarmpark: str


def _scenario(name: str, quick: bool, *, rvo: bool = False, **update) -> Scenario:
    """Scenario ``name``, cut short if ``quick``, with ``update``; ``rvo``: with
    ``navigation.avoidance: rvo`` (the papers' figures are reproduced with their method, also
    where the scenario file runs the default stack)."""
    scn = load_scenario(SCENARIOS / f"{name}.yaml")
    if rvo:
        update["navigation"] = scn.navigation.model_copy(update={"avoidance": "rvo"})
    if quick:  # cut short: what would happen after the end is left out
        cut = min(scn.duration_s, QUICK_DURATION_S)
        update["duration_s"] = cut
        update["commands"] = [c for c in scn.commands if c.at_s <= cut]
        update["sensing"] = scn.sensing.model_copy(
            update={"kidnap": [k for k in scn.sensing.kidnap if k.at_s <= cut]}
        )
    return scn.model_copy(update=update) if update else scn


def _run(name: str, quick: bool, **kw):
    from swarmpark.apps.run import run_world

    return run_world(build_world(_scenario(name, quick, **kw)))


def _fmt(v, spec: str = ".1f", none: str = "-") -> str:
    return none if v is None else format(v, spec)


def _outcome(r: dict) -> str:
    """Success, time to park and collisions of a run result, in words."""
    if r["success"]:
        return f"parked in {_fmt(r['time_to_park_s'])} s, {len(r['collisions'])} collisions"
    return (
        f"NOT parked at {r['sim_time_s']:.0f} s ({len(r['deadlocks'])} deadlocks, "
        f"{len(r['collisions'])} collisions)"
    )


# --------------------------------------------------------------------------- formation


def _formation(img: Path, quick: bool) -> list[FidelityRow]:
    from swarmpark.control.formation.paper_report import run_paper

    rep = run_paper(img)
    t1, ex = rep["table1"], rep["experiment"]
    order = sorted(t1, key=lambda m: t1[m]["integral_m2s"])
    mod = "control/formation/planner.py, leader_follower.py, metrics.py"
    rows = [
        FidelityRow(
            "Liu 2010 Table 1 / Fig. 6: formation error of three methods (six robots)",
            mod,
            "with formation < leader-follower < without formation",
            " < ".join(f"{m} {t1[m]['integral_m2s']:.3g} m²s" for m in order)
            + f"; max pair error {1e3 * t1['formation']['max_pair_error_m']:.1f} mm (proposed)",
        ),
        FidelityRow(
            "Liu 2010 Table 2 / Fig. 9: moving obstacle, stop and retreat (two robots)",
            "control/formation/online.py, paper.py",
            "seen at 5 s; stop and retreat at 8 s; resume 15 s; step b at 20 s",
            f"seen at {ex['obstacle_appears_s']:.0f} s; "
            + ", ".join(f"{d['decision']} at {d['t_obs_s']:.0f} s" for d in ex["decisions"])
            + f"; resume {_fmt(ex['resume_s'], '.0f')} s; step b at "
            f"{_fmt(ex['formation_b_reached_s'], '.0f')} s (see docs/formation.md); "
            f"closest {ex['min_obstacle_distance_m']:.2f} m >= D_obs {ex['d_obs_m']:.1f} m",
        ),
    ]
    r = _run("formation-person-blocks", quick).result
    fe = (r.get("formation_error") or [{}])[0]
    decisions = ", ".join(f"{d['decision']} {d['t_s']:.0f} s" for d in fe.get("online", []))
    rows.append(
        FidelityRow(
            "Liu 2010 Sect. II.D: a person stops on the path (no wait or retreat clears it)",
            "control/formation/online.py, run.py",
            "not covered (stop or reverse always resolves in the paper)",
            f"{decisions or 'no decision yet'}; {_outcome(r)}",
        )
    )
    return rows


# --------------------------------------------------------------------------- layout


def _layout_png(img: Path) -> None:
    from swarmpark.apps.cli_layout import _draw
    from swarmpark.core.geometry import Footprint
    from swarmpark.layout import LayoutError, layout

    fps = [Footprint(1.2, 0.8, pivot_from_rear_m=0.3)] * 24
    panels = []
    for m in LAYOUT_METHODS:
        t0 = time.perf_counter()
        try:
            res = layout(L_BAY, fps, method=m)
            res.report["solve_time_s"] = time.perf_counter() - t0
            panels.append((m, res, None))
        except LayoutError as exc:
            panels.append((m, None, str(exc)))
    _draw(str(img / "layout_methods.png"), panels, L_BAY, None, fps)


def _centroid_spacing(boundary, fp, count: int) -> float:
    """Closest pair of the potential layout with the paper's centroid field (eqs. 2-3 on
    centroid distances), from the same stacking start: the value before issue 21."""
    from swarmpark.layout import potential
    from swarmpark.layout.methods import stack_best
    from swarmpark.layout.region import make_region, make_skids, rect_gaps

    region = make_region(boundary, None, 0.0, 0.3)
    skids = make_skids([fp] * count)
    centres, _ = potential.spread(
        region, skids, stack_best(region, skids, count).centres, variant="centroid"
    )
    return float(rect_gaps(centres, skids.half).min())


def _layout(img: Path, quick: bool) -> list[FidelityRow]:
    from swarmpark.core.geometry import Footprint
    from swarmpark.layout import LayoutError, capacity, layout

    _layout_png(img)
    fp = Footprint(1.2, 0.8)
    rows = []
    for name, (boundary, count) in LAYOUT_CASES.items():
        cells = []
        for m in LAYOUT_METHODS:
            try:
                if count is None:
                    cells.append(f"{m} {len(capacity(boundary, fp, method=m).poses)}")
                else:
                    spacing = layout(boundary, [fp] * count, method=m).report["min_spacing_m"]
                    cells.append(f"{m} {_fmt(spacing, '.2f')} m")
            except LayoutError as exc:
                cells.append(f"{m} refused ({str(exc)[:60]})")
        if count is not None:
            cells.insert(
                2,
                f"potential with the paper's centroid field {_centroid_spacing(boundary, fp, count):.2f} m",
            )
        if count is None:
            rows.append(
                FidelityRow(
                    f"Hing 2015 Sect. 3.1 / Fig. 2: capacity, {name} (1.2 x 0.8 m skids)",
                    "layout/stacking.py, potential.py, convex.py",
                    "convex floor planning packs the boundary (at least stacking's count)",
                    "skids that fit: " + ", ".join(cells),
                )
            )
        else:
            rows.append(
                FidelityRow(
                    f"Hing 2018 Sect. 3.2 / Fig. 4: spread of the goals, {name}",
                    "layout/stacking.py, potential.py, convex.py",
                    "stacking packs; the potential field pushes goals apart to fill the "
                    "boundary; convex maximizes the spacing",
                    # (potential: distances between footprints, layout/potential.py says why)
                    "closest pair: " + ", ".join(cells),
                )
            )
    return rows


# --------------------------------------------------------------------------- navigation


def _assignment(out: Path, quick: bool, compare: bool) -> list[FidelityRow]:
    """The cost comparison (all park scenarios; without ``compare`` or when quick only the
    Fig. 6 and Fig. 7 ones, and the page is not rewritten) and the Fig. 6/7 rows."""
    from swarmpark.apps.compare import compare_costs, markdown_table

    figs = [
        SCENARIOS / "hallway-fig7.yaml",
        SCENARIOS / "hallway-side-room-fig7.yaml",
        SCENARIOS / "dead-end-fig6.yaml",
    ]
    if quick:
        rows = compare_costs(
            figs,
            costs=("sequential", "euclidean", "formation"),
            workers=1,
            duration_s=QUICK_DURATION_S,
        )
    else:
        rows = compare_costs(sorted(SCENARIOS.glob("*.yaml")) if compare else figs, workers=2)
    if quick or compare:
        (out / "assignment-comparison.md").write_text(
            "# Assignment costs on the scenario suite\n\n"
            "Generated by `swarmpark figures`"
            + (f" --quick (every run cut at {QUICK_DURATION_S:g} s)" if quick else "")
            + ": every park scenario, once per assignment cost, everything else unchanged. "
            "*ratio* is time to park over the lower bound (bottleneck assignment of shortest "
            "free-space paths at full speed).\n\n" + markdown_table(rows)
        )
    by = {(r["scenario"], r["cost"]): r for r in rows}

    def cell(scn: str, cost: str) -> str:
        r = by.get((scn, cost))
        if r is None:
            return f"{cost}: not run"
        if r["success"]:
            return f"{cost}: parked in {r['time_to_park_s']:.1f} s"
        return f"{cost}: NOT parked ({r['deadlocks']} deadlocks)"

    return [
        FidelityRow(
            "Hing 2018 Fig. 7: hallway, Euclidean cost vs formation cost",
            "assign/, supervisor (re-assignment every tick)",
            "Euclidean costs tie and can block; the formation cost does not",
            "; ".join(cell("hallway-fig7", c) for c in ("euclidean", "formation")),
        ),
        FidelityRow(
            "Hing 2018 Fig. 7, Euclidean wrong rather than tied: hallway, the second skid "
            "starts in a room behind a wall",
            "assign.py, scenarios/hallway-side-room-fig7.yaml",
            "the Euclidean assignment lets a parked skid block the hallway; the formation "
            "cost does not",
            "; ".join(
                cell("hallway-side-room-fig7", c) for c in ("euclidean", "formation", "path")
            ),
        ),
        FidelityRow(
            "Hing 2018 Fig. 6: dead-end bay, a parked skid blocks the rest",
            "assign/, supervisor fill order (layout fill_order)",
            "sequential assignment blocks; formation cost + deepest first parks all",
            "; ".join(cell("dead-end-fig6", c) for c in ("sequential", "formation")),
        ),
    ]


def _navigation(img: Path, quick: bool) -> list[FidelityRow]:
    from swarmpark.apps.plot import plot_run

    rows = []
    r = _run("room-swap-fig8", quick).result
    rows.append(
        FidelityRow(
            "Hing 2018 Fig. 8: two skids swap places within parked formations (RVO)",
            "control/orca/, control/nav/",
            "the swap succeeds, no collision",
            f"{_outcome(r)}, closest {_fmt(r['min_clearance_m'], '.2f')} m",
        )
    )
    r = _run("head-on-fig11", quick, rvo=True).result
    low = r["robots"]["top"]["max_lateral_deviation_m"]
    high = r["robots"]["bottom"]["max_lateral_deviation_m"]
    rows.append(
        FidelityRow(
            "Hing 2018 Fig. 11: head-on pass, priorities",
            "control/orca/ (priorities)",
            "the lower-priority skid takes the larger avoidance route",
            f"largest lateral deviation: low priority {_fmt(low, '.2f')} m, high priority "
            f"{_fmt(high, '.2f')} m; {_outcome(r)}",
        )
    )
    r = _run("pass-through-fig6", quick, rvo=True).result
    rows.append(
        FidelityRow(
            "Hing 2015 Fig. 6 (bottom): a skid drives through a parked 3 x 3 formation",
            "control/orca/, control/nav/",
            "the parked skids make room and return",
            _outcome(r),
        )
    )
    planned = _run("u-trap-2015", quick).result
    pure = _run("experimental/u-trap-2015-pure-pf", quick).result
    x, y, _ = pure["robots"]["r1"]["final_pose"]
    rows.append(
        FidelityRow(
            "Hing 2015 Sect. 4 / 2018 Sect. 3.4: pure potential field (no planner) stops in a "
            "local minimum; planning first overcomes it",
            "control/nav/pure_pf.py (navigation.mode: pure-pf), control/nav/navigator.py",
            "pure field: some skids stay in local minima; planner + field: parks",
            f"U-shaped crate (u-trap-2015): pure-pf {_outcome(pure)}, stopped at "
            f"({x:.1f}, {y:.1f}) m, {pure['robots']['r1']['final_position_error_m']:.1f} m "
            f"from its goal; planner + field {_outcome(planned)}",
        )
    )
    out = _run("hangar-park", quick)
    plot_run(out, img / "hangar-park.png")
    return rows


# --------------------------------------------------------------------------- fidelity.md


def fidelity_markdown(rows: list[FidelityRow], quick: bool) -> str:
    """The fidelity table as a markdown page."""
    esc = lambda s: s.replace("|", "\\|")  # noqa: E731
    lines = [
        "# Fidelity to the papers",
        "",
        "Generated by `swarmpark figures`"
        + (
            f" --quick: every scenario cut at {QUICK_DURATION_S:g} s, NOT the docs' numbers"
            if quick
            else ""
        )
        + ". Papers: Hing et al. 2015 (parking skids), Hing et al. 2018 "
        "(swarm parking), Liu, Sun & Zhu 2010 (formation motion planning), in "
        "shared/papers. The *swarmpark* column is computed by the command (seed 0); "
        "modules are under `src/swarmpark/`.",
        "",
        "| paper item | implemented in | paper | swarmpark |",
        "|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {esc(r.item)} | `{esc(r.module)}` | {esc(r.paper)} | {esc(r.swarmpark)} |")
    lines += ["", *NOTES]
    return "\n".join(lines) + "\n"


def replace_block(page: Path, name: str, text: str) -> bool:
    """Replace the ``<!-- figures:name -->`` block of ``page`` with ``text``; False if the page
    or the block does not exist."""
    if not page.is_file():
        return False
    src = page.read_text()
    pat = re.compile(
        rf"(<!-- figures:{re.escape(name)} -->\n).*?(<!-- /figures:{re.escape(name)} -->)", re.S
    )
    if not pat.search(src):
        return False
    page.write_text(pat.sub(lambda m: m.group(1) + text.rstrip("\n") + "\n" + m.group(2), src))
    return True


def run_figures(
    out: str | Path,
    *,
    quick: bool = False,
    compare: bool = True,
    progress: Callable[[str], None] | None = None,
) -> dict:
    """Regenerate everything into ``out`` (``out/img`` for figures); returns the written files
    and the fidelity rows. ``compare=False`` leaves ``assignment-comparison.md`` alone (its
    28 runs are most of the time) and compares costs on the Fig. 6/7 scenarios only."""
    from swarmpark.apps.figures_sensing import sensing

    out = Path(out)
    img = out / "img"
    img.mkdir(parents=True, exist_ok=True)
    say = progress or (lambda _msg: None)
    rows: list[FidelityRow] = []
    for name, step in (
        ("layout", lambda: _layout(img, quick)),
        ("assignment", lambda: _assignment(out, quick, compare)),
        ("navigation", lambda: _navigation(img, quick)),
        ("formation", lambda: _formation(img, quick)),
        ("sensing", lambda: sensing(img, quick, _scenario)),
    ):
        say(f"figures: {name} ...")
        got = step()
        rows.extend(FidelityRow(**r) if isinstance(r, dict) else r for r in got)
    replace_block(out / "formation.md", "formation-table", (img / "formation_table.md").read_text())
    replace_block(out / "sensing.md", "sensing-table", (img / "sensing_table.md").read_text())
    page = out / "fidelity.md"
    page.write_text(fidelity_markdown(rows, quick))
    files = sorted(
        str(p) for p in [*img.iterdir(), page, out / "assignment-comparison.md"] if p.exists()
    )
    return {"files": files, "rows": [r.__dict__ for r in rows]}
