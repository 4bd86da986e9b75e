"""The layout methods, registered by name: each one says how it lays out given skids
(:meth:`LayoutMethod.solve`) and how it fills a region with one footprint size
(:meth:`LayoutMethod.fill`, for :func:`~swarmpark.layout.api.capacity`).

A method is a subclass of :class:`LayoutMethod` with a ``name`` and a ``description``;
defining it registers it in :data:`LAYOUT_METHODS` (as pyrobosim's planners register by
subclassing). The scenario schema, the API, the CLI, the bench and the operator UI take the
names from there. The heavy solvers (potential field, cvxpy) are imported only when used.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from swarmpark.core.geometry import Footprint
from swarmpark.core.registry import Registry
from swarmpark.layout import stacking
from swarmpark.layout.region import LayoutError, Region, Skids, describe_skids, make_skids

__all__ = [
    "LAYOUT_METHODS",
    "LayoutMethod",
    "Stacking",
    "Potential",
    "Convex",
    "get_method",
    "stack_best",
    "capacity_stack",
]

#: Every layout method by name, in the order they were defined.
LAYOUT_METHODS: Registry[type[LayoutMethod]] = Registry("layout method", "park.method")


class LayoutMethod:
    """A layout method. Subclasses set ``name`` and ``description`` and are registered.

    Both methods work in the layout frame (the region rotated so the heading is +x) and
    return centres ``(N, 2)`` with a details dict (``iterations``, ``notices`` and
    method-specific entries) that ends up in the layout's report.
    """

    name: ClassVar[str]
    description: ClassVar[str]
    #: Method whose layout is used (with a notice) when this one's fails validation.
    fallback: ClassVar[str | None] = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        LAYOUT_METHODS.add(cls.name, cls, cls.description)

    @classmethod
    def solve(cls, region: Region, skids: Skids) -> tuple[np.ndarray, dict]:
        """Centres for every skid; :class:`LayoutError` with ``fits`` if they do not fit."""
        raise NotImplementedError

    @classmethod
    def fill(
        cls, region: Region, footprint: Footprint, stacked: stacking.StackResult
    ) -> tuple[np.ndarray, dict]:
        """Centres ``(K, 2)`` of as many ``footprint`` skids as this method fits (``K`` may
        be 0). ``stacked`` is the stacking fill of the region, a lower bound to start from."""
        raise NotImplementedError


def get_method(name: str) -> type[LayoutMethod]:
    """The method called ``name``; :class:`LayoutError` listing the known names if none is."""
    if name not in LAYOUT_METHODS:
        raise LayoutError(
            f"park.method: must be one of {list(LAYOUT_METHODS.names())} (got {name!r})"
        )
    return LAYOUT_METHODS.get(name)


def stack_best(region: Region, skids: Skids, count: int | None) -> stacking.StackResult:
    """Stacking in the paper's column order, and in row order if that fits more."""
    best = stacking.stack(region, skids, order="columns", count=count)
    want = len(skids) if count is None else count
    if best.fits < want:
        alt = stacking.stack(region, skids, order="rows", count=count)
        if alt.fits > best.fits:
            best = alt
    return best


def capacity_stack(region: Region, footprint: Footprint) -> stacking.StackResult:
    """Stacking until full with one footprint size."""
    area = footprint.length_m * footprint.width_m
    upper = int(region.free.area / area) + 1
    return stack_best(region, make_skids([footprint] * upper), None)


def not_enough(skids: Skids, fits: int, margin: float, method: str) -> LayoutError:
    """The error for skids that do not all fit (``fits`` says how many do)."""
    return LayoutError(
        f"park.boundary: only {fits} of {len(skids)} skids ({describe_skids(skids)}, "
        f"margin {margin:g} m) fit with method {method!r}",
        fits=fits,
    )


def _stack_all(region: Region, skids: Skids, method: str) -> tuple[stacking.StackResult, dict]:
    """Stacking of every skid (or the error) and the details it reports."""
    st = stack_best(region, skids, len(skids))
    if st.fits < len(skids):
        raise not_enough(skids, st.fits, region.margin, method)
    info: dict = {"scan_order": st.order, "iterations": 0, "notices": []}
    if st.order != "columns":
        info["notices"].append(
            "stacking scanned by rows: the paper's column scan fits fewer skids here"
        )
    return st, info


class Stacking(LayoutMethod):
    name = "stacking"
    description = (
        "Stacking (2018 Algorithm 1): column scan from the left-most point, whole footprint tested"
    )

    @classmethod
    def solve(cls, region, skids):
        st, info = _stack_all(region, skids, cls.name)
        return st.centres, info

    @classmethod
    def fill(cls, region, footprint, stacked):
        return stacked.centres[stacked.placed], {
            "scan_order": stacked.order,
            "iterations": 0,
            "notices": [],
        }


class Potential(LayoutMethod):
    name = "potential"
    description = "Potential field (2018 eqs. 1-4): the stacking layout spread out evenly"

    @classmethod
    def solve(cls, region, skids):
        from swarmpark.layout import potential

        st, info = _stack_all(region, skids, cls.name)
        centres, pinfo = potential.spread(region, skids, st.centres)
        pinfo["notices"] = info["notices"] + pinfo.get("notices", [])
        pinfo["scan_order"] = st.order
        return centres, pinfo

    @classmethod
    def fill(cls, region, footprint, stacked):
        from swarmpark.layout import potential

        centres = stacked.centres[stacked.placed]
        return potential.spread(region, make_skids([footprint] * len(centres)), centres)


class Convex(LayoutMethod):
    name = "convex"
    description = (
        "Convex optimization (2015 Sect. 3.1): max-min spacing floor plan, structured optimization"
    )
    #: The LP holds its rows only within solver tolerance (see ``api._finish_checked``).
    fallback = "stacking"

    @classmethod
    def solve(cls, region, skids):
        from swarmpark.layout import convex

        return convex.solve(region, skids)

    @classmethod
    def fill(cls, region, footprint, stacked):
        from swarmpark.layout import convex

        return convex.largest(region, footprint, int(stacked.fits))
