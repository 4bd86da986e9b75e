"""scripts/sweep_diff.py: two runs of a sweep compared site by site."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from helpers import load_script

diff_mod = load_script("sweep_diff")


def _runs(parked, times, deadlocks=(0, 0, 0)):
    return pd.DataFrame(
        {
            "kind": ["door", "door", "hangar"],
            "seed": [1000, 1001, 1000],
            "param.perturb.draw": [1, 1, 1],
            "n_robots": [4, 10, 6],
            "n_parked": parked,
            "success": [p == n for p, n in zip(parked, (4, 10, 6), strict=True)],
            "time_to_park_s": times,
            "n_collisions": [0, 0, 0],
            "n_deadlocks": list(deadlocks),
        }
    )


def test_the_diff_counts_both_sides_on_the_runs_they_share():
    before = _runs([4, 8, 6], [40.0, np.nan, 60.0], deadlocks=(1, 5, 0))
    after = _runs([4, 10, 6], [40.0, 90.0, 45.0], deadlocks=(1, 2, 0)).iloc[[1, 2, 0]]
    s, runs = diff_mod.diff(before, after)
    assert s["runs"] == 3 and s["skids"] == 20
    assert (s["parked_runs_before"], s["parked_runs_after"]) == (2, 3)
    assert (s["parked_skids_before"], s["parked_skids_after"]) == (18, 20)
    assert (s["deadlocks_before"], s["deadlocks_after"]) == (6, 3)
    # Parked both ways: the 4-skid door (same time) and the hangar (0.75): geometric mean.
    assert s["parked_both"] == 2
    assert s["time_ratio"] == pytest.approx(np.sqrt(0.75))
    changed = runs[runs.changed]
    assert sorted(zip(changed.kind, changed.seed, strict=True)) == [
        ("door", 1001),
        ("hangar", 1000),
    ]
    # A sweep run on part of the other's sites compares on those.
    s, _ = diff_mod.diff(before, after.iloc[:1])
    assert s["runs"] == 1


def test_two_fleet_sizes_of_one_seed_are_two_sites():
    # A sweep with `robots: [4, 10]` makes a site of each size from one seed: matched on kind
    # and seed alone, each run was compared with both sizes' runs on the other side.
    before = _runs([4, 8, 6], [40.0, np.nan, 60.0]).assign(seed=1000, robots_asked=[4, 10, 6])
    after = before.assign(n_parked=[4, 10, 6], success=True, time_to_park_s=[40.0, 90.0, 60.0])
    s, runs = diff_mod.diff(before, after)
    assert s["runs"] == 3 and s["skids"] == 20
    assert (s["parked_skids_before"], s["parked_skids_after"]) == (18, 20)
    assert runs[runs.changed].robots_asked.tolist() == [10]


def test_the_diff_refuses_what_is_not_a_pair_of_sweep_results(tmp_path, capsys):
    runs = _runs([4, 10, 6], [40.0, 90.0, 45.0])
    with pytest.raises(ValueError, match="before: not a sweep's results .*n_parked"):
        diff_mod.diff(runs.drop(columns="n_parked"), runs)
    with pytest.raises(ValueError, match=r"not the same parameters \(param.perturb.draw on"):
        diff_mod.diff(runs, runs.drop(columns="param.perturb.draw"))
    other = runs.assign(seed=runs.seed + 4000)
    with pytest.raises(ValueError, match="no site in common"):
        diff_mod.diff(runs, other)
    path = tmp_path / "a.parquet"
    runs.to_parquet(path)
    with pytest.raises(SystemExit) as exc:
        diff_mod.main([str(path), str(tmp_path / "missing.parquet")])
    assert exc.value.code == 2
    assert "after: no such file" in capsys.readouterr().err
    diff_mod.main([str(path), str(path)])
    assert "0 of 3 runs changed" in capsys.readouterr().out


def test_pairs_are_pooled_and_tested_per_site(tmp_path, capsys):
    # Two pairs: the unperturbed runs, then a draw; the sites are paired across both.
    before = _runs([4, 8, 6], [40.0, np.nan, 60.0])
    after = _runs([4, 10, 5], [40.0, 90.0, np.nan])
    plain_b, plain_a = (
        before.drop(columns="param.perturb.draw"),
        after.drop(columns="param.perturb.draw"),
    )
    runs = pd.concat([diff_mod.diff(before, after)[1], diff_mod.diff(plain_b, plain_a)[1]])
    p = diff_mod.pooled(runs)
    assert p["runs"] == 6 and p["skids"] == 40
    assert (p["parked_runs_before"], p["parked_runs_after"]) == (4, 4)
    assert (p["parked_skids_before"], p["parked_skids_after"]) == (36, 38)
    # Per site over both runs: door 1000 0, door 1001 +4, hangar 1000 -2.
    assert p["sites"] == 3
    assert p["site_gain_mean"] == pytest.approx(2 / 3)
    assert p["site_gain_se"] == pytest.approx(np.std([0, 4, -2], ddof=1) / np.sqrt(3))
    assert (p["sites_gained"], p["sites_lost"]) == (1, 1)
    assert p["parked_both"] == 2 and p["time_ratio"] == pytest.approx(1.0)
    # Per kind: two door sites (two runs each), one hangar.
    k = p["by_kind"]
    assert k.loc["door"].tolist() == [4, 28, 2, 4, 24, 28]
    assert k.loc["hangar"].tolist() == [2, 12, 2, 0, 12, 10]
    paths = []
    for k, frame in enumerate((before, after, plain_b, plain_a)):
        paths.append(tmp_path / f"{k}.parquet")
        frame.to_parquet(paths[-1])
    diff_mod.main([str(x) for x in paths])
    out = capsys.readouterr().out
    assert "== pooled: 6 runs, 40 skids" in out
    assert "skids parked:      36 before, 38 after" in out
    assert "mean +0.67 (standard error 1.76) over 3 sites; 1 gained, 1 lost" in out
    assert "per kind of site:" in out
    with pytest.raises(SystemExit) as exc:
        diff_mod.main([str(x) for x in paths[:3]])
    assert exc.value.code == 2
    assert "files: give BEFORE AFTER pairs (got 3 files)" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        diff_mod.main([str(paths[0]), str(paths[1]), str(paths[0]), str(paths[3])])
    assert exc.value.code == 2
    assert "not the same parameters (param.perturb.draw on one side) (pair 2)" in (
        capsys.readouterr().err
    )
