"""Map files that are not what they claim: every one is refused with one clean MapError line
naming the file or key, and nothing else is raised (no PIL, Unicode, Index or memory error)."""

import shutil
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
import yaml
from helpers import ROOT

from swarmpark.core.gridmap import MapError, grid_from_walls, load_map_yaml
from swarmpark.core.limits import MAX_GRID_CELLS

MAPS = ROOT / "scenarios" / "maps"


def _png_header_only(width: int, height: int) -> bytes:
    """A PNG whose header claims ``width`` x ``height`` grey pixels and whose data is one
    tiny compressed row (a decompression bomb's header: it must never be expanded)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b"\x00" * 16))
        + chunk(b"IEND", b"")
    )


def _copy_map(tmp_path: Path) -> tuple[Path, dict]:
    shutil.copy(MAPS / "elevator.pgm", tmp_path / "elevator.pgm")
    meta = yaml.safe_load((MAPS / "elevator.yaml").read_text())
    return tmp_path / "map.yaml", meta


def _image_cases():
    pgm = (MAPS / "elevator.pgm").read_bytes()
    return {
        "empty": b"",
        "truncated": pgm[: len(pgm) // 3],
        "header-only": pgm[:15],
        "zero-size-pgm": b"P5\n0 0\n255\n",
        "negative-size-pgm": b"P5\n-4 3\n255\n" + b"\x00" * 12,
        "ascii-p2": b"P2\n2 2\n255\n0 255\n255 0\n",
        "colour-p6-truncated": b"P6\n4 4\n255\n" + b"\x00" * 7,
        "png-bomb": _png_header_only(60_000, 60_000),
        "text": b"this is not an image\n",
    }


@pytest.mark.parametrize("case", sorted(_image_cases()))
def test_broken_images_are_refused_cleanly(tmp_path, case):
    path, meta = _copy_map(tmp_path)
    (tmp_path / "broken.img").write_bytes(_image_cases()[case])
    meta["image"] = "broken.img"
    path.write_text(yaml.safe_dump(meta))
    try:
        grid = load_map_yaml(path)
    except MapError as exc:
        msg = str(exc)
        assert "\n" not in msg and "broken.img" in msg, msg
    else:
        # Only a well-formed picture may load (the P2 case is a valid 2 x 2 ASCII PGM).
        assert case == "ascii-p2" and grid.shape == (2, 2)


YAML_CASES = {
    "not-utf8": b"image: elevator.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n# \xff\xfe\n",
    "nested": ("a: " + "[" * 2000 + "]" * 2000 + "\n").encode(),
    "origin-strings": b"image: elevator.pgm\nresolution: 0.05\norigin: [a, b, c]\n",
    "origin-nan": b"image: elevator.pgm\nresolution: 0.05\norigin: [.nan, 0, 0]\n",
    "origin-inf": b"image: elevator.pgm\nresolution: 0.05\norigin: [0, -.inf, 0]\n",
    "resolution-tiny": b"image: elevator.pgm\nresolution: 1.0e-6\norigin: [0, 0, 0]\n",
    "resolution-string": b"image: elevator.pgm\nresolution: fine\norigin: [0, 0, 0]\n",
    "resolution-nan": b"image: elevator.pgm\nresolution: .nan\norigin: [0, 0, 0]\n",
    "negate-2": b"image: elevator.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 2\n",
    "list": b"- 1\n- 2\n",
    "empty": b"",
}


@pytest.mark.parametrize("case", sorted(YAML_CASES))
def test_broken_map_yaml_is_refused_cleanly(tmp_path, case):
    shutil.copy(MAPS / "elevator.pgm", tmp_path / "elevator.pgm")
    path = tmp_path / "map.yaml"
    path.write_bytes(YAML_CASES[case])
    with pytest.raises(MapError) as info:
        load_map_yaml(path)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith("map"), msg


def test_a_seeded_byte_mutator_never_escapes_map_error(tmp_path):
    """200 random corruptions of the suite's map image and YAML: each loads or is refused
    with a MapError, never another exception."""
    rng = np.random.default_rng(7)
    pgm = bytearray((MAPS / "room-built.pgm").read_bytes())
    text = (MAPS / "room-built.yaml").read_bytes()
    outcomes = {"loaded": 0, "refused": 0}
    for k in range(200):
        img, meta = bytearray(pgm), bytearray(text)
        target = img if k % 2 else meta
        for _ in range(int(rng.integers(1, 6))):
            op = rng.integers(3)
            pos = int(rng.integers(0, max(len(target), 1)))
            if op == 0 and len(target):
                target[pos] = int(rng.integers(0, 256))
            elif op == 1:
                del target[pos:]
            else:
                target[pos:pos] = bytes(rng.integers(0, 256, int(rng.integers(1, 8)), np.uint8))
        (tmp_path / "room-built.pgm").write_bytes(bytes(img))
        (tmp_path / "map.yaml").write_bytes(bytes(meta))
        try:
            load_map_yaml(tmp_path / "map.yaml")
            outcomes["loaded"] += 1
        except MapError as exc:
            assert "\n" not in str(exc), str(exc)
            outcomes["refused"] += 1
    assert outcomes["refused"] > 0 and sum(outcomes.values()) == 200


def test_grids_over_the_cell_budget_are_refused_before_allocation():
    side = int(np.sqrt(MAX_GRID_CELLS)) + 10
    with pytest.raises(MapError, match="over the budget"):
        grid_from_walls((side * 0.05, side * 0.05), 0.05, [])
    with pytest.raises(MapError, match=r"map.size_m\[0\] must be <= 10000.0 \(got 1e\+20\)"):
        grid_from_walls((1e20, 10.0), 0.05, [])
    with pytest.raises(MapError, match="map.resolution_m must be >= 0.001"):
        grid_from_walls((10.0, 10.0), 1e-6, [])
