"""People's right of way (control/nav/people.py): skids stop short of a person's predicted
walk and step out of it when the person would walk into them where they stand."""

from dataclasses import replace

import numpy as np
import pytest
from navkit import FOOTPRINT, make_view

from swarmpark.control.nav.navigator import Navigator
from swarmpark.control.nav.params import NavParams, PeopleParams
from swarmpark.control.nav.people import PeopleYield
from swarmpark.control.nav.scene import Scene
from swarmpark.core.geometry import footprint_corners, integrate_unicycle, rect_disc_gap

RADIUS = 0.25


def _scene(view):
    return Scene(0.1, 0.03).update(view)


def _gap(pose, xy):
    corners = footprint_corners(np.asarray(pose)[None], FOOTPRINT.corners_body()[None])
    return float(rect_disc_gap(corners, np.asarray(xy)[None], np.array([RADIUS]))[0])


def _walk_at_parked_skid(params: NavParams, seconds: float = 6.0, pose=(5.0, 3.0, 0.0)):
    """A person walks south at 1.2 m/s along x = 5 m past a skid parked at ``pose`` (its goal
    is where it stands; by default straight across the walk); returns the smallest gap and
    the skid's last pose."""
    nav = Navigator(params)
    pose = np.array([pose], dtype=float)
    goal = pose.copy()
    person, vel = np.array([5.0, 5.8]), np.array([0.0, -1.2])
    v = np.zeros((1, 2))
    dt, gaps = 0.05, []
    for k in range(int(seconds / dt)):
        view = make_view(
            pose,
            goal,
            t=k * dt,
            dt=dt,
            vel=v,
            people_xy=person,
            people_vel=vel,
            people_radius=[RADIUS],
        )
        cmd = nav.compute(view)
        # Within the acceleration limit (1 m/s^2), as the simulator drives it.
        v = v + np.clip(cmd - v, -1.0 * dt, 1.0 * dt)
        pose = integrate_unicycle(pose, v[:, 0], v[:, 1], dt)
        person = person + vel * dt
        gaps.append(_gap(pose[0], person))
    return min(gaps), pose[0]


def test_a_parked_skid_steps_out_of_the_way_of_a_person_walking_at_it():
    gap, pose = _walk_at_parked_skid(NavParams())
    assert gap > 0.0  # the person passed without touching it
    assert abs(pose[1] - 3.0) < 0.05  # it moved along its axis, not sideways
    # Without the right of way the person walks into the skid standing there.
    off, still = _walk_at_parked_skid(NavParams(people=PeopleParams(enabled=False)))
    assert off < 0.0
    assert np.allclose(still[:2], [5.0, 3.0], atol=0.02)


def test_a_parked_skid_beside_a_walk_along_its_axis_stays():
    # Parked heading north 0.85 m beside the walk (0.2 m between its side and the person, inside
    # the make-room corridor): stepping along its axis would only drive it ahead of the
    # person, so it keeps its spot and the person passes beside it.
    gap, pose = _walk_at_parked_skid(NavParams(), pose=(5.85, 3.0, np.pi / 2))
    assert gap > 0.1
    assert np.allclose(pose[:2], [5.85, 3.0], atol=0.005)  # (it drove 5 cm without the rule)


def test_a_skid_steps_aside_on_the_side_it_reaches_first():
    view = make_view(
        [[5.0, 3.0, 0.0]],
        vel=[[0.5, 0.0]],  # already driving forward: ahead is quicker than back
        people_xy=[4.95, 5.0],  # a little behind its centre
        people_vel=[[0.0, -1.2]],
        people_radius=[RADIUS],
    )
    res = PeopleYield(PeopleParams()).step(view, np.array([0]), np.zeros((1, 2)), _scene(view))
    assert res.stepping_aside[0]
    assert res.commands[0, 0] > 0.0 and res.commands[0, 1] == 0.0


def test_a_skid_stops_short_of_a_predicted_walk_and_goes_on_when_it_is_clear():
    yielder = PeopleYield(PeopleParams())
    # Driving east at 0.5 m/s; a person 2 m north of its route walks south across it: in a
    # second the front would be inside the person's predicted walk.
    view = make_view(
        [[3.6, 3.0, 0.0]],
        vel=[[0.5, 0.0]],
        people_xy=[5.0, 5.0],
        people_vel=[[0.0, -1.2]],
        people_radius=[RADIUS],
    )
    raw = np.array([[0.5, 0.0]])
    res = yielder.step(view, np.array([0]), raw, _scene(view))
    assert not res.stepping_aside[0]
    assert res.commands[0, 0] < 0.5
    # Once the person has crossed (south of the route, walking away), it drives on.
    later = replace(view, people_xy=np.array([[5.0, 1.0]]))
    res = yielder.step(later, np.array([0]), raw, _scene(later))
    assert res.commands[0, 0] == pytest.approx(0.5)
    # A standing person far from the route does not slow it either.
    still = replace(view, people_xy=np.array([[5.0, 5.5]]), people_vel=np.zeros((1, 2)))
    res = yielder.step(still, np.array([0]), raw, _scene(still))
    assert res.commands[0, 0] == pytest.approx(0.5)


def test_standing_people_get_a_berth_in_the_field_only():
    yielder = PeopleYield(PeopleParams(standing_berth_m=0.5))
    view = make_view(
        [[2.0, 3.0, 0.0]],
        people_xy=[[5.0, 3.0], [7.0, 3.0]],
        people_vel=[[0.0, 0.0], [1.0, 0.0]],
        people_radius=[RADIUS, RADIUS],
    )
    wide = yielder.field_view(view)
    assert wide.people_radius.tolist() == [RADIUS + 0.5, RADIUS]
    assert len(yielder.without_people(view).people_xy) == 0


@pytest.mark.parametrize(
    "field,value",
    [("horizon_s", 0.0), ("clearance_m", -0.1), ("rollout_samples", 0), ("enabled", "yes")],
)
def test_bad_people_params_name_the_field(field, value):
    with pytest.raises(ValueError, match=f"PeopleParams.{field}"):
        PeopleParams(**{field: value})


def test_aside_clearance_cannot_exceed_the_clearance():
    with pytest.raises(ValueError, match="aside_clearance_m"):
        PeopleParams(clearance_m=0.1, aside_clearance_m=0.2)


def test_a_stopped_skid_does_not_step_aside():
    view = make_view(
        [[5.0, 3.0, 0.0]],
        people_xy=[5.0, 5.0],
        people_vel=[[0.0, -1.2]],
        people_radius=[RADIUS],
        stopped=[True],
    )
    res = PeopleYield(PeopleParams()).step(view, np.array([0]), np.zeros((1, 2)), _scene(view))
    assert not res.stepping_aside[0] and np.all(res.commands == 0.0)
