"""The fleet scaling plot of ``swarmpark bench`` (apps/bench/plots.py) is drawn from rows."""

from swarmpark.apps.bench.plots import scaling_png


def test_scaling_plot_is_written(tmp_path):
    rows = [
        {
            "N": n,
            "first_tick_ms": 4.0 * n,
            "planning_max_ms": n,
            "steady_mean_ms": n / 10,
            "steady_p99_ms": n / 8,
            "control_period_ms": 50.0,
        }
        for n in (10, 100, 1000)
    ]
    out = scaling_png(rows, tmp_path / "img" / "scaling.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rvo = [dict(r, steady_mean_ms=r["steady_mean_ms"] * 1.5) for r in rows]
    both = scaling_png(rows, tmp_path / "both.png", rvo)
    assert (
        both.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and both.stat().st_size != out.stat().st_size
    )
