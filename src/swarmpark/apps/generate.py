"""Seeded site generator: random but valid parking scenarios of ten kinds, for sweeps.

``swarmpark generate KIND --seed S [--robots N] --out FILE.yaml`` writes one scenario in the
polygon-walls map form. Everything random comes from one ``numpy`` Generator seeded from
``(seed, kind)``, so the same kind and seed give the same file. Every file is checked before it
is returned (:func:`swarmpark.apps.feasible.check_feasible`): it loads and builds, the starts
are clear, the park layout fits (the layout code itself is called) and every goal is reachable
in the static map. A draw that fails the check is redrawn with more room (``slack``), so the
sites are feasible by construction and by test.

Kinds
-----
hangar        a hall with pillars on a grid and racks along the long walls
elevator      a hall and a cabin behind a door of random width >= skid width + 2 margins
door          two rooms joined by a door; the fleet parks in the far room
corridor      two rooms joined by a corridor
l-bay         an L-shaped bay with pillars standing in it
pass-through  a parked block of skids that a high-priority skid drives through (RVO)
people        a hall where people walk through the parking area's aisles
open-deck     a deck with few walls; the skids localize onboard (AMCL)
unload        the fleet parked in an elevator's cabin drives out and parks in the hall
swap          two groups change rooms through one door or corridor, each parking in the other's

>>> data = generate("door", 3, robots=4)
>>> data["name"], len(data["robots"]), data["expect"]
('gen-door-s3', 4, {'success': True, 'max_collisions': 0})
>>> generate("door", 3, robots=4) == data
True
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml

from swarmpark.apps.feasible import FeasibilityError, check_feasible

__all__ = ["KINDS", "GenerateError", "generate", "write_scenario", "MIN_ROBOTS", "MAX_ROBOTS"]

#: Fleet sizes drawn when ``robots`` is not given (inclusive).
MIN_ROBOTS, MAX_ROBOTS = 4, 30
#: Footprints (length, width) a mixed fleet draws from; the first is the suite's default skid.
FOOTPRINTS = ((1.2, 0.8), (1.0, 0.7), (1.4, 0.9))
WALL_T = 0.3  # wall thickness, as in the hand-written scenarios
RESOLUTION_M = 0.1  # generated sites are large; 10 cm cells keep planning cheap
MAX_ATTEMPTS = 8
#: Then this many more draws, leaving out what may not fit (an L-bay's pillars).
LAST_RESORT_ATTEMPTS = 4
#: Kinds whose fleet may mix footprints (pass-through keeps the paper's uniform block).
MIXED_KINDS = (
    "hangar", "elevator", "door", "corridor", "l-bay", "people", "open-deck", "unload", "swap",
)  # fmt: skip


class GenerateError(ValueError):
    """Bad generator input, or no feasible draw (names the field and value)."""


@dataclass
class _Ctx:
    """One draw's fleet and the sizes every builder needs."""

    rng: np.random.Generator
    n: int
    fps: list[tuple[float, float]]
    margin: float
    heading: float
    slack: float
    pitch: float = 0.0  # start grid spacing: circumscribed diameter + a gap
    gap: float = 0.0
    #: The draws after MAX_ATTEMPTS failed ones: the builder leaves out what may not fit.
    last_resort: bool = False

    def __post_init__(self) -> None:
        r = max(math.hypot(length / 2, width / 2) for length, width in self.fps)
        self.gap = float(self.rng.uniform(0.3, 0.7))
        self.pitch = 2 * r + self.gap

    @property
    def wmax(self) -> float:
        return max(w for _, w in self.fps)


@dataclass
class _Site:
    size: tuple[float, float]
    walls: list[list[list[float]]]
    starts: list[list[float]]
    boundary: list[list[float]] | None
    obstacles: list[dict] = field(default_factory=list)
    extra: dict = field(default_factory=dict)
    commands: list[dict] | None = None


