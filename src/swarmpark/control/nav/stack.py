"""The controller a scenario's ``navigation`` selects: one factory per navigation mode.

The names and descriptions live in :data:`swarmpark.control.modes.NAVIGATION_MODES` (the
schema reads them there without importing the navigation stack); :data:`FACTORIES` holds
how each is built, and a mode registered without a factory is an error naming it.
"""

from __future__ import annotations

from collections.abc import Callable

from swarmpark.control.base import Controller
from swarmpark.control.modes import DEFAULT_AVOIDANCE, DEFAULT_NAVIGATION, NAVIGATION_MODES
from swarmpark.control.nav.params import NavParams

__all__ = ["FACTORIES", "make_controller"]


def _planner(params: NavParams) -> Controller:
    from swarmpark.control.nav.navigator import Navigator

    return Navigator(params)


def _pure_pf(params: NavParams) -> Controller:
    from swarmpark.control.nav.pure_pf import PurePotentialField

    return PurePotentialField(params)


#: Navigation mode name -> controller factory taking the stack's :class:`NavParams`.
FACTORIES: dict[str, Callable[[NavParams], Controller]] = {
    "planner": _planner,
    "pure-pf": _pure_pf,
}


def make_controller(
    mode: str = DEFAULT_NAVIGATION,
    avoidance: str = DEFAULT_AVOIDANCE,
    params: NavParams | None = None,
) -> Controller:
    """The controller of navigation mode ``mode`` with skid-skid ``avoidance``.

    ``params`` (default: :class:`NavParams` with ``avoidance``) tunes its components.
    An unknown mode raises :class:`~swarmpark.core.registry.UnknownNameError` listing the
    known ones.

    >>> type(make_controller("pure-pf")).__name__
    'PurePotentialField'
    >>> make_controller("bug2")
    Traceback (most recent call last):
    ...
    swarmpark.core.registry.UnknownNameError: navigation.mode: unknown navigation mode 'bug2' (known: planner, pure-pf)
    """
    NAVIGATION_MODES.check(mode)
    if mode not in FACTORIES:
        raise ValueError(f"navigation.mode: {mode!r} is registered but has no controller")
    p = NavParams(avoidance=avoidance) if params is None else params
    return FACTORIES[mode](p)
