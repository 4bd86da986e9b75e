"""The path follower on hand-built views: projection onto the path, the lookahead target,
the final approach and which end leads."""

import numpy as np
import pytest
from navkit import make_view

from swarmpark.control.nav.follower import (
    PackedPaths,
    PathFollower,
    PathState,
    paths_ahead,
    point_at,
    station,
)
from swarmpark.control.nav.params import FollowerParams

PATH = np.array([[1.0, 3.0], [5.0, 3.0], [5.0, 5.0]])  # 4 m along x, then 2 m up


def test_station_and_point_at_walk_the_polyline():
    cum, seg, s = station(PATH, np.array([3.0, 3.4]))
    assert cum.tolist() == [0.0, 4.0, 6.0]
    assert seg == 0 and s == pytest.approx(2.0)
    cum, seg, s = station(PATH, np.array([5.3, 4.0]))
    assert seg == 1 and s == pytest.approx(5.0)
    pt, m = point_at(PATH, cum, 4.5)
    assert pt == pytest.approx([5.0, 3.5]) and m == 1
    pt, _ = point_at(PATH, cum, 6.0)
    assert pt == pytest.approx([5.0, 5.0])


def _follow(pose, path=PATH, reverse=False, lookahead=None, goal_yaw=0.0):
    """Targets on ``PATH``; with the goal heading 0 its last segment is no run along the goal's
    axis (``np.pi / 2``: it is, and the path turns onto it at (5, 3) by 90 deg)."""
    view = make_view([pose], [[5.0, 5.0, goal_yaw]])
    states = [PathState(path=path, reverse=reverse)]
    return PathFollower(FollowerParams()).targets(view, np.array([0]), states, lookahead)


def test_target_is_the_lookahead_point_on_the_path():
    targets, final, stage_left = _follow([2.0, 3.2, 0.0])
    la = FollowerParams().lookahead_m
    assert not final[0] and stage_left[0] == np.inf
    assert targets[0] == pytest.approx([2.0 + la, 3.0, 0.0])
    # Round the corner: the target is on the next segment, heading along it.
    targets, _, _ = _follow([4.0, 3.0, 0.0])
    assert targets[0] == pytest.approx([5.0, 3.0 + (4.0 - 1.0) + la - 4.0, np.pi / 2])
    # A longer lookahead (RVO's) reaches farther.
    targets, _, _ = _follow([1.5, 3.0, 0.0], lookahead=3.0)
    assert targets[0, :2] == pytest.approx([4.5, 3.0])


def test_a_skid_drives_to_its_staging_point_before_turning_onto_the_axis():
    # The last segment runs along the goal's axis and the path turns onto it by 90 deg at
    # (5, 3): the target stays on the staging point, not round the corner, and the path left
    # to it is reported (the navigator brakes on it) ...
    targets, final, stage_left = _follow([4.0, 3.0, 0.0], goal_yaw=np.pi / 2)
    assert not final[0] and stage_left[0] == pytest.approx(1.0)
    assert targets[0] == pytest.approx([5.0, 3.0, 0.0])
    # ... also within approach_m of the goal (2 m; the lookahead point short of the staging
    # point), until within stage_reach_m of it.
    targets, final, stage_left = _follow([3.5, 3.0, 0.0], goal_yaw=np.pi / 2)
    assert not final[0] and stage_left[0] == pytest.approx(1.5)
    assert targets[0] == pytest.approx([3.5 + FollowerParams().lookahead_m, 3.0, 0.0])
    # Aiming at the staging point, straight at it from where the skid stands.
    targets, _, _ = _follow([4.2, 3.3, 0.0], goal_yaw=np.pi / 2)
    assert targets[0] == pytest.approx([5.0, 3.0, np.arctan2(-0.3, 0.8)])
    targets, final, stage_left = _follow([5.0, 3.05, 0.0], goal_yaw=np.pi / 2)
    assert final[0] and stage_left[0] == np.inf
    assert targets[0] == pytest.approx([5.0, 5.0, np.pi / 2])


def test_reverse_points_the_target_heading_backwards():
    targets, _, _ = _follow([2.0, 3.0, np.pi], reverse=True)
    assert abs(targets[0, 2]) == pytest.approx(np.pi)


def test_final_approach_attracts_the_goal_itself():
    # 1.5 m of path left (< approach_m = 2 m): the target is the goal pose.
    targets, final, _ = _follow([5.0, 3.5, np.pi / 2])
    assert final[0]
    assert targets[0] == pytest.approx([5.0, 5.0, 0.0])
    # No path yet: the goal as well.
    targets, final, _ = _follow([2.0, 3.0, 0.0], path=None)
    assert final[0] and targets[0] == pytest.approx([5.0, 5.0, 0.0])


@pytest.mark.parametrize(
    ("yaw_deg", "reverse"), [(0, False), (100, False), (150, True), (-170, True)]
)
def test_a_fresh_path_is_led_by_the_end_facing_it(yaw_deg, reverse):
    view = make_view([[1.0, 3.0, np.deg2rad(yaw_deg)]], [[5.0, 5.0, 0.0]])
    assert PathFollower(FollowerParams()).choose_end(view, 0, PATH) is reverse