def _rect(x0: float, y0: float, x1: float, y1: float) -> list[list[float]]:
    return [[_r(x0), _r(y0)], [_r(x1), _r(y0)], [_r(x1), _r(y1)], [_r(x0), _r(y1)]]


def _r(v: float) -> float:
    return round(float(v), 3)


def _outer(w: float, h: float) -> list[list[list[float]]]:
    t = WALL_T
    return [
        _rect(0, 0, w, t),
        _rect(0, h - t, w, h),
        _rect(0, t, t, h - t),
        _rect(w - t, t, w, h - t),
    ]


def _start_grid(ctx: _Ctx) -> tuple[int, int]:
    """Columns and rows of the start grid (a spare row now and then)."""
    rows = max(1, math.ceil(math.sqrt(ctx.n)))
    cols = math.ceil(ctx.n / rows) + int(ctx.rng.integers(0, 2))
    return cols, rows


def _starts(ctx: _Ctx, x0: float, y0: float, cols: int, rows: int, facing_deg: float):
    """Poses on a jittered grid with corner ``(x0, y0)``; no two circumscribed discs touch."""
    slots = ctx.rng.choice(cols * rows, size=ctx.n, replace=False)
    jit = 0.4 * ctx.gap
    out = []
    for s in np.sort(slots):
        c, r = divmod(int(s), rows)
        x = x0 + (c + 0.5) * ctx.pitch + ctx.rng.uniform(-jit, jit)
        y = y0 + (r + 0.5) * ctx.pitch + ctx.rng.uniform(-jit, jit)
        out.append([_r(x), _r(y), _r(facing_deg + ctx.rng.uniform(-30, 30))])
    return out


def _box_dims(ctx: _Ctx, factor: float = 1.0) -> tuple[float, float]:
    """Width and height of a park box that holds the fleet with room to spare (``slack``)."""
    from swarmpark.core.geometry import Footprint
    from swarmpark.layout import LayoutError, layout

    area = sum((length + ctx.margin) * (w + ctx.margin) for length, w in ctx.fps)
    area *= 1.15 * ctx.slack * factor
    aspect = float(ctx.rng.uniform(0.6, 1.7))
    fps = [Footprint(length, w) for length, w in ctx.fps]
    for _ in range(40):
        bw, bh = math.sqrt(area * aspect), math.sqrt(area / aspect)
        try:
            layout(_rect(0, 0, bw, bh), fps, heading=ctx.heading, margin_m=ctx.margin)
            return _r(bw), _r(bh)
        except LayoutError:
            area *= 1.1
    raise GenerateError(f"robots: {ctx.n} skids do not fit a box of {area:.0f} m^2")


def _west_east(ctx: _Ctx, mid_w: float, box_w: float, box_h: float, band: float = 1.5):
    """The common frame: starts in the west, a middle of ``mid_w``, the box in the east."""
    cols, rows = _start_grid(ctx)
    sw, sh = cols * ctx.pitch, rows * ctx.pitch
    h = 2 * WALL_T + 2 * band + max(sh, box_h) + ctx.rng.uniform(0, 4)
    x_box = WALL_T + 1.0 + sw + mid_w
    w = x_box + box_w + ctx.rng.uniform(1.5, 4) + WALL_T
    sy = ctx.rng.uniform(WALL_T + band, h - WALL_T - band - sh)
    by = ctx.rng.uniform(WALL_T + band, h - WALL_T - band - box_h)
    starts = _starts(ctx, WALL_T + 1.0, sy, cols, rows, 0.0)
    return _r(w), _r(h), starts, (x_box, by), WALL_T + 1.0 + sw


# ----------------------------------------------------------------------------- kinds


