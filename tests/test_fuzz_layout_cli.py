"""`swarmpark layout` arguments a fuzzer found harmful: each ends in exit 2 with one line naming
the option and the value (no traceback, no hang, no memory blow-up), and a seeded mutator over
the arguments finds no other outcome."""

import numpy as np
import pytest

from swarmpark.apps.cli_layout import layout_command

ROOM = "[[0,0],[8,0],[8,6],[0,6]]"
FP = ["--footprint", "1.2", "0.8"]

CASES = {
    "huge count": (["--count", "1000000000", *FP], "--count: at most 5000 skids"),
    "infinite footprint": (["--count", "5", "--footprint", "inf", "0.8"], "--footprint"),
    "tiny footprint": (["--count", "5", "--footprint", "1e-9", "1e-9"], "0.01..50.0 m"),
    "huge coordinate": (
        ["--boundary", "[[0,0],[1e20,0],[8,6],[0,6]]", "--count", "3", *FP],
        "+-10000 m",
    ),
    "NaN vertex": (["--boundary", "[[0,0],[NaN,0],[8,6],[0,6]]", "--count", "3", *FP], "finite"),
    "png folder missing": (
        ["--count", "3", *FP, "--png", "/nonexistent-dir/x.png"],
        "does not exist",
    ),
    "png unknown extension": (["--count", "3", *FP, "--png", "x.xyz"], "cannot write 'xyz'"),
    "margin NaN": (["--count", "3", *FP, "--margin-m", "nan"], "--margin-m: must be finite"),
    "heading NaN": (["--count", "3", *FP, "--heading-deg", "nan"], "--heading-deg"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_harmful_arguments_exit_2_with_one_line(capsys, case):
    argv, needle = CASES[case]
    if "--boundary" not in argv:
        argv = ["--boundary", ROOM, *argv]
    code = layout_command(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and needle in err, err


def test_a_seeded_argument_mutator_only_gives_results_or_exit_2(capsys):
    rng = np.random.default_rng(11)
    numbers = ["0", "-1", "1e9", "1e-9", "nan", "inf", "-inf", "1.5", "3", "abc", ""]
    base = ["--boundary", ROOM, "--count", "6", "--footprint", "1.2", "0.8", "--json"]
    codes = []
    for _ in range(60):
        argv = list(base)
        for _ in range(int(rng.integers(1, 3))):
            k = int(rng.choice([3, 5, 6]))
            argv[k] = str(rng.choice(numbers))
        if rng.random() < 0.3:
            argv += ["--margin-m", str(rng.choice(numbers))]
        if rng.random() < 0.3:
            argv += ["--method", str(rng.choice(["stacking", "potential", "convex", "magic"]))]
        try:
            code = layout_command(argv)
        except SystemExit as exc:  # argparse refuses a malformed option with exit 2
            code = exc.code
        err = capsys.readouterr().err
        assert code in (0, 2), (argv, err)
        if code == 2:
            assert err.strip().count("\n") <= 1 and "error" in err, (argv, err)
        codes.append(code)
    assert 0 in codes and 2 in codes
