"""The path follower on hand-built views: projection onto the path, the lookahead target,
the final approach and which end leads."""

import numpy as np
import pytest
from navkit import make_view

from swarmpark.control.nav.follower import PathFollower, PathState, point_at, station
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


def _follow(pose, path=PATH, reverse=False, lookahead=None):
    view = make_view([pose], [[5.0, 5.0, np.pi / 2]])
    states = [PathState(path=path, reverse=reverse)]
    return PathFollower(FollowerParams()).targets(view, np.array([0]), states, lookahead)


def test_target_is_the_lookahead_point_on_the_path():
    targets, final = _follow([2.0, 3.2, 0.0])
    la = FollowerParams().lookahead_m
    assert not final[0]
    assert targets[0] == pytest.approx([2.0 + la, 3.0, 0.0])
    # Round the corner: the target is on the next segment, heading along it.
    targets, _ = _follow([4.0, 3.0, 0.0])
    assert targets[0] == pytest.approx([5.0, 3.0 + (4.0 - 1.0) + la - 4.0, np.pi / 2])
    # A longer lookahead (RVO's) reaches farther.
    targets, _ = _follow([1.5, 3.0, 0.0], lookahead=3.0)
    assert targets[0, :2] == pytest.approx([4.5, 3.0])


def test_reverse_points_the_target_heading_backwards():
    targets, _ = _follow([2.0, 3.0, np.pi], reverse=True)
    assert abs(targets[0, 2]) == pytest.approx(np.pi)


def test_final_approach_attracts_the_goal_itself():
    # 1.5 m of path left (< approach_m = 2 m): the target is the goal pose.
    targets, final = _follow([5.0, 3.5, np.pi / 2])
    assert final[0]
    assert targets[0] == pytest.approx([5.0, 5.0, np.pi / 2])
    # No path yet: the goal as well.
    targets, final = _follow([2.0, 3.0, 0.0], path=None)
    assert final[0] and targets[0] == pytest.approx([5.0, 5.0, np.pi / 2])


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