def _hangar(ctx: _Ctx) -> _Site:
    rng = ctx.rng
    rack_d = float(rng.uniform(0.8, 1.2))
    bw, bh = _box_dims(ctx, 1.2)  # pillars may stand in the box
    w, h, starts, (bx, by), s_end = _west_east(ctx, rng.uniform(4, 9), bw, bh, rack_d + 1.5)
    walls = _outer(w, h)
    p = float(rng.uniform(4.5, 7.5))
    size = float(rng.uniform(0.5, 0.8))
    for x in np.arange(s_end + 2.0, w - 2.0, p):
        for y in np.arange(WALL_T + rack_d + 2.0 + rng.uniform(0, 2), h - rack_d - 2.0, p):
            walls.append(_rect(x, y, x + size, y + size))
    for _ in range(int(rng.integers(1, 4))):
        length = float(rng.uniform(3, 6))
        x0 = float(rng.uniform(s_end + 1, max(s_end + 1.5, w - WALL_T - length - 0.5)))
        y0, y1 = (
            (WALL_T, WALL_T + rack_d) if rng.random() < 0.5 else (h - WALL_T - rack_d, h - WALL_T)
        )
        walls.append(_rect(x0, y0, x0 + length, y1))
    return _Site((w, h), walls, starts, _rect(bx, by, bx + bw, by + bh))


def _door_site(ctx: _Ctx, cabin: bool) -> _Site:
    """Two spaces split by a wall with a door; ``cabin``: the far one is just the box."""
    rng = ctx.rng
    door = ctx.wmax + 2 * ctx.margin + float(rng.uniform(0.2, 1.2))
    bw, bh = _box_dims(ctx)
    bh = max(bh, door + 0.6)
    room_w = bw if cabin else bw + rng.uniform(2, 5)
    w, h, starts, (_, by), s_end = _west_east(ctx, 0.0, 0.0, 0.0)
    xd = s_end + rng.uniform(2.5, 5)
    w = _r(xd + WALL_T + room_w + WALL_T)
    h = _r(max(h, bh + 2 * WALL_T + (0.0 if cabin else 3.0)))
    walls = _outer(w, h)
    if cabin:
        cy = float(rng.uniform(WALL_T, h - WALL_T - bh))
        if cy > WALL_T:
            walls.append(_rect(xd, WALL_T, w - WALL_T, cy))
        if cy + bh < h - WALL_T:
            walls.append(_rect(xd, cy + bh, w - WALL_T, h - WALL_T))
        lo, hi = cy, cy + bh
        box = _rect(xd + WALL_T, cy, w - WALL_T, cy + bh)
    else:
        lo, hi = WALL_T, h - WALL_T
        bx = xd + WALL_T + rng.uniform(1.0, room_w - bw - 1.0) if room_w - bw > 2 else xd + WALL_T
        by = float(rng.uniform(WALL_T + 1.0, max(WALL_T + 1.0, h - WALL_T - 1.0 - bh)))
        box = _rect(bx, by, bx + bw, min(by + bh, h - WALL_T))
    # A cabin can be exactly the door plus 0.6 m high: clamp the round-off below zero.
    d0 = lo + 0.3 + float(rng.uniform(0.0, max(hi - lo - 0.6 - door, 0.0)))
    if d0 > lo:
        walls.append(_rect(xd, lo, xd + WALL_T, d0))
    if d0 + door < hi:
        walls.append(_rect(xd, d0 + door, xd + WALL_T, hi))
    return _Site((w, h), walls, starts, box)


def _elevator(ctx: _Ctx) -> _Site:
    return _door_site(ctx, cabin=True)


def _door(ctx: _Ctx) -> _Site:
    return _door_site(ctx, cabin=False)


def _corridor(ctx: _Ctx) -> _Site:
    rng = ctx.rng
    cw = ctx.wmax + float(rng.uniform(1.0, 2.2))
    length = float(rng.uniform(5, 14))
    bw, bh = _box_dims(ctx)
    w, h, starts, (bx, by), s_end = _west_east(ctx, length + 3.0, bw, bh)
    xa, xb = s_end + 1.0, s_end + 1.0 + length
    walls = _outer(w, h)
    c0 = float(rng.uniform(WALL_T + 0.5, h - WALL_T - 0.5 - cw))
    walls.append(_rect(xa, WALL_T, xb, c0))
    walls.append(_rect(xa, c0 + cw, xb, h - WALL_T))
    return _Site((w, h), walls, starts, _rect(bx, by, bx + bw, by + bh))


