"""Fixed-step simulator of differential-drive rectangular skids, static solids and walking people.

One :meth:`Simulator.step` takes commanded ``(v, omega)`` for every skid, applies the
acceleration and speed limits, integrates the unicycle about each pivot exactly, and checks
the proposed footprints against each other, the static solids and the people. A motion that
would overlap anything is rejected for that step (the skid keeps its pose and stops, a person
waits), so nothing tunnels through anything; the contact is recorded with both parties. A
walking person who meets a skid gives way first: the skid's own move is then judged against
the person where they stood (so a skid driving off is not held by a person walking after it).

People who react (the default, ``reacts`` in the scenario) stop short of a skid in their way,
wait, and back off if it cannot leave otherwise (:mod:`swarmpark.sim.people`). One who does
not react walks into the skid (a contact of kind ``person-robot``, not the fleet's).

The same step also measures every skid's clearance (footprint distance) to the nearest other
skid and the nearest static solid, up to :data:`CLEARANCE_RANGE_M`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
from scipy.spatial import cKDTree

from swarmpark.core.geometry import (
    TOUCH_TOLERANCE_M,
    body_corners,
    convex_distance,
    convex_overlap,
    envelope_pairs,
    footprint_corners,
    integrate_unicycle,
    pivot_to_center,
    rect_disc_gap,
)
from swarmpark.sim.people import PeopleReaction
from swarmpark.world.scenario import World

__all__ = ["Simulator", "Contact", "StepResult", "CLEARANCE_RANGE_M"]

#: Clearances beyond this distance are not tracked (reported as this value).
CLEARANCE_RANGE_M = 2.0
#: A contact episode ends once the two parties are this far apart again.
CONTACT_RELEASE_M = 0.10


@dataclass(frozen=True)
class Contact:
    """A contact episode: the first step at which a motion by ``a`` or ``b`` was rejected."""

    t_s: float
    a: str
    b: str
    #: robot-robot, robot-wall, robot-obstacle, robot-person (the skid moved into the person)
    #: or person-robot (a walking person met a skid standing still: not the fleet's fault).
    kind: str

    def as_dict(self) -> dict:
        return {"t_s": round(self.t_s, 6), "a": self.a, "b": self.b, "kind": self.kind}


@dataclass
class StepResult:
    new_contacts: list[Contact] = field(default_factory=list)
    blocked: np.ndarray | None = None  # (N,) bool, robots whose motion was rejected
    clearance_robot_m: np.ndarray | None = None  # (N,) nearest other robot
    clearance_static_m: np.ndarray | None = None  # (N,) nearest wall/obstacle


class Simulator:
    """Deterministic simulation of a :class:`~swarmpark.world.scenario.World`.

    State: ``t`` (s), ``poses`` ``(N, 3)`` pivot poses, ``vel`` ``(N, 2)`` actual ``(v, omega)``,
    ``person_s`` walked distance of every person, ``person_held`` the people who stood or
    backed off the last step to let a skid in their way go (``reaction.pace`` says which).
    """

    def __init__(self, world: World) -> None:
        self.world = world
        self.ids = world.ids
        self.dt = world.scenario.dt_s
        robots = world.robots
        self.footprints = [r.footprint for r in robots]
        self.corners_body = body_corners(self.footprints)
        self.center_offset = np.array([fp.center_offset_m for fp in self.footprints])
        self.circumradius = np.array([fp.circumradius_m for fp in self.footprints])
        self.max_speed = np.array([r.max_speed_mps for r in robots])
        self.max_accel = np.array([r.max_accel_mps2 for r in robots])
        self.max_yaw_rate = np.array([r.max_yaw_rate_radps for r in robots])
        self.max_yaw_accel = np.array([r.max_yaw_accel_radps2 for r in robots])
        self.t = 0.0
        self.tick = 0
        self.poses = np.stack([r.start for r in robots]).astype(float)
        self.vel = np.zeros((len(robots), 2))
        self.people = list(world.people)
        self.person_s = np.zeros(len(self.people))
        self.person_radius = np.array([p.radius_m for p in self.people])
        self.reaction = PeopleReaction(self.people)

        # Static solids: convex pieces, with an STR-tree over their bounding boxes.
        self.static_pieces, self.static_owner = world.static_convex_pieces()
        lo, hi = self.static_pieces.min(axis=1), self.static_pieces.max(axis=1)
        self._static_tree = shapely.STRtree(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))
        self._static_lo, self._static_hi = lo, hi
        # A map image's occupied blocks are solid all through: the pieces above are their
        # outline cells, and the interior cells are checked on the grid (a skid that got
        # inside a block some other way, carried there by hand, still collides).
        self._interior = None
        if not world.wall_polygons:
            interior = world.grid.occupied.copy()
            interior[tuple(world.grid.boundary_cells().T)] = False
            if interior.any():
                self._interior = interior
                # Summed-area table: which footprints' boxes hold any interior cell, at once.
                self._interior_sat = np.pad(interior.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
        self._active: set[tuple[str, str]] = set()

    # ------------------------------------------------------------------ queries

    @property
    def n(self) -> int:
        return len(self.ids)

    def corners(self, poses: np.ndarray | None = None) -> np.ndarray:
        """World footprint corners ``(N, 4, 2)``."""
        return footprint_corners(self.poses if poses is None else poses, self.corners_body)

    def person_positions(self, s: np.ndarray | None = None) -> np.ndarray:
        s = self.person_s if s is None else s
        if not self.people:
            return np.zeros((0, 2))
        return np.stack([p.position_at(si) for p, si in zip(self.people, s, strict=True)])

    def people_done(self) -> bool:
        """True when every non-looping person has finished the route."""
        return all(
            (not p.loop) and s >= p.route_length_m - 1e-9
            for p, s in zip(self.people, self.person_s, strict=True)
        )

    # ------------------------------------------------------------------ stepping

    def limit_command(self, cmd: np.ndarray) -> np.ndarray:
        """Clip commanded ``(v, omega)`` ``(N, 2)`` to the speed and acceleration limits."""
        v_cmd = np.clip(cmd[:, 0], -self.max_speed, self.max_speed)
        w_cmd = np.clip(cmd[:, 1], -self.max_yaw_rate, self.max_yaw_rate)
        dv = np.clip(v_cmd - self.vel[:, 0], -self.max_accel * self.dt, self.max_accel * self.dt)
        dw = np.clip(
            w_cmd - self.vel[:, 1], -self.max_yaw_accel * self.dt, self.max_yaw_accel * self.dt
        )
        return np.column_stack([self.vel[:, 0] + dv, self.vel[:, 1] + dw])

    def step(self, cmd: np.ndarray, hold: np.ndarray | None = None) -> StepResult:
        """Advance one fixed step.

        Parameters
        ----------
        cmd
            ``(N, 2)`` commanded ``(v, omega)`` per skid.
        hold
            ``(N,)`` bool: skids that must not move this step (e-stop); their velocity is zeroed.
        """
        dt = self.dt
        vel = self.limit_command(np.asarray(cmd, dtype=float).reshape(self.n, 2))
        if hold is not None:
            vel[hold] = 0.0
        proposed = integrate_unicycle(self.poses, vel[:, 0], vel[:, 1], dt)
        new_s = self._people_react(self._people_progress(dt))

        # Reject colliding motion until the configuration is clear. Reverting everyone involved
        # always terminates: the previous configuration was clear. After the first pass only
        # the robots and people that were just reverted need checking again.
        robot_ok = np.ones(self.n, dtype=bool)
        person_ok = np.ones(len(self.people), dtype=bool)
        robot_moves = np.any(proposed != self.poses, axis=1)
        person_moves = new_s != self.person_s
        focus_r, focus_p = robot_moves.copy(), person_moves.copy()
        contacts: set[tuple[str, str, str]] = set()
        while focus_r.any() or focus_p.any():
            poses = np.where(robot_ok[:, None], proposed, self.poses)
            s = np.where(person_ok, new_s, self.person_s)
            bad_r, bad_p, found = self._collisions(poses, s, focus_r, focus_p)
            contacts |= found
            revert_p = bad_p & person_ok & person_moves
            if revert_p.any():
                # People give way first; the skids they met are judged again against the
                # people where they stood (a skid driving off may go on).
                person_ok &= ~revert_p
                focus_r, focus_p = bad_r & robot_ok & robot_moves, revert_p
                continue
            revert_r = bad_r & robot_ok & robot_moves
            robot_ok &= ~revert_r
            focus_r, focus_p = revert_r, revert_p
        contacts = self._blame_people(contacts, proposed)
        self.poses = np.where(robot_ok[:, None], proposed, self.poses)
        self.vel = np.where(robot_ok[:, None], vel, 0.0)
        self.person_s = np.where(person_ok, new_s, self.person_s)
        self.t = (self.tick + 1) * dt
        self.tick += 1
        clear_r, clear_s, near = self._clearances()

        # A contact episode is recorded once, when the pair first touches; it lasts while the
        # pair stays within CONTACT_RELEASE_M (a bumper that nudges the wall again is one episode).
        keys = {(a, b) for a, b, _ in contacts}
        new = [
            Contact(self.t, a, b, k) for a, b, k in sorted(contacts) if (a, b) not in self._active
        ]
        self._active = keys | (self._active & near)
        return StepResult(new, ~robot_ok, clear_r, clear_s)

    def _blame_people(self, contacts: set, proposed: np.ndarray) -> set:
        """Who is at fault in a skid-person contact: the skid ("robot-person", the fleet's)
        if its own move would have touched the person where the person stood before the step;
        the person ("person-robot", reported, not counted against the fleet) if only the
        person's walk closed the gap, e.g. into a skid standing still or driving away."""
        if not any(k == "robot-person" for _, _, k in contacts):
            return contacts
        index = {rid: i for i, rid in enumerate(self.ids)}
        pidx = {p.id: k for k, p in enumerate(self.people)}
        before = self.person_positions()
        out = set()
        for a, b, k in contacts:
            if k == "robot-person":
                i, j = index[a], pidx[b]
                corners = self.corners(proposed[i : i + 1])
                gap = rect_disc_gap(corners, before[j : j + 1], self.person_radius[j : j + 1])
                k = "robot-person" if gap[0] < -TOUCH_TOLERANCE_M else "person-robot"
            out.add((a, b, k))
        return out

    def _people_react(self, new_s: np.ndarray) -> np.ndarray:
        """Walked distances ``new_s`` after the people who react have reacted to the skids
        where they stand now (:mod:`swarmpark.sim.people`)."""
        if not self.reaction.reacts.any():
            return new_s
        centers = pivot_to_center(self.poses, self.center_offset)
        return self.reaction.step(
            self.person_s,
            new_s,
            self.dt,
            self.corners(),
            centers,
            self.circumradius,
            self.vel[:, 0],
        )

    @property
    def person_held(self) -> np.ndarray:
        """``(P,)`` the people who stood or backed off the last step for a skid in their way."""
        return self.reaction.pace <= 0.0

    def _people_progress(self, dt: float) -> np.ndarray:
        if not self.people:
            return self.person_s
        start = np.array([p.start_s for p in self.people])
        speed = np.array([p.speed_mps for p in self.people])
        length = np.array([np.inf if p.loop else p.route_length_m for p in self.people])
        walking = self.t + dt > start + 1e-12
        step = speed * np.clip(self.t + dt - np.maximum(start, self.t), 0.0, dt)
        return np.where(walking, np.minimum(self.person_s + step, length), self.person_s)

    def _collisions(
        self, poses: np.ndarray, person_s: np.ndarray, focus_r: np.ndarray, focus_p: np.ndarray
    ):
        """Overlaps in a candidate configuration, among pairs with a focused member.

        Returns robot and person collision masks and the contact pairs.
        """
        n = self.n
        bad_r = np.zeros(n, dtype=bool)
        bad_p = np.zeros(len(self.people), dtype=bool)
        contacts: set[tuple[str, str, str]] = set()
        corners = self.corners(poses)
        centers = pivot_to_center(poses, self.center_offset)

        # Robot-robot: circumscribed discs on a KD-tree, then the separating-axis test.
        if n > 1 and focus_r.any():
            pairs = cKDTree(centers).query_pairs(2 * self.circumradius.max(), output_type="ndarray")
            if len(pairs):
                i, j = pairs[:, 0], pairs[:, 1]
                dist = np.linalg.norm(centers[i] - centers[j], axis=1)
                keep = (focus_r[i] | focus_r[j]) & (
                    dist < self.circumradius[i] + self.circumradius[j]
                )
                i, j = i[keep], j[keep]
                hit = convex_overlap(corners[i], corners[j]) > TOUCH_TOLERANCE_M
                bad_r[i[hit]] = bad_r[j[hit]] = True
                contacts |= {
                    (self.ids[a], self.ids[b], "robot-robot")
                    for a, b in zip(i[hit], j[hit], strict=True)
                }

        # Robot-static: footprint bounding boxes on the STR-tree of the static pieces.
        fr = np.flatnonzero(focus_r)
        if len(fr):
            lo, hi = corners[fr].min(axis=1), corners[fr].max(axis=1)
            qi, si = self._static_pairs(lo, hi)
            ri = fr[qi]
            hit = convex_overlap(corners[ri], self.static_pieces[si]) > TOUCH_TOLERANCE_M
            bad_r[ri[hit]] = True
            for a, b in zip(ri[hit], si[hit], strict=True):
                owner = self.static_owner[b]
                contacts.add(
                    (self.ids[a], owner, "robot-wall" if owner == "wall" else "robot-obstacle")
                )
            if self._interior is not None:
                near = fr[self._boxes_hold_interior(corners[fr])]
                inside = near[self.world.grid.footprint_hits(corners[near], self._interior)]
                bad_r[inside] = True
                contacts |= {(self.ids[a], "wall", "robot-wall") for a in inside}

        # Robot-person: discs against every footprint within reach.
        if self.people and (focus_r.any() or focus_p.any()):
            ppos = self.person_positions(person_s)
            d = np.linalg.norm(centers[:, None, :] - ppos[None], axis=-1)
            near = d < self.circumradius[:, None] + self.person_radius[None]
            near &= focus_r[:, None] | focus_p[None, :]
            ri, pi = np.nonzero(near)
            if len(ri):
                hit = (
                    rect_disc_gap(corners[ri], ppos[pi], self.person_radius[pi])
                    < -TOUCH_TOLERANCE_M
                )
                bad_r[ri[hit]] = True
                bad_p[pi[hit]] = True
                contacts |= {
                    (self.ids[a], self.people[b].id, "robot-person")
                    for a, b in zip(ri[hit], pi[hit], strict=True)
                }
        return bad_r, bad_p, contacts

    def _static_pairs(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(box, static piece) pairs whose boxes meet (as the pieces' search tree finds them)."""
        return envelope_pairs(lo, hi, self._static_lo, self._static_hi, self._static_tree)

    def _boxes_hold_interior(self, corners: np.ndarray) -> np.ndarray:
        """Bool ``(N,)``: the footprints' bounding boxes hold an interior block cell."""
        r0, c0, r1, c1 = self.world.grid.cell_windows(corners)
        sat = self._interior_sat
        return (sat[r1, c1] - sat[r0, c1] - sat[r1, c0] + sat[r0, c0]) > 0

    def _clearances(self):
        """Per-robot footprint distance to the nearest robot and static solid (capped at
        CLEARANCE_RANGE_M) in the current, collision-free configuration, and the pairs closer
        than CONTACT_RELEASE_M (people included)."""
        n = self.n
        corners = self.corners()
        centers = pivot_to_center(self.poses, self.center_offset)
        clear_r = np.full(n, CLEARANCE_RANGE_M)
        clear_s = np.full(n, CLEARANCE_RANGE_M)
        near: set[tuple[str, str]] = set()
        if n > 1:
            reach = 2 * self.circumradius.max() + CLEARANCE_RANGE_M
            pairs = cKDTree(centers).query_pairs(reach, output_type="ndarray")
            if len(pairs):
                i, j = pairs[:, 0], pairs[:, 1]
                dist = np.linalg.norm(centers[i] - centers[j], axis=1)
                keep = dist - self.circumradius[i] - self.circumradius[j] < CLEARANCE_RANGE_M
                i, j = i[keep], j[keep]
                gap = convex_distance(corners[i], corners[j])
                np.minimum.at(clear_r, i, gap)
                np.minimum.at(clear_r, j, gap)
                close = gap < CONTACT_RELEASE_M
                near |= {
                    (self.ids[a], self.ids[b]) for a, b in zip(i[close], j[close], strict=True)
                }
        lo, hi = corners.min(axis=1) - CLEARANCE_RANGE_M, corners.max(axis=1) + CLEARANCE_RANGE_M
        ri, si = self._static_pairs(lo, hi)
        if len(ri):
            gap = convex_distance(corners[ri], self.static_pieces[si])
            np.minimum.at(clear_s, ri, gap)
            close = gap < CONTACT_RELEASE_M
            near |= {
                (self.ids[a], self.static_owner[b])
                for a, b in zip(ri[close], si[close], strict=True)
            }
        if self.people:
            ppos = self.person_positions()
            d = np.linalg.norm(centers[:, None, :] - ppos[None], axis=-1)
            lim = self.circumradius[:, None] + self.person_radius[None] + CONTACT_RELEASE_M
            ri, pi = np.nonzero(d < lim)
            if len(ri):
                gap = rect_disc_gap(corners[ri], ppos[pi], self.person_radius[pi])
                close = gap < CONTACT_RELEASE_M
                near |= {
                    (self.ids[a], self.people[b].id)
                    for a, b in zip(ri[close], pi[close], strict=True)
                }
        return clear_r, clear_s, near
