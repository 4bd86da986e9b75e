"""Layers point one way (docs/architecture.md): the math never imports the simulator, the
supervisor, the server or the applications; the supervisor never imports the server."""

import ast
from pathlib import Path

import pytest
from helpers import ROOT

from swarmpark._moved import MOVED

SRC = ROOT / "src" / "swarmpark"
ALIASES = {SRC / (old.removeprefix("swarmpark.").replace(".", "/") + ".py") for old in MOVED}
#: What each layer may import from swarmpark (besides itself).
ALLOWED = {
    "core": set(),
    "plan": {"core"},
    "layout": {"core"},
    "assign": {"core"},
    "metrics": {"core", "plan", "assign"},
    "control": {"core", "plan"},
    "sense": {"core"},
    # The protocol (links/base.py, checked below) needs only core; the concrete links (ROS 2,
    # the fake fleet) sit beside the simulator and read the world and the LIDAR model.
    "links": {"core", "world", "sense"},
    "world": {"core", "layout", "assign", "control"},  # the registries of names
    "sim": {"core", "links", "sense", "world"},
    "supervisor": {
        "core",
        "plan",
        "layout",
        "assign",
        "metrics",
        "control",
        "sense",
        "links",
        "sim",
        "world",
    },
}
#: The one deliberate exception, with its reason: ``sense.amcl`` forwards the old name
#: ``OdometryDrift`` (moved to the simulator) for one release, lazily and with a warning.
EXCEPTIONS = {("sense/amcl/__init__.py", "sim")}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.ImportFrom)
            and node.module
            and node.module.startswith("swarmpark.")
        ):
            out.add(node.module.split(".")[1])
        elif isinstance(node, ast.ImportFrom) and node.module == "swarmpark":
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.Import):
            out.update(a.name.split(".")[1] for a in node.names if a.name.startswith("swarmpark."))
    return out


def _layer(path: Path) -> str:
    rel = path.relative_to(SRC)
    return rel.parts[0].removesuffix(".py")


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_layers_import_only_what_lies_below(layer):
    bad = []
    for path in sorted(SRC.rglob("*.py")):
        if path in ALIASES or _layer(path) != layer:
            continue
        rel = str(path.relative_to(SRC))
        for imported in _imports(path) - {layer, "_moved"} - ALLOWED[layer]:
            if (rel, imported) not in EXCEPTIONS:
                bad.append(f"{rel} imports swarmpark.{imported}")
    assert not bad, bad


def test_the_robot_link_protocol_needs_only_core():
    assert _imports(SRC / "links" / "base.py") - {"links"} <= {"core"}