def _l_bay(ctx: _Ctx) -> _Site:
    rng = ctx.rng
    fx, fy = rng.uniform(0.35, 0.5, size=2)
    bw, bh = _box_dims(ctx, 1.25 / (1 - fx * fy))
    w, h, starts, (bx, by), _ = _west_east(ctx, rng.uniform(4, 8), bw, bh)
    from shapely.geometry import Point, Polygon, box

    x0, y0, x1, y1 = bx, by, bx + bw, by + bh
    # Each arm of the L stays wide enough for a skid in any heading, with its margins (a small
    # fleet's box is small: a cut of half of it left arms no skid fits in).
    arm = max(max(fp) for fp in ctx.fps) + 2 * ctx.margin + 0.2
    cw, ch = min(fx * bw, max(bw - arm, 0.0)), min(fy * bh, max(bh - arm, 0.0))
    cx = x0 if rng.random() < 0.5 else x1 - cw  # which corner the L misses
    cy = y0 if rng.random() < 0.5 else y1 - ch
    shape = box(x0, y0, x1, y1).difference(box(cx, cy, cx + cw, cy + ch))
    pts = list(shape.exterior.coords)[:-1]
    boundary = [[_r(x), _r(y)] for x, y in pts]
    walls = _outer(w, h)
    poly = Polygon(boundary).buffer(-1.0)
    # A small fleet's L can have no room beside its pillars (l-bay seed 32766, 2 skids).
    pillars = 0 if ctx.last_resort else int(rng.integers(1, 4))
    for _ in range(pillars):
        for _try in range(20):
            px, py = rng.uniform(x0, x1), rng.uniform(y0, y1)
            if poly.contains(Point(px, py)):
                s = float(rng.uniform(0.4, 0.7))
                walls.append(_rect(px - s / 2, py - s / 2, px + s / 2, py + s / 2))
                break
    return _Site((w, h), walls, starts, boundary)


def _pass_through(ctx: _Ctx) -> _Site:
    rng = ctx.rng
    length, width = ctx.fps[0]
    k = ctx.n - 1
    rows = max(1, round(math.sqrt(k)))
    cols = math.ceil(k / rows)
    sx = width + float(rng.uniform(0.6, 1.0))
    sy = length + float(rng.uniform(0.6, 1.0))
    run_in, run_out = float(rng.uniform(6, 10)), float(rng.uniform(6, 10))
    w = WALL_T + run_in + cols * sx + run_out + WALL_T + 2.0
    h = WALL_T + 3.0 + rows * sy + 3.0 + WALL_T
    bx, by = WALL_T + run_in + 1.0, WALL_T + 3.0
    starts, cmds = [], []
    for i in range(k):
        c, r = divmod(i, rows)
        pose = [_r(bx + (c + 0.5) * sx), _r(by + (r + 0.5) * sy), 90.0]
        starts.append(pose)
        cmds.append({"at_s": 0, "goto": {"robot": f"g{i + 1}", "pose": pose}})
    # The runner crosses between two rows (or along the block's middle with one row).
    lane = int(rng.integers(1, rows)) if rows > 1 else 0
    ry = by + lane * sy if rows > 1 else by + 0.5 * sy
    starts.append([_r(WALL_T + 2.0), _r(ry), 0.0])
    runner_goal = [_r(w - WALL_T - 2.5), _r(ry), 0.0]
    cmds.append({"at_s": 1, "goto": {"robot": f"g{ctx.n}", "pose": runner_goal, "priority": 10}})
    return _Site(
        (_r(w), _r(h)), _outer(w, h), starts, None, extra={"navigation": {"avoidance": "rvo"}},
        commands=cmds,
    )  # fmt: skip


