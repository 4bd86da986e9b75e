"""Input limits and validators shared by every edge (scenario and map loaders, CLI, API).

One definition of "a usable number", "a grid small enough to allocate" and "a polygon small
enough to process", so that a file, a command-line argument and a request body are refused
for the same reason with the same words: the field, the value, and the limit.

>>> finite_float(2.5, "map.resolution_m")
2.5
>>> finite_float(float("nan"), "goto.pose[0]")
Traceback (most recent call last):
...
ValueError: goto.pose[0] must be a finite number (got nan)
>>> check_grid_cells((10_000, 10_000), "map")
Traceback (most recent call last):
...
ValueError: map: a grid of 10000 x 10000 cells is over the budget of 16000000 cells (use a coarser resolution or a smaller map)
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = [
    "MAX_GRID_CELLS",
    "MAX_POLYGON_VERTICES",
    "MAX_COORDINATE_M",
    "MIN_RESOLUTION_M",
    "MAX_ID_LENGTH",
    "MIN_FOOTPRINT_M",
    "MAX_FOOTPRINT_M",
    "MAX_ROBOTS_PER_COMMAND",
    "finite_float",
    "finite_sequence",
    "check_grid_cells",
    "check_vertices",
    "check_inside",
    "MAX_HEADING_DEG",
    "MAX_DURATION_S",
    "MIN_DT_S",
    "MAX_TICKS",
    "MAX_BODY_BYTES",
    "MAX_PARK_BODY_BYTES",
    "MAX_BOUNDARY_VERTICES",
    "MAX_VIEWERS",
    "MAX_ROBOTS",
]

#: Grids (maps, costmaps) larger than this are refused before anything is allocated: a
#: 200 m x 200 m deck at 5 cm. Each planning field over it is 128 MB of float64.
MAX_GRID_CELLS = 16_000_000
#: A boundary, wall or obstacle polygon may have at most this many vertices (an operator
#: draws tens; a CAD export of a hangar has hundreds).
MAX_POLYGON_VERTICES = 2_000
#: A park boundary may have this many (a surveyed deck outline, densely sampled). The
#: layout of one that large runs for seconds in the server's work pool (about 2 s with a
#: fixed heading, 30 s with ``heading_deg: auto`` on the development machine), never on the
#: path of the e-stop.
MAX_BOUNDARY_VERTICES = 20_000
#: Coordinates beyond this (10 km) are not a site on a ship or in a hangar.
MAX_COORDINATE_M = 10_000.0
#: Cells finer than a millimetre are a typo, not a map.
MIN_RESOLUTION_M = 1e-3
#: A skid footprint side must lie in this range (a centimetre is a typo; 50 m is a ship).
MIN_FOOTPRINT_M = 0.01
MAX_FOOTPRINT_M = 50.0
#: Skids in one command or one layout request.
MAX_ROBOTS_PER_COMMAND = 5_000
#: Robot and person ids longer than this are refused (they go into every frame and log line).
MAX_ID_LENGTH = 64
#: Headings (degrees) beyond this many turns are a typo (and lose precision when wrapped).
MAX_HEADING_DEG = 3600.0
#: A scenario runs at most a day of simulated time, in ticks of at least a millisecond, and
#: at most this many ticks in all, so every run ends.
MAX_DURATION_S = 86_400.0
MIN_DT_S = 1e-3
MAX_TICKS = 10_000_000
#: Skids in one scenario.
MAX_ROBOTS = 1_000
#: Largest request body the server reads (HTTP 413 beyond): a park boundary of the largest
#: allowed polygon is a few tens of kB.
MAX_BODY_BYTES = 256 * 1024
#: Largest body of a park or park-preview request: a boundary of
#: :data:`MAX_BOUNDARY_VERTICES` vertices written at full float precision (about 42 bytes
#: a vertex) fits.
MAX_PARK_BODY_BYTES = 1024 * 1024
#: WebSocket viewers of one server at once (more are refused with close code 1013).
MAX_VIEWERS = 256


def _show(value: object, limit: int = 40) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def finite_float(
    value: object,
    field: str,
    *,
    lo: float | None = None,
    hi: float | None = None,
    error: type[ValueError] = ValueError,
) -> float:
    """``value`` as a finite float within ``[lo, hi]``; ``error(message)`` naming ``field``
    and the value otherwise (NaN, infinities, strings such as ``'NaN'``, booleans)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise error(f"{field} must be a number (got {_show(value)})")
    x = float(value)
    if not math.isfinite(x):
        raise error(f"{field} must be a finite number (got {_show(value)})")
    if lo is not None and x < lo:
        raise error(f"{field} must be >= {lo} (got {_show(value)})")
    if hi is not None and x > hi:
        raise error(f"{field} must be <= {hi} (got {_show(value)})")
    return x


def finite_sequence(
    values: object,
    field: str,
    *,
    length: int | None = None,
    bound: float = MAX_COORDINATE_M,
    error: type[ValueError] = ValueError,
) -> list[float]:
    """A list of finite floats, each within ``[-bound, bound]`` (``length`` of them when
    given)."""
    if not isinstance(values, Sequence) or isinstance(values, str | bytes):
        raise error(f"{field} must be a list of numbers (got {_show(values)})")
    if length is not None and len(values) != length:
        raise error(f"{field} must have {length} numbers (got {_show(values)})")
    return [
        finite_float(v, f"{field}[{k}]", lo=-bound, hi=bound, error=error)
        for k, v in enumerate(values)
    ]


def check_grid_cells(
    shape: tuple[int, int], field: str, *, error: type[ValueError] = ValueError
) -> None:
    """Refuse a grid of ``shape`` (rows, columns) that is empty or over :data:`MAX_GRID_CELLS`,
    before it is allocated."""
    rows, cols = (int(s) for s in shape)
    if rows <= 0 or cols <= 0:
        raise error(f"{field}: a grid of {rows} x {cols} cells is empty")
    if rows * cols > MAX_GRID_CELLS:
        raise error(
            f"{field}: a grid of {rows} x {cols} cells is over the budget of {MAX_GRID_CELLS} "
            "cells (use a coarser resolution or a smaller map)"
        )


def check_vertices(
    n: int, field: str, *, error: type[ValueError] = ValueError, limit: int | None = None
) -> None:
    """Refuse a polygon with more than ``limit`` (default :data:`MAX_POLYGON_VERTICES`)
    vertices."""
    limit = MAX_POLYGON_VERTICES if limit is None else limit
    if n > limit:
        raise error(f"{field} has {n} vertices, more than the limit of {limit}")


def check_inside(
    points: Sequence[Sequence[float]],
    bounds: Sequence[float],
    field: str,
    *,
    error: type[ValueError] = ValueError,
) -> None:
    """Refuse the first point ``[x, y, ...]`` outside ``bounds`` = ``(xmin, ymin, xmax,
    ymax)`` (the map), naming it: a goal or boundary off the map is a typo, never a place a
    skid can go."""
    xmin, ymin, xmax, ymax = (float(b) for b in bounds)
    for k, p in enumerate(points):
        x, y = float(p[0]), float(p[1])
        if not (xmin <= x <= xmax and ymin <= y <= ymax):
            where = f"{field}[{k}]" if len(points) > 1 else field
            raise error(
                f"{where}: {_show([x, y])} is outside the map "
                f"[{xmin:g}, {ymin:g}, {xmax:g}, {ymax:g}]"
            )
