"""How the simulator's scripted people react to a skid in their way.

A person walks a route at constant speed (:class:`~swarmpark.world.build.Person`: the walked
distance ``s`` says where). A person who ``reacts`` (the default) behaves as people do when a
machine stands in their way, in the spirit of the reactive pedestrians of crowd simulators
(social force, ORCA), but kept to the route so a scenario stays easy to read:

* **Stop short.** When the next :data:`STOP_AHEAD_M` of the walk would enter a skid's
  footprint, where the skid stands now, the person stands; for a skid standing still or
  manoeuvring slowly (under :data:`SLOW_MPS`) in their way they stop already
  :data:`STOP_AHEAD_STILL_M` short, as people wait for a machine busy in a narrow aisle
  rather than walk up to it (while they walk behind one that drives across).
* **Wait.** They walk on once the route is clear to :data:`CLEAR_PAST_M` past where it met
  the skid, and for at least :data:`CLEAR_AHEAD_M` ahead (not on the heels of a skid that
  drives off along their route).
* **Back off.** A skid that has not left after :data:`PATIENCE_S` may only be able to leave
  towards the person (a skid in a tight row that must back out): the person then walks back
  along their route, at :data:`RETREAT_PACE` of their speed and up to :data:`RETREAT_M`,
  never into another skid, and waits there.

A person who does not react walks the route whatever stands in it; the simulator then stops
them at the skid and reports the contact as ``person-robot`` (not the fleet's fault).
Everything is a function of the poses and the step, so runs stay deterministic.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from swarmpark.core.geometry import TOUCH_TOLERANCE_M, rect_disc_gap

__all__ = [
    "PeopleReaction",
    "STOP_AHEAD_M",
    "STOP_AHEAD_STILL_M",
    "SLOW_MPS",
    "CLEAR_PAST_M",
    "CLEAR_AHEAD_M",
    "PATIENCE_S",
    "RETREAT_M",
    "RETREAT_PACE",
]

#: A person stands while their walk this far ahead would enter a skid's footprint (a little
#: over two steps at walking speed: they stop short of the skid, not against it).
STOP_AHEAD_M = 0.15
#: ... and this far short of a skid slower than SLOW_MPS (standing, docking or turning; skids
#: cruise at 0.5 m/s).
STOP_AHEAD_STILL_M = 2.5
SLOW_MPS = 0.3
#: The walk is checked at this spacing.
SAMPLE_M = 0.05
#: They walk on once the route is clear this far past where it met the skid, and at least
#: this far ahead of them.
CLEAR_PAST_M = 0.5
CLEAR_AHEAD_M = 1.0
#: After standing this long for the same skid, they back off ...
PATIENCE_S = 2.0
#: ... up to this far back along their route, at this fraction of their walking speed.
RETREAT_M = 1.5
RETREAT_PACE = 0.5


class PeopleReaction:
    """The reaction state of every person and the step that applies it.

    Attributes
    ----------
    pace
        ``(P,)`` what each person did in the last step, as a fraction of their speed along
        the route: 1 walked (or stood a scripted wait), 0 stood for a skid, ``-RETREAT_PACE``
        backed off. People who do not react are always 1.
    """

    def __init__(self, people: Sequence) -> None:
        self.people = list(people)
        k = len(self.people)
        self.reacts = np.array([p.reacts for p in self.people], dtype=bool)
        self.radius = np.array([p.radius_m for p in self.people], dtype=float)
        self.pace = np.ones(k)
        #: Route position where the walk met a skid (NaN: not blocked).
        self.block_s = np.full(k, np.nan)
        #: Seconds stood for the current block.
        self.held_s = np.zeros(k)
        #: Route position where the person started backing off (NaN: not backing off).
        self.retreat_from = np.full(k, np.nan)
        #: Which skids are slow this step.
        self._slow = np.zeros(0, dtype=bool)

    def step(
        self,
        s: np.ndarray,
        new_s: np.ndarray,
        dt: float,
        corners: np.ndarray,
        centers: np.ndarray,
        circumradius: np.ndarray,
        speed: np.ndarray | None = None,
    ) -> np.ndarray:
        """Walked distances after the reaction.

        Parameters
        ----------
        s, new_s
            ``(P,)`` walked distance now and where the script would take each person.
        dt
            The step (s).
        corners, centers, circumradius
            The skids where they stand: footprints ``(N, 4, 2)``, centres ``(N, 2)`` and
            circumradii ``(N,)``.
        speed
            ``(N,)`` the skids' speeds (m/s; None: all standing).
        """
        out = np.array(new_s, dtype=float, copy=True)
        self.pace[:] = 1.0
        if not len(corners):
            return out
        slow = np.ones(len(corners), bool) if speed is None else np.abs(speed) < SLOW_MPS
        self._slow = slow
        for k in np.flatnonzero(self.reacts):
            out[k] = self._one(k, float(s[k]), float(new_s[k]), dt, corners, centers, circumradius)
        return out

    def _one(self, k, s, new_s, dt, corners, centers, circumradius) -> float:
        if not np.isnan(self.block_s[k]):
            ahead = max(self.block_s[k] - s + CLEAR_PAST_M, CLEAR_AHEAD_M)
            if self._first_hit(k, s, ahead, corners, centers, circumradius) is not None:
                return self._held(k, s, dt, corners, centers, circumradius)
            self.block_s[k] = np.nan  # the way is clear: walk on
            self.held_s[k] = 0.0
            self.retreat_from[k] = np.nan
        if new_s <= s:
            return new_s  # not walking (not started, or done)
        hit = self._first_hit(k, new_s, STOP_AHEAD_M, corners, centers, circumradius)
        slow = self._slow
        if hit is None and slow.any():
            hit = self._first_hit(
                k, new_s, STOP_AHEAD_STILL_M, corners[slow], centers[slow], circumradius[slow]
            )
        if hit is None:
            return new_s
        # Stop short: where the walk would have met the skid is remembered, to walk on
        # only once the route past it is clear.
        self.block_s[k] = new_s + hit
        self.held_s[k] = dt
        self.pace[k] = 0.0
        return s

    def _held(self, k, s, dt, corners, centers, circumradius) -> float:
        """A blocked person: stand, or back off once patience runs out."""
        self.held_s[k] += dt
        self.pace[k] = 0.0
        if self.held_s[k] < PATIENCE_S:
            return s
        if np.isnan(self.retreat_from[k]):
            self.retreat_from[k] = s
        target = max(self.retreat_from[k] - RETREAT_M, 0.0)
        back = max(s - RETREAT_PACE * self.people[k].speed_mps * dt, target)
        if back >= s:
            return s
        # Never back into another skid (the walk behind, checked like the walk ahead).
        gap = self._gaps(k, np.array([back]), corners, centers, circumradius)
        if gap.size and gap.min() < 0.0:
            return s
        self.pace[k] = -RETREAT_PACE
        return back

    def _gaps(self, k, route_s, corners, centers, circumradius) -> np.ndarray:
        """Gaps ``(M, R)`` of person ``k`` at route positions ``route_s`` ``(M,)`` to the
        skids within reach (``R`` may be 0)."""
        person, r = self.people[k], self.radius[k]
        m = len(route_s)
        first = person.position_at(float(route_s[0]))
        span = float(np.abs(route_s[-1] - route_s[0]))
        reach = circumradius + r + span + TOUCH_TOLERANCE_M
        near = np.flatnonzero(np.linalg.norm(centers - first, axis=1) < reach)
        if not len(near):
            return np.zeros((m, 0))
        pts = np.stack([first] + [person.position_at(float(x)) for x in route_s[1:]])
        gap = rect_disc_gap(
            np.tile(corners[near], (m, 1, 1)),
            np.repeat(pts, len(near), axis=0),
            np.full(m * len(near), r),
        )
        return gap.reshape(m, len(near))

    def _first_hit(self, k, s0, length, corners, centers, circumradius) -> float | None:
        """Distance along the route from ``s0`` (within ``length``) at which person ``k``
        would overlap a skid, or None."""
        n = max(1, int(np.ceil(length / SAMPLE_M)))
        offs = np.linspace(0.0, max(length, 0.0), n + 1)
        gap = self._gaps(k, s0 + offs, corners, centers, circumradius)
        if not gap.size:
            return None
        bad = np.flatnonzero((gap < 0.0).any(axis=1))
        return float(offs[bad[0]]) if len(bad) else None