def _people(ctx: _Ctx) -> _Site:
    rng = ctx.rng
    bw, bh = _box_dims(ctx)
    w, h, starts, (bx, by), _ = _west_east(ctx, rng.uniform(5, 9), bw, bh, 2.0)
    # Walkers are placed by the feasibility pass, which knows the goals (see _place_walkers).
    site = _Site((w, h), _outer(w, h), starts, _rect(bx, by, bx + bw, by + bh))
    site.extra["_walkers"] = int(rng.integers(1, 4))
    return site


def _open_deck(ctx: _Ctx) -> _Site:
    rng = ctx.rng
    bw, bh = _box_dims(ctx)
    w, h, starts, (bx, by), s_end = _west_east(ctx, rng.uniform(6, 12), bw, bh, 3.0)
    walls = _outer(w, h)
    for _ in range(int(rng.integers(0, 3))):  # a few free-standing walls north or south
        length = float(rng.uniform(2, 4))
        x0 = float(rng.uniform(s_end + 1, max(s_end + 1.5, w - WALL_T - length - 1)))
        y0 = WALL_T + 0.8 if rng.random() < 0.5 else h - WALL_T - 1.1
        walls.append(_rect(x0, y0, x0 + length, y0 + WALL_T))
    site = _Site((w, h), walls, starts, _rect(bx, by, bx + bw, by + bh))
    # Few walls to see: this is the kind that measures onboard localization.
    site.extra["sensing"] = {"localization": "amcl", "lidar_beams": 360}
    return site


def _unload(ctx: _Ctx) -> _Site:
    """The elevator the other way round: the fleet stands parked in the cabin (the park
    layout of the cabin, each skid driven in nose first or backed in) and parks in the hall,
    in the area the elevator kind starts from (its start grid's extent)."""
    from swarmpark.core.geometry import Footprint
    from swarmpark.layout import LayoutError, layout

    site = _door_site(ctx, cabin=True)
    fps = [Footprint(length, w, length / 2) for length, w in ctx.fps]
    try:
        parked = layout(site.boundary, fps, heading=math.radians(ctx.heading), margin_m=ctx.margin)
    except LayoutError as exc:
        raise FeasibilityError(f"robots: the fleet does not fit the cabin ({exc})") from None
    flips = ctx.rng.integers(0, 2, size=ctx.n) * 180.0
    starts = [
        [_r(x), _r(y), _r(math.degrees(yaw) + flip)]
        for (x, y, yaw), flip in zip(parked.poses.tolist(), flips.tolist(), strict=True)
    ]
    xy = np.array([p[:2] for p in site.starts])
    lo, hi = xy.min(axis=0) - 0.5 * ctx.pitch, xy.max(axis=0) + 0.5 * ctx.pitch
    return _Site(site.size, site.walls, starts, _rect(lo[0], lo[1], hi[0], hi[1]))


