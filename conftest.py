"""pytest at the repository root: the moved-module aliases are not collected (importing one
warns, on purpose)."""

from swarmpark._moved import MOVED

collect_ignore = ["src/" + old.replace(".", "/") + ".py" for old in MOVED]
