"""The collision monitor (as Navigation2's): each command is simulated forward over a short
horizon, within the acceleration limits, and slowed or stopped before any contact with static
solids, other skids (where they stand) and people (walking on)."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from swarmpark.control.base import ControlView
from swarmpark.control.nav.kernels import (
    hits_against_skids,
    pairs_touching,
    rollout_corners,
    rollout_poses,
)
from swarmpark.control.nav.params import MonitorParams
from swarmpark.control.nav.scene import Scene
from swarmpark.core.geometry import (
    TOUCH_TOLERANCE_M,
    convex_overlap,
    envelope_pairs,
    footprint_corners,
    rect_disc_gap,
)

__all__ = ["CollisionMonitor", "MonitorResult", "rollout"]


def _bounds(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``corners.min(axis=1), corners.max(axis=1)`` of footprints ``(N, 4, 2)``, elementwise
    over the four corners (the same values; numpy's reduction over a short middle axis is
    several times slower)."""
    c = corners
    lo = np.minimum(np.minimum(c[:, 0], c[:, 1]), np.minimum(c[:, 2], c[:, 3]))
    hi = np.maximum(np.maximum(c[:, 0], c[:, 1]), np.maximum(c[:, 2], c[:, 3]))
    return lo, hi


def _centres(corners: np.ndarray) -> np.ndarray:
    """``corners.mean(axis=1)`` of footprints ``(N, 4, 2)``, summed in the same order."""
    c = corners
    return (((c[:, 0] + c[:, 1]) + c[:, 2]) + c[:, 3]) / 4.0


def rollout(
    view: ControlView, rows: np.ndarray, v_cmd: np.ndarray, w_cmd, times: np.ndarray
) -> np.ndarray:
    """Poses ``(len(rows), T, 3)`` of skids ``rows`` at ``times`` under the commands held,
    from their current velocities within the acceleration limits (a skid turning fast
    cannot stop turning at once), integrated in control steps as the simulator does
    (:func:`~swarmpark.core.geometry.integrate_unicycle`)."""
    n_sub = max(1, int(round(times[-1] / view.dt)))
    sub_dt = times[-1] / n_sub
    record = np.clip(np.round(times / sub_dt), 1, n_sub).astype(np.int64)
    n = len(rows)
    dv = np.broadcast_to(view.max_accel[rows] * sub_dt, (n,))
    dw = np.full(n, np.inf) if view.max_yaw_accel is None else view.max_yaw_accel[rows] * sub_dt
    # Compiled (kernels.rollout_poses): the same arithmetic as one numpy call per sub-step.
    return rollout_poses(
        np.ascontiguousarray(view.poses[rows], dtype=float),
        np.ascontiguousarray(view.vel[rows, 0], dtype=float),
        np.ascontiguousarray(view.vel[rows, 1], dtype=float),
        np.ascontiguousarray(np.broadcast_to(v_cmd, (n,)), dtype=float),
        np.ascontiguousarray(np.broadcast_to(w_cmd, (n,)), dtype=float),
        np.ascontiguousarray(dv, dtype=float),
        np.ascontiguousarray(np.broadcast_to(dw, (n,)), dtype=float),
        float(sub_dt),
        n_sub,
        record,
    )


def _swept(
    view: ControlView, rows: np.ndarray, cmd: np.ndarray, body: np.ndarray, times: np.ndarray
) -> np.ndarray:
    """Footprints ``(len(rows), T, 4, 2)`` of skids ``rows`` (body-frame corners ``body``)
    at ``times`` under the commands ``cmd`` held (:func:`rollout`)."""
    pose = rollout(view, rows, cmd[:, 0], cmd[:, 1], times)
    return rollout_corners(pose.reshape(-1, 3), body, len(times)).reshape(
        len(rows), len(times), 4, 2
    )