def _swap(ctx: _Ctx) -> _Site:
    """Two groups change sides through one bottleneck, a door or a corridor (drawn): about
    half the fleet starts in the west room and parks in the east room, the rest the other way
    round. In each room the group's start grid and the other group's park box lie side by
    side along the dividing wall, in an order drawn per room."""
    rng = ctx.rng
    n_west = int(rng.integers(max(1, ctx.n // 2 - 1), min(ctx.n - 1, ctx.n // 2 + 1) + 1))
    groups = ((0, n_west), (n_west, ctx.n))
    subs = [replace(ctx, n=b - a, fps=ctx.fps[a:b]) for a, b in groups]
    grids = [_start_grid(c) for c in subs]
    sizes = [(cols * c.pitch, rows * c.pitch) for (cols, rows), c in zip(grids, subs, strict=True)]
    boxes = [_box_dims(c) for c in subs]  # group k's box, in the other room
    band = 1.5
    # Room k holds group k's starts and the other group's box, one above the other.
    room_w = [max(sizes[k][0], boxes[1 - k][0]) + 2 * band for k in (0, 1)]
    room_h = [sizes[k][1] + boxes[1 - k][1] + 3 * band for k in (0, 1)]
    h = _r(2 * WALL_T + max(room_h) + rng.uniform(0, 3))
    if rng.random() < 0.5:  # a door in a wall
        passage, cw = WALL_T, ctx.wmax + 2 * ctx.margin + float(rng.uniform(0.2, 1.2))
    else:  # a corridor
        passage, cw = float(rng.uniform(4, 12)), ctx.wmax + float(rng.uniform(1.0, 2.2))
    xa = WALL_T + room_w[0]
    xb = xa + passage
    w = _r(xb + room_w[1] + WALL_T)
    walls = _outer(w, h)
    c0 = float(rng.uniform(WALL_T + 0.5, h - WALL_T - 0.5 - cw))
    walls.append(_rect(xa, WALL_T, xb, c0))
    walls.append(_rect(xa, c0 + cw, xb, h - WALL_T))
    starts, box = [], [None, None]
    for k, (x0, facing) in enumerate(((WALL_T, 0.0), (xb, 180.0))):
        (cols, rows), (sw, sh), (bw, bh) = grids[k], sizes[k], boxes[1 - k]
        inner = h - 2 * WALL_T - sh - bh - 3 * band  # spare height in this room
        low = float(rng.uniform(0, max(inner, 0.0)))
        starts_low = rng.random() < 0.5
        y_s = WALL_T + band + (low if starts_low else bh + band + low)
        y_b = WALL_T + band + (sh + band + low if starts_low else low)
        sx = x0 + band + (room_w[k] - 2 * band - sw) * (1.0 if k == 0 else 0.0)
        bx = x0 + band + (room_w[k] - 2 * band - bw) * (1.0 if k == 0 else 0.0)
        starts += _starts(subs[k], sx, y_s, cols, rows, facing)
        box[1 - k] = _rect(bx, y_b, bx + bw, y_b + bh)
    ids = [f"g{i + 1}" for i in range(ctx.n)]
    commands = [
        {
            "at_s": 0,
            "park": {
                "robots": ids[a:b],
                "boundary": box[k],
                "heading_deg": ctx.heading,
                "method": "stacking",
                "margin_m": _r(ctx.margin),
                "assignment": "formation",
            },
        }
        for k, (a, b) in enumerate(groups)
    ]
    return _Site((w, h), walls, starts, None, commands=commands)


KINDS: dict[str, Callable[[_Ctx], _Site]] = {
    "hangar": _hangar,
    "elevator": _elevator,
    "door": _door,
    "corridor": _corridor,
    "l-bay": _l_bay,
    "pass-through": _pass_through,
    "people": _people,
    "open-deck": _open_deck,
    "unload": _unload,
    "swap": _swap,  # last: a kind's index seeds its draws
}


# ----------------------------------------------------------------------------- assembly


def _fleet(rng: np.random.Generator, kind: str, n: int) -> list[tuple[float, float]]:
    if kind in MIXED_KINDS and rng.random() < 0.5:
        return [FOOTPRINTS[int(i)] for i in rng.integers(0, len(FOOTPRINTS), size=n)]
    return [FOOTPRINTS[0]] * n


def _scenario(kind: str, seed: int, ctx: _Ctx, site: _Site) -> dict:
    ids = [f"g{i + 1}" for i in range(ctx.n)]
    robots = []
    for rid, pose, (length, width) in zip(ids, site.starts, ctx.fps, strict=True):
        spec: dict = {"id": rid, "pose": pose}
        if (length, width) != FOOTPRINTS[0]:
            spec["footprint"] = {
                "length_m": length,
                "width_m": width,
                "pivot_from_rear_m": length / 2,
            }
        robots.append(spec)
    if site.commands is not None:
        commands = site.commands
    else:
        park = {
            "robots": ids,
            "boundary": site.boundary,
            "heading_deg": ctx.heading,
            "method": "stacking",
            "margin_m": _r(ctx.margin),
            "assignment": "formation",
        }
        commands = [{"at_s": 0, "park": park}]
    extra = {k: v for k, v in site.extra.items() if not k.startswith("_")}
    return {
        "name": f"gen-{kind}-s{seed}",
        "seed": int(seed),
        "dt_s": 0.05,
        "duration_s": 600.0,  # replaced by the feasibility pass (scaled with the site)
        "map": {"size_m": [_r(site.size[0]), _r(site.size[1])], "resolution_m": RESOLUTION_M, "walls": site.walls},
        "robot_defaults": {"footprint": {"length_m": 1.2, "width_m": 0.8, "pivot_from_rear_m": 0.6}},
        "robots": robots,
        "obstacles": site.obstacles,
        "commands": commands,
        **extra,
        "expect": {"success": True, "max_collisions": 0},
    }  # fmt: skip


def generate(kind: str, seed: int, *, robots: int | None = None) -> dict:
    """A feasible scenario mapping of ``kind`` for ``seed`` (see the module docstring).

    Raises
    ------
    GenerateError
        Unknown kind, a fleet size out of range, or no feasible draw in
        :data:`MAX_ATTEMPTS` draws and :data:`LAST_RESORT_ATTEMPTS` simpler ones (a
        generator bug).
    """
    if kind not in KINDS:
        raise GenerateError(f"kind: unknown kind {kind!r} (known: {', '.join(KINDS)})")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise GenerateError(f"seed: must be an integer >= 0 (got {seed!r})")
    low = 2 if kind in ("pass-through", "swap") else 1
    if robots is not None and not (low <= robots <= 2 * MAX_ROBOTS):
        raise GenerateError(f"robots: must be in {low}..{2 * MAX_ROBOTS} (got {robots!r})")
    rng = np.random.default_rng([int(seed), list(KINDS).index(kind)])
    n = int(robots) if robots is not None else int(rng.integers(MIN_ROBOTS, MAX_ROBOTS + 1))
    fps = _fleet(rng, kind, n)
    last: Exception | None = None
    for attempt in range(MAX_ATTEMPTS + LAST_RESORT_ATTEMPTS):
        margin = float(rng.uniform(0.6, 1.0) if kind == "people" else rng.uniform(0.25, 0.45))
        heading = float(rng.choice([0.0, 90.0]))
        ctx = _Ctx(rng, n, fps, margin, heading, slack=1.0 + 0.2 * attempt)
        ctx.last_resort = attempt >= MAX_ATTEMPTS
        try:
            site = KINDS[kind](ctx)
            data = _scenario(kind, seed, ctx, site)
            report = check_feasible(data, walkers=site.extra.get("_walkers", 0), rng=rng)
        except FeasibilityError as exc:
            last = exc
            continue
        data["duration_s"] = report["duration_s"]
        data["obstacles"] = report["obstacles"]
        if not data["obstacles"]:
            del data["obstacles"]
        return data
    raise GenerateError(f"kind {kind!r} seed {seed}: no feasible draw ({last})")


class _Dumper(yaml.SafeDumper):
    """Points, poses and small mappings of scalars on one line, as in the hand-written files."""

    def represent_list(self, data):
        flat = all(not isinstance(v, (list, dict)) for v in data)
        pts = all(isinstance(v, list) and len(v) <= 3 for v in data) and len(data) <= 8
        return self.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flat or pts)

    def represent_dict(self, data):
        flat = all(not isinstance(v, (list, dict)) for v in data.values()) and len(data) <= 6
        return self.represent_mapping("tag:yaml.org,2002:map", data.items(), flow_style=flat)


_Dumper.add_representer(list, _Dumper.represent_list)
_Dumper.add_representer(dict, _Dumper.represent_dict)


def write_scenario(data: dict, path: str | Path, *, header: str = "") -> Path:
    """Write a scenario mapping as YAML (flow style for points), with a comment header."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = yaml.dump(data, Dumper=_Dumper, sort_keys=False, width=100)
    path.write_text("".join(f"# {line}\n" for line in header.splitlines()) + text)
    return path