def test_near_the_goal_the_shorter_arc_leads_with_hysteresis():
    fol = PathFollower(FollowerParams())
    # Goal 1 m straight behind the skid, facing like it: the rear has the shorter arc.
    view = make_view([[4.0, 3.0, 0.0]], [[3.0, 3.0, 0.0]])
    states = [PathState(reverse=False)]
    rev = fol.update_ends(view, np.array([0]), np.array([True]), states)
    assert rev[0] and states[0].reverse
    # Not in the final approach: the end stays as it is.
    states = [PathState(reverse=False)]
    rev = fol.update_ends(view, np.array([0]), np.array([False]), states)
    assert not rev[0] and not states[0].reverse
    # Nearly the same arcs for both ends (goal beside the skid): no switching back and forth.
    view = make_view([[4.0, 3.0, 0.0]], [[4.0, 4.0, 0.0]])
    for start in (False, True):
        states = [PathState(reverse=start)]
        rev = fol.update_ends(view, np.array([0]), np.array([True]), states)
        assert rev[0] == start


def test_is_for_compares_the_goal():
    st = PathState(path_goal=np.array([1.0, 2.0, 0.5]))
    assert st.is_for(np.array([1.0, 2.0, 0.5]))
    assert not st.is_for(np.array([1.0, 2.0, 0.6]))
    assert not PathState().is_for(np.array([1.0, 2.0, 0.5]))


def _targets_one_by_one(view, idx, states, params, lookahead_m):
    """The follower's targets computed robot by robot with station/point_at (the reference
    the fleet-wide arrays must match bit for bit)."""
    from swarmpark.core.geometry import wrap_angle

    targets = view.goals[idx].copy()
    final = np.ones(len(idx), dtype=bool)
    for k, i in enumerate(idx):
        path = states[i].path
        if path is None or len(path) < 2:
            continue
        cum, _, s_here = station(path, view.poses[i, :2])
        if cum[-1] - s_here <= params.approach_m:
            continue
        final[k] = False
        pt, m = point_at(path, cum, min(s_here + lookahead_m, cum[-1]))
        seg = path[m + 1] - path[m]
        heading = np.arctan2(seg[1], seg[0]) + (np.pi if states[i].reverse else 0.0)
        targets[k] = [pt[0], pt[1], wrap_angle(heading)]
    return targets, final


def test_fleet_targets_match_the_per_robot_projection_exactly():
    rng = np.random.default_rng(3)
    n = 40
    poses = np.column_stack([rng.uniform(0, 10, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    goals = np.column_stack([rng.uniform(0, 10, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    view = make_view(poses, goals)
    params = FollowerParams()
    fol = PathFollower(params)

    def random_path(k):
        if k == 0:
            return None
        return np.cumsum(rng.uniform(-2, 2, (k, 2)), axis=0) + rng.uniform(0, 10, 2)

    states = [
        PathState(path=random_path(int(rng.integers(0, 9))), reverse=bool(rng.integers(2)))
        for _ in range(n)
    ]
    idx = np.flatnonzero(rng.random(n) < 0.8)
    for round_ in range(3):  # replaced paths (longer ones too) refill their rows
        for la in (params.lookahead_m, 3.0):
            got = fol.targets(view, idx, states, la)
            want = _targets_one_by_one(view, idx, states, params, la)
            assert np.array_equal(got[1], want[1])
            assert np.array_equal(got[0], want[0])  # bit for bit
        assert (~want[1]).sum() > 5  # the lookahead branch was exercised
        for i in rng.choice(n, 10, replace=False):
            states[i].path = random_path(int(rng.integers(0, 6 + 10 * round_)))


def test_paths_ahead_match_the_path_walked_one_skid_at_a_time():
    """Each mover's way for making room: from its rear (its front when reversing) through
    its pivot and the path's vertices to ``length_m`` ahead of where it projects, bit for bit
    as walked with :func:`station` and :func:`point_at` one skid at a time."""
    rng = np.random.default_rng(5)
    n = 30
    poses = np.column_stack([rng.uniform(0, 10, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    view = make_view(poses, poses.copy())
    states = [
        PathState(
            path=None if k % 7 == 0 else np.cumsum(rng.uniform(-2, 2, (k % 6 + 2, 2)), axis=0),
            reverse=bool(k % 3 == 0),
        )
        for k in range(n)
    ]
    rows = np.flatnonzero(rng.random(n) < 0.7)
    got = paths_ahead(view, rows, states, PackedPaths(), 2.5)
    for line, i in zip(got, rows.tolist(), strict=True):
        pose, fp, st = view.poses[i], view.footprints[i], states[i]
        head = np.array([np.cos(pose[2]), np.sin(pose[2])])
        back = pose[:2] - head * (fp.length_m - fp.pivot if st.reverse else fp.pivot)
        if st.path is None:
            want = np.vstack([back, pose[:2]])
        else:
            cum, j, s_here = station(st.path, pose[:2], st.geometry())
            end = min(s_here + 2.5, cum[-1])
            tip, _ = point_at(st.path, cum, end)
            want = np.vstack([back, pose[:2], st.path[j + 1 :][cum[j + 1 :] < end], tip])
        np.testing.assert_array_equal(line, want)
    assert sum(len(line) > 3 for line in got) > 5  # vertices inside the lookahead were kept


def test_waiting_is_false_only_for_a_plan_made_for_the_current_goal():
    view = make_view([[1.0, 1.0, 0.0]] * 3, [[5.0, 5.0, 0.5]] * 3)
    states = [
        PathState(),
        PathState(path_goal=np.array([5.0, 5.0, 0.5])),
        PathState(path_goal=np.array([5.0, 5.1, 0.5])),
    ]
    fol = PathFollower(FollowerParams())
    assert fol.waiting(view, np.arange(3), states).tolist() == [True, False, True]
    states[2].path_goal = np.array([5.0, 5.0, 0.5])  # planned anew for the current goal
    assert fol.waiting(view, np.arange(3), states).tolist() == [True, False, False]