@dataclass(frozen=True)
class MonitorResult:
    """The safe commands ``(len(idx), 2)``, per row the skids that slowed it at full speed
    (empty unless it was slowed), and whether it was slowed."""

    commands: np.ndarray
    blockers: list[set[int]]
    slowed: np.ndarray


class CollisionMonitor:
    """Scales each command down until its forward simulation is collision-free.

    Parameters
    ----------
    params
        :class:`~swarmpark.control.nav.params.MonitorParams`.
    """

    def __init__(self, params: MonitorParams) -> None:
        self.params = params
        p = params
        self.scales = np.asarray(p.scales)
        self._coarse = np.linspace(p.horizon_s / p.samples, p.horizon_s, p.samples)
        self.times, self._dt = self._coarse, None
        self._fps, self._fps_reach = None, 0.0

    def _sample_times(self, dt: float) -> None:
        """Set :attr:`times` for control step ``dt``: the horizon's ``samples`` and every step
        over its first ``step_samples_s``."""
        if dt == self._dt:
            return
        steps = dt * np.arange(1, int(np.floor(self.params.step_samples_s / dt + 1e-9)) + 1)
        times = np.concatenate([steps[steps < self._coarse[-1] - 1e-9], self._coarse])
        times = np.unique(np.round(times, 9))
        self.times, self._dt = times, dt

    def check(
        self,
        view: ControlView,
        idx: np.ndarray,
        raw: np.ndarray,
        scene: Scene,
        *,
        robots: bool = True,
        joint: bool = False,
        straight: bool = False,
    ) -> MonitorResult:
        """Safe commands for robots ``idx`` commanded ``raw`` (others where they are now);
        with ``joint``, also stop pairs whose commands together would bring them into
        contact (:meth:`joint_check`); with ``straight``, a skid whose every speed collides
        only because of its turn drives on straight when that is safe. ``robots=False``
        ignores the other skids."""
        self._sample_times(view.dt)
        scales, S = self.scales, len(self.scales)
        body = scene.skids.grown[idx]
        plain = scene.skids.plain[idx]
        # A skid already inside its margin of something is judged by its plain footprint, or it
        # could never move away again.
        others = footprint_corners(view.poses, scene.skids.plain)
        inside = self.within_margin(view, idx, body, scene, others)
        body = np.where(inside[:, None, None], plain, body)
        bad, blockers = self._unsafe(view, idx, raw, body, scene, others, robots)
        # The fastest safe scale; if even turning in place collides, stop turning as well.
        safe = ~bad.any(axis=2)
        stuck = ~safe.any(axis=1)
        first_safe = np.where(stuck, S - 1, np.argmax(safe, axis=1))
        out = raw.copy()
        out[:, 0] *= scales[first_safe]
        out[stuck] = 0.0
        # A skid whose turn is what collides (its corner swings into a wall it drives along)
        # drives on straight instead, if that is safe, until it has room to turn.
        if straight:
            self._straight_on(view, idx, raw, out, stuck, body, scene, others, robots)
        self._slower_turn(view, idx, raw, out, stuck, body, scene, others, robots)
        slowed = first_safe > 0
        for b, s in zip(blockers, slowed.tolist(), strict=True):
            if b and not s:
                b.clear()  # only a skid slowed down was held up by the others
        if joint and robots:
            self.joint_check(view, idx, out, body)
        elif robots:
            self.close_pairs(view, idx, out, scene, blockers)
        return MonitorResult(out, blockers, slowed)

    def _straight_on(self, view, idx, raw, out, stuck, body, scene, others, robots) -> None:
        """Rows ``stuck`` (no speed safe with their turn) that drive and turn get the fastest
        safe speed without the turn, if one is above 0 (in place on ``out``)."""
        turn = np.flatnonzero(stuck & (raw[:, 0] != 0.0) & (raw[:, 1] != 0.0))
        if not len(turn):
            return
        cmd = np.column_stack([raw[turn, 0], np.zeros(len(turn))])
        bad, _ = self._unsafe(view, idx[turn], cmd, body[turn], scene, others, robots)
        safe = ~bad.any(axis=2)
        ok = safe.any(axis=1) & (np.argmax(safe, axis=1) < len(self.scales) - 1)
        k = turn[ok]
        out[k, 0] = raw[k, 0] * self.scales[np.argmax(safe[ok], axis=1)]
        out[k, 1] = 0.0

    def _slower_turn(self, view, idx, raw, out, stuck, body, scene, others, robots) -> None:
        """Rows ``stuck`` (no speed safe) that only turn on the spot get the fastest of the
        turn rate's shares ``scales[1:-1]`` that is safe, if any (in place on ``out``). The
        rollout holds the rate for the whole horizon, past where a turn ending short of a
        neighbour would stop: a skid 10 deg from the end of a turn (braking onto it, 0.5
        rad/s) was refused again and again beside a parked neighbour on a generated open
        deck, where 0.3 rad/s was safe."""
        turn = np.flatnonzero(stuck & (raw[:, 0] == 0.0) & (raw[:, 1] != 0.0))
        for share in self.scales[1:-1]:
            if not len(turn):
                return
            cmd = np.column_stack([np.zeros(len(turn)), raw[turn, 1] * share])
            bad, _ = self._unsafe(view, idx[turn], cmd, body[turn], scene, others, robots)
            ok = ~bad[:, -1].any(axis=1)
            out[turn[ok]] = cmd[ok]
            turn = turn[~ok]

    def _unsafe(self, view, idx, raw, body, scene, others, robots: bool):
        """``(n, S, T)`` whether skid ``idx[k]`` commanded ``raw[k]`` at speed scale ``s``
        touches something at rollout time ``t``, and who (other skids) it would touch."""
        scales, times = self.scales, self.times
        n_act, S, T = len(idx), len(scales), len(times)
        # Poses for every (robot, scale, time), from the current velocity towards the command.
        v_cmd = (raw[:, 0][:, None] * scales[None, :]).ravel()
        w_cmd = np.repeat(raw[:, 1], S)
        pose = rollout(view, np.repeat(idx, S), v_cmd, w_cmd, times).reshape(-1, 3)
        owner = np.repeat(np.arange(n_act), S * T)
        corners = rollout_corners(pose, np.ascontiguousarray(body, dtype=float), S * T)
        bad = self._hits_static(view, corners, scene, group=S * T)
        blockers = self._hits_skids(view, idx, corners, owner, bad, others, scene, robots)
        self._hits_people(view, corners, n_act, bad)
        return bad.reshape(n_act, S, T), blockers

    @staticmethod
    def _hits_static(
        view: ControlView, corners: np.ndarray, scene: Scene, group: int = 1
    ) -> np.ndarray:
        """Which footprints ``corners`` overlap a static solid. The footprints come in runs of
        ``group`` (one skid's rollout): the STR-tree is asked once per run, for the box around
        it, and the pairs are then narrowed to the footprints whose own box meets the piece's."""
        bad = np.zeros(len(corners), dtype=bool)
        lo, hi = _bounds(corners)
        glo = lo.reshape(-1, group, 2).min(axis=1)
        ghi = hi.reshape(-1, group, 2).max(axis=1)
        st = scene.static
        gi, si = envelope_pairs(glo, ghi, st.lo, st.hi, st.tree)
        if len(gi):
            qi = (gi[:, None] * group + np.arange(group)).ravel()
            si = np.repeat(si, group)
            meet = np.all((lo[qi] <= st.hi[si]) & (hi[qi] >= st.lo[si]), axis=1)
            qi, si = qi[meet], si[meet]
            hit = convex_overlap(corners[qi], view.static_pieces[si]) > TOUCH_TOLERANCE_M
            bad[qi[hit]] = True
        return bad

    def _hits_skids(self, view, idx, corners, owner, bad, others, scene: Scene, robots: bool):
        """Mark (in ``bad``) footprints overlapping other skids where they stand (``others``:
        their corners); returns per robot row the skids hit at full speed."""
        S, T = len(self.scales), len(self.times)
        blockers: list[set[int]] = [set() for _ in range(len(idx))]
        if not robots or not len(idx):
            return blockers
        centres = _centres(corners)
        other_c = _centres(others)
        radius = scene.skids.max_circumradius * 2 + self.params.margin_m
        # One search per skid, around its first rollout pose and wide enough for its whole
        # rollout; then the footprint-skid pairs closer than ``radius`` (as one search per
        # footprint would find them).
        hub = centres[:: S * T]
        run = centres.reshape(len(idx), S * T, 2)
        spread = np.linalg.norm(run - hub[:, None], axis=2).max(axis=1)
        cand = cKDTree(other_c).query_ball_point(hub, radius + spread + 1e-6)
        lens = np.fromiter(map(len, cand), int, len(cand))
        rb = np.fromiter(itertools.chain.from_iterable(cand), int, int(lens.sum()))
        ra = np.repeat(np.arange(len(idx)), lens)
        keep = rb != idx[ra]
        ra, rb = ra[keep], rb[keep]
        # Each footprint against each candidate skid (compiled: kernels.hits_against_skids).
        qa, qb = hits_against_skids(
            ra.astype(np.int64),
            rb.astype(np.int64),
            np.ascontiguousarray(centres),
            np.ascontiguousarray(other_c),
            np.ascontiguousarray(corners, dtype=float),
            np.ascontiguousarray(others, dtype=float),
            float(radius),
            S * T,
            TOUCH_TOLERANCE_M,
            bad,
        )
        full_speed = (qa // T) % S == 0
        for a, b in zip(owner[qa[full_speed]].tolist(), qb[full_speed].tolist(), strict=True):
            blockers[a].add(b)
        return blockers

    def _hits_people(self, view: ControlView, corners, n_act: int, bad: np.ndarray) -> None:
        """Mark (in ``bad``) footprints overlapping a person walking on at their velocity."""
        if not len(view.people_xy):
            return
        tt = np.tile(np.repeat(self.times, 1), n_act * len(self.scales))
        for k in range(len(view.people_xy)):
            centre = view.people_xy[k] + view.people_vel[k] * tt[:, None]
            gap = rect_disc_gap(corners, centre, np.full(len(corners), view.people_radius[k]))
            bad |= gap < 0

    def within_margin(
        self,
        view: ControlView,
        idx: np.ndarray,
        grown: np.ndarray,
        scene: Scene,
        others: np.ndarray | None = None,
    ) -> np.ndarray:
        """Skids whose grown footprint overlaps a static solid or another skid right now
        (``others``: all skids' plain corners where they stand, if known)."""
        corners = footprint_corners(view.poses[idx], grown)
        out = self._hits_static(view, corners, scene)
        if not len(idx):
            return out
        if others is None:
            others = footprint_corners(view.poses, scene.skids.plain)
        xy = view.poses[:, :2]
        rng = self.params.neighbour_range_m
        cand = cKDTree(xy).query_ball_point(xy[idx], rng)
        lens = np.fromiter(map(len, cand), int, len(cand))
        ib = np.fromiter(itertools.chain.from_iterable(cand), int, int(lens.sum()))
        ia = np.repeat(np.arange(len(idx)), lens)
        dist = np.linalg.norm(xy[idx[ia]] - xy[ib], axis=1)
        # Only skids whose discs around the pivot (through the farthest corner) meet can
        # overlap: the exact test is left for those.
        r_a = np.linalg.norm(corners - xy[idx, None], axis=2).max(axis=1)
        r_b = np.linalg.norm(others - xy[:, None], axis=2).max(axis=1)
        near = (dist < rng) & (dist <= r_a[ia] + r_b[ib] + 1e-6)
        near &= idx[ia] != ib
        ia, ib = ia[near], ib[near]
        if len(ia):
            hit = convex_overlap(corners[ia], others[ib]) > TOUCH_TOLERANCE_M
            out[ia[hit]] = True
        return out

    def _max_circumradius(self, fps) -> float:
        """The largest circumradius of footprints ``fps``, kept while they stay the same."""
        if fps is not self._fps:
            self._fps, self._fps_reach = fps, max(f.circumradius_m for f in fps)
        return self._fps_reach

    def close_pairs(
        self,
        view: ControlView,
        idx: np.ndarray,
        out: np.ndarray,
        scene: Scene,
        blockers: list[set[int]],
    ) -> None:
        """Of two skids already within their margins of each other whose commands, held
        together, bring them into contact within the horizon, the one of lower rank stops
        (in place on ``out``; the other is added to its ``blockers``).

        With ``pairs_closing`` (the default) every pair within reach of each other counts,
        not only those already within their margins: a skid turning in place sweeps its
        corners out while the skid driving up behind it takes it as standing (each safe
        against the other standing, they touched on generated hangar and open-deck sites).

        Each skid's own check takes the others as standing still, and a skid inside its
        margin is judged by its plain footprint (or it could never move away). Side by side
        that is not enough: two skids 2 cm apart, one driving along the other's side while
        the other's corner swings in, each safe against the other standing, touched on a
        generated L bay. Rank as for giving way (:class:`~.recovery.GiveWay`): priority,
        then nearer its goal, then lower index. The skid that goes on is safe against the
        stopped one standing, so the pair parts. Stopping both (the joint check of the RVO
        mode, for every pair) stalled pairs for good in this mode. If the stopped skid's
        braking still meets the other's move, the other stops too.

        Pairs are taken within reach of each other plus the distance both can travel over the
        horizon (each at the faster of its current and commanded speed). Within reach alone,
        two skids closing head-on at full speed came into the check 0.2 s before contact, too
        late to brake; with docking and manoeuvres at full speed that gave two contacts on
        the 84 training draws, and none with the wider search.

        Two skids farther apart than the monitor's ``margin_m`` must stay that far apart (each
        footprint grown by half of it); only pairs already closer, and the check that stops
        both, are judged by their plain footprints. Judged by plain footprints always, two
        skids turning towards each other on a generated open deck closed to 1 cm between
        their estimates, and 1.2 cm of relative localization error made that a contact.
        """
        self._sample_times(view.dt)
        moving = np.flatnonzero(np.any(out != 0.0, axis=1))
        if len(moving) < 2:
            return
        rows = idx[moving]
        reach = 2.0 * self._max_circumradius(view.footprints) + 2.0 * self.params.margin_m
        # Two skids can close by as much as both travel over the horizon, at the faster of
        # their current and commanded speeds.
        h = float(self.times[-1])
        speed = np.maximum(np.abs(view.vel[rows, 0]), np.abs(out[moving, 0]))
        xy = view.poses[rows, :2]
        pairs = cKDTree(xy).query_pairs(reach + 2.0 * h * speed.max(), output_type="ndarray")
        if len(pairs):
            gap = np.linalg.norm(xy[pairs[:, 0]] - xy[pairs[:, 1]], axis=1)
            pairs = pairs[gap <= reach + h * (speed[pairs[:, 0]] + speed[pairs[:, 1]])]
        if not len(pairs):
            return
        pairs = pairs.astype(np.int64)
        if not self.params.pairs_closing:
            grown = np.ascontiguousarray(scene.skids.grown[rows], dtype=float)
            now = np.ascontiguousarray(footprint_corners(view.poses[rows], grown)[:, None])
            pairs = pairs[pairs_touching(pairs, now, TOUCH_TOLERANCE_M)]
            if not len(pairs):
                return
        # Only the skids of those pairs are rolled out (most skids on the move have none).
        members, inverse = np.unique(pairs.ravel(), return_inverse=True)
        pairs = inverse.reshape(-1, 2).astype(np.int64)
        moving, rows = moving[members], rows[members]
        plain = np.ascontiguousarray(scene.skids.plain[rows], dtype=float)
        # Each footprint grown by half the margin: two of them touch when the plain ones come
        # within the margin of each other.
        half = np.ascontiguousarray(0.5 * (plain + scene.skids.grown[rows]), dtype=float)
        # Pairs farther apart now than the margin keep it; pairs already within it must not
        # touch (or they could never part).
        now = np.ascontiguousarray(footprint_corners(view.poses[rows], half)[:, None])
        apart = ~pairs_touching(pairs, now, TOUCH_TOLERANCE_M)

        def touching(cmd: np.ndarray, keep: np.ndarray) -> np.ndarray:
            """Pairs whose swept footprints touch (grown by half the margin where ``keep``)."""
            pose = rollout(view, rows, cmd[:, 0], cmd[:, 1], self.times).reshape(-1, 3)
            out = np.zeros(len(pairs), dtype=bool)
            for sel, body in ((keep, half), (~keep, plain)):
                if sel.any():
                    swept = rollout_corners(pose, body, len(self.times))
                    swept = swept.reshape(len(rows), len(self.times), 4, 2)
                    out[sel] = pairs_touching(pairs[sel], swept, TOUCH_TOLERANCE_M)
            return out

        hit = touching(out[moving], apart)
        if not hit.any():
            return
        to_goal = np.linalg.norm(view.poses[rows, :2] - view.goals[rows, :2], axis=1)
        key = np.lexsort((rows, np.nan_to_num(to_goal, nan=np.inf), -view.priority[rows]))
        rank = np.empty(len(rows), int)
        rank[key] = np.arange(len(rows))  # 0 = highest
        for a, b in pairs[hit]:
            lo, hi = (a, b) if rank[a] > rank[b] else (b, a)
            out[moving[lo]] = 0.0
            blockers[moving[lo]].add(int(rows[hi]))
        again = touching(out[moving], np.zeros(len(pairs), dtype=bool))
        for a, b in pairs[again]:
            out[moving[a]] = out[moving[b]] = 0.0

    def joint_check(
        self, view: ControlView, idx: np.ndarray, out: np.ndarray, body: np.ndarray
    ) -> None:
        """Stop the pairs of skids whose commands, held together, bring them into contact
        within the horizon (in place on ``out``).

        Each skid's own check treats the others as standing still; two skids turning in
        place next to each other, each safe alone, can still swing their corners together.
        ORCA should prevent that, but its guarantee is for one step and holonomic centres.
        The stopped skids' braking is rolled out again, until no new pair is found.
        """
        self._sample_times(view.dt)
        times = self.times
        reach = self._max_circumradius(view.footprints) * 2.0
        # Two skids closing at their current speed plus their top speed over the horizon.
        speed = np.abs(view.vel[idx, 0]).max(initial=0.0) + view.max_speed[idx].max()
        pairs = cKDTree(view.poses[idx, :2]).query_pairs(
            reach + 2.0 * speed * times[-1], output_type="ndarray"
        )
        body = np.ascontiguousarray(body, dtype=float)
        corners, test, bad = None, pairs, np.zeros(0, dtype=int)
        while len(test):
            if corners is None:
                corners = _swept(view, idx, out, body, times)
            else:
                # Only the skids stopped in the last pass move differently: roll them out
                # again, and test the pairs with one of them (the others' verdicts stand, and
                # their skids were stopped already).
                corners[bad] = _swept(view, idx[bad], out[bad], body[bad], times)
                moved = np.zeros(len(idx), dtype=bool)
                moved[bad] = True
                test = pairs[moved[pairs[:, 0]] | moved[pairs[:, 1]]]
            hit = pairs_touching(test.astype(np.int64), corners, TOUCH_TOLERANCE_M)
            bad = np.unique(test[hit])
            bad = bad[np.any(out[bad] != 0.0, axis=1)]
            if not len(bad):
                return
            out[bad] = 0.0
