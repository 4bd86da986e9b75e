"""Manoeuvres for stuck skids (:mod:`swarmpark.control.nav.manoeuvre`), without a scenario."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import hall_walls
from navkit import FOOTPRINT, advance, make_view
from scipy.spatial import cKDTree

from swarmpark.apps.run import run_world
from swarmpark.control.nav.follower import PathState
from swarmpark.control.nav.manoeuvre import ManoeuvrePlanner, ManoeuvreState
from swarmpark.control.nav.params import ManoeuvreParams
from swarmpark.world.scenario import build_world, parse_scenario

#: A spot with a pillar just below it and a parked neighbour on its left: the straight
#: approach from below is blocked, the way in is from the right and a turn on the spot.
PILLAR = (4.6, 1.2, 5.4, 1.9)
GOAL = np.array([5.0, 2.8, np.pi / 2])
NEIGHBOUR = np.array([3.6, 2.8, np.pi / 2])


def _drive(params, start, steps=900):
    """Drive skid 0 from ``start`` with the manoeuvre planner alone (eligible all along)."""
    planner = ManoeuvrePlanner(params)
    states = [ManoeuvreState(), ManoeuvreState()]
    view = make_view([start, NEIGHBOUR], [GOAL, NEIGHBOUR], boxes=[PILLAR], active=[True, False])
    idx = np.array([0])
    trace = []
    for _ in range(steps):
        raw = np.zeros((1, 2))
        planner.step(view, idx, raw, states, np.array([True]))
        cmd = np.vstack([raw, np.zeros((1, 2))])
        trace.append((view.t, states[0].running(), states[0].failed))
        view = advance(view, cmd)
    return view, states[0], trace


def _running(p):
    """A planner whose skid 0 (stuck below the pillar) is running a manoeuvre after 0.5 s."""
    planner = ManoeuvrePlanner(p)
    states = [ManoeuvreState(), ManoeuvreState()]
    view = make_view(
        [[6.5, 0.8, np.pi / 2], NEIGHBOUR], [GOAL, NEIGHBOUR], boxes=[PILLAR], active=[True, False]
    )
    idx = np.array([0])
    for _ in range(10):
        planner.step(view, idx, np.zeros((1, 2)), states, np.array([True]))
        view = advance(view, np.zeros((2, 2)))
    assert states[0].running()
    return planner, states, view, idx


def test_a_stuck_skid_manoeuvres_into_its_spot():
    p = ManoeuvreParams()
    view, st, trace = _drive(p, np.array([6.5, 0.8, np.pi / 2]))
    started = [t for t, running, _ in trace if running]
    # Nothing happens before the skid has been without progress for stuck_s.
    assert started and started[0] >= p.stuck_s - 1e-9
    # The first search found its way (later ones, from the spot itself, may find nothing
    # left to do: here no docking takes over).
    assert st.planned >= 1 and all(failed == 0 for t, _, failed in trace if t <= started[0])
    err = np.hypot(*(view.poses[0, :2] - GOAL[:2]))
    assert err < 0.06
    assert abs(np.angle(np.exp(1j * (view.poses[0, 2] - GOAL[2])))) < np.deg2rad(3.0)


def test_a_skid_stuck_near_its_goal_manoeuvres_sooner():
    # 1.8 m from its goal (within near_goal_m) beside the pillar: parking, not travelling.
    p = ManoeuvreParams()
    start = np.array([6.2, 1.5, np.pi / 2])
    assert np.hypot(*(start[:2] - GOAL[:2])) < p.near_goal_m
    view, st, trace = _drive(p, start)
    started = [t for t, running, _ in trace if running]
    assert started and p.near_stuck_s - 1e-9 <= started[0] < p.stuck_s
    err = np.hypot(*(view.poses[0, :2] - GOAL[:2]))
    assert err < 0.06
    # With near_goal_m 0 the same skid waits stuck_s, as one on its way.
    _, _, trace = _drive(ManoeuvreParams(near_goal_m=0.0), start, steps=300)
    started = [t for t, running, _ in trace if running]
    assert started and started[0] >= p.stuck_s - 1e-9


def test_a_manoeuvre_ends_when_the_skid_is_no_longer_eligible():
    p = ManoeuvreParams(stuck_s=0.5)
    planner, states, view, idx = _running(p)
    raw = np.array([[0.3, 0.1]])
    out = planner.step(view, idx, raw, states, np.array([False]))  # e.g. held by the fill order
    assert not states[0].running() and not out.any()
    np.testing.assert_array_equal(raw, [[0.3, 0.1]])  # its command is left alone


def test_a_manoeuvre_held_still_by_the_monitor_is_dropped_and_retried_later():
    p = ManoeuvreParams(stuck_s=0.5, blocked_s=1.0, retry_s=2.0)
    planner = ManoeuvrePlanner(p)
    states = [ManoeuvreState(), ManoeuvreState()]
    view = make_view(
        [[6.5, 0.8, np.pi / 2], NEIGHBOUR], [GOAL, NEIGHBOUR], boxes=[PILLAR], active=[True, False]
    )
    idx = np.array([0])
    t_drop = None
    for _ in range(40):
        raw = np.zeros((1, 2))
        planner.step(view, idx, raw, states, np.array([True]))
        was = states[0].running()
        planner.observe(view, idx, states, raw, np.zeros((1, 2)))  # the monitor stops it
        if was and not states[0].running() and t_drop is None:
            t_drop = view.t
        view = advance(view, np.zeros((2, 2)))
    assert t_drop is not None
    assert states[0].retry_t == t_drop + p.retry_s
    # The next manoeuvre is planned with the roomier margin first.
    assert states[0].roomy


def test_a_run_stopped_while_a_trace_of_its_turn_passes_counts_as_held():
    """The monitor stops the run but passes a 1e-4 rad/s heading correction: held."""
    p = ManoeuvreParams(stuck_s=0.5, blocked_s=1.0)
    planner, states, view, idx = _running(p)
    for _ in range(5):
        planner.observe(view, idx, states, np.array([[0.1, 1e-4]]), np.array([[0.0, 1e-4]]))
    assert states[0].blocked_s > 0
    # A turn on the spot the monitor lets through is not held.
    planner.observe(view, idx, states, np.array([[0.0, 0.3]]), np.array([[0.0, 0.3]]))
    assert states[0].blocked_s == 0


def test_a_wedged_skid_first_backs_straight_out():
    """In a slot 3 cm wider than the skid on each side, no turn is possible: the manoeuvre
    starts with a straight run out along the skid's own heading, then plans from there."""
    slot = [(3.2, 2.0, 4.7, 2.57), (3.2, 3.43, 4.7, 4.0), (4.7, 2.0, 5.0, 4.0)]
    view = make_view([[3.6, 3.0, 0.0]], [[1.5, 1.2, np.pi / 2]], boxes=slot)
    planner = ManoeuvrePlanner(ManoeuvreParams())
    occ, origin, res = planner._window(view, 0)
    segments = planner._plan(view, 0, occ, origin, res, planner.params.grow_m)
    assert segments and segments[0][0] == "reverse"
    out = segments[0][2]
    assert out[0] < 3.2 - 0.6 and abs(out[1] - 3.0) < 1e-9  # clear of the slot, same line


def test_a_skid_wedged_between_parked_skids_backs_straight_out():
    """Parked skids 3 cm from it on both sides (the collision monitor's margin; they are
    stamped into the window 5 cm wide) and a wall 0.3 m ahead: its way out straight back is
    checked without their stamps' margin, which it already stands in (with it, every way out
    failed and a skid by a pillar stood 16 s, 0.5 m from its spot, on a generated hangar)."""
    gap = 0.03
    side = 0.8 + gap
    poses = [[3.6, 3.0, 0.0], [4.1, 3.0 + side, 0.0], [4.1, 3.0 - side, 0.0]]
    view = make_view(
        poses,
        [[1.0, 1.0, np.pi / 2]] + poses[1:],
        boxes=[(4.9, 1.5, 5.2, 4.5)],
        active=[True, False, False],
    )
    planner = ManoeuvrePlanner(ManoeuvreParams())
    occ, origin, res = planner._window(view, 0)
    segments = planner._plan(view, 0, occ, origin, res, planner.params.grow_m)
    assert segments and segments[0][0] == "reverse"
    out = segments[0][2]
    assert out[0] <= 4.1 - 1.2 and abs(out[1] - 3.0) < 1e-9  # past the neighbours' rears


def test_runs_and_turns_brake_onto_their_ends():
    # The same manoeuvre driven with the braking profile and with the proportional law
    # (brake_share 0): both end at the spot, braking 3 s sooner (17.8 s against 20.8 s).
    ends = []
    for share in (ManoeuvreParams().brake_share, 0.0):
        view, _, trace = _drive(ManoeuvreParams(brake_share=share), np.array([6.5, 0.8, np.pi / 2]))
        t0 = next(t for t, running, _ in trace if running)
        ends.append(next(t for t, running, _ in trace if t > t0 and not running) - t0)
        assert np.hypot(*(view.poses[0, :2] - GOAL[:2])) < 0.06
    assert ends[0] < ends[1] - 2.0


def test_on_a_coarse_map_a_manoeuvre_keeps_the_monitors_margin():
    """A generated open deck (10 cm map, seed 3040): skid 1 stands 0.3 m past its spot and
    22 deg off, a parked neighbour ahead on its right. Searched on the map's 10 cm cells, the
    manoeuvre began with a turn on the spot, checked at the centre of the skid's cell 4 cm
    from where it stands, that swept its corner within the monitor's 3 cm of that neighbour
    (the monitor refused it, and the skid planned it again for 100 s); on 5 cm cells every
    pose of it keeps the margin from the other skids."""
    from dataclasses import replace

    from shapely.geometry import Polygon
    from shapely.geometry import box as shapely_box

    from swarmpark.core.geometry import Footprint, footprint_corners
    from swarmpark.core.gridmap import grid_from_walls

    small = Footprint(1.0, 0.7, 0.5)
    fps = (small, small, Footprint(1.2, 0.8, 0.6), small, small)
    shift = np.array([12.0, 6.0, 0.0])
    poses = (
        np.array(
            [
                [16.8728, 7.7581, -0.0247],
                [16.9927, 9.2743, -0.3752],
                [15.1093, 9.1347, 0.0259],
                [18.1079, 8.8464, 0.025],
                [18.109, 9.9703, -0.0037],
            ]
        )
        - shift
    )
    goals = poses.copy()
    goals[1] = np.array([16.717, 9.1412, 0.0]) - shift
    view = make_view(poses, goals, active=[False, True, False, False, False])
    view = replace(
        view, footprints=fps, grid=grid_from_walls((10.0, 6.0), 0.1, [shapely_box(0, 0, 0.1, 0.1)])
    )
    st = ManoeuvreState()
    ManoeuvrePlanner(ManoeuvreParams())._start(view, 1, st)
    assert st.running()
    others = [
        Polygon(c)
        for c in footprint_corners(
            np.delete(poses, 1, 0),
            np.array([f.corners_body() for k, f in enumerate(fps) if k != 1]),
        )
    ]
    body = small.corners_body()[None]
    for n, (kind, a, b) in enumerate(st.segments):
        if n == 0:  # the first segment starts where the skid stands, not at its cell's centre
            a = np.array([*poses[1, :2], a[2]])
            b = np.array([*poses[1, :2], b[2]]) if kind == "turn" else b
        for f in np.linspace(0.0, 1.0, 21):
            pose = (
                a + f * (b - a)
                if kind != "turn"
                else np.array([*a[:2], a[2] + f * np.angle(np.exp(1j * (b[2] - a[2])))])
            )
            me = Polygon(footprint_corners(pose[None], body)[0])
            assert min(me.distance(o) for o in others) >= 0.03 - 1e-3, (kind, pose)


#: A dead-end slot 1.1 m wide at the hall's east side, the 0.8 m skid in it nose to its end
#: wall (no room to turn on the spot), and its goal 7 m west: as a skid parked on an elevator
#: and sent to a bay beyond the door.
SLOT = [(7.6, 2.4, 9.0, 2.45), (7.6, 3.55, 9.0, 3.6), (9.0, 2.4, 9.3, 3.6)]
SLOT_START = np.array([8.35, 3.0, 0.0])
FAR_GOAL = np.array([1.0, 3.0, np.pi])


def _far(paths, steps=300):
    """Drive the slotted skid with a window too small for its goal (``paths``: its plan)."""
    p = ManoeuvreParams(stuck_s=0.5, window_margin_m=1.5, max_window_m=8.0)
    planner = ManoeuvrePlanner(p)
    states = [ManoeuvreState()]
    view = make_view([SLOT_START], [FAR_GOAL], boxes=SLOT)
    assert planner._window(view, 0) is None  # the goal is beyond one window
    idx = np.array([0])
    for _ in range(steps):
        raw = np.zeros((1, 2))
        planner.step(view, idx, raw, states, np.array([True]), paths=paths)
        if states[0].failed or (states[0].planned and not states[0].running()):
            break
        view = advance(view, raw)
    return p, view, states[0]


def test_a_skid_stuck_far_from_its_goal_manoeuvres_onto_its_path():
    path = PathState(path=np.array([SLOT_START[:2], FAR_GOAL[:2]]), path_goal=FAR_GOAL.copy())
    p, view, st = _far([path])
    assert st.planned >= 1 and st.failed == 0 and not st.running()  # planned, driven, done
    # It ends on its path, via_m[0] along it, facing along it (the way to its goal).
    end = view.poses[0]
    assert abs(end[0] - (SLOT_START[0] - p.via_m[0])) < 0.06 and abs(end[1] - 3.0) < 0.06
    assert abs(np.angle(np.exp(1j * (end[2] - np.pi)))) < np.deg2rad(3.0)
    # Without a path (or one planned for another goal) there is nothing to aim at.
    _, _, st = _far(None)
    assert st.failed == 1 and not st.running()
    stale = PathState(path=path.path, path_goal=np.array([1.0, 2.0, np.pi]))
    _, _, st = _far([stale])
    assert st.failed == 1


#: A wall across the hall and a skid standing nose to it, 5 cm off (pivot 0.65 m from it,
#: less than its reach of 0.72 m: it cannot turn on the spot).
WALL = (4.0, 1.0, 4.3, 5.0)
NOSE_IN = np.array([3.35, 3.0, 0.0])


def _edges(b):
    """The four sides of box ``b`` as point pairs."""
    x0, y0, x1, y1 = b
    c = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    return [(np.array(c[k]), np.array(c[(k + 1) % 4])) for k in range(4)]


def test_a_skid_nose_to_a_wall_cannot_turn_on_the_spot_to_its_path():
    planner = ManoeuvrePlanner(ManoeuvreParams())
    view = make_view([NOSE_IN], boxes=[WALL])
    near = cKDTree(np.vstack([np.linspace(a, b, 40) for a, b in _edges(WALL)]))
    idx = np.array([0])
    assert planner.cramped(view, idx, np.array([2.0]), near).tolist() == [True]
    # Within cramped_rad of its path's heading it drives on as the field says.
    assert planner.cramped(view, idx, np.array([0.1]), near).tolist() == [False]
    # Moving, or 1 m back from the wall, it is not cramped.
    moving = make_view([NOSE_IN], boxes=[WALL], vel=[[-0.2, 0.0]])
    assert planner.cramped(moving, idx, np.array([2.0]), near).tolist() == [False]
    roomy = make_view([NOSE_IN - [1.0, 0.0, 0.0]], boxes=[WALL])
    assert planner.cramped(roomy, idx, np.array([2.0]), near).tolist() == [False]
    # Off, never.
    off = ManoeuvrePlanner(ManoeuvreParams(cramped=False))
    assert off.cramped(view, idx, np.array([2.0]), near).tolist() == [False]


def test_a_cramped_skid_backs_straight_out_then_turns_to_its_path_at_once():
    """No wait for stuck_s: it backs out along its own heading until it can turn, turns to
    its path's heading, and hands back to the path follower."""
    p = ManoeuvreParams()
    planner = ManoeuvrePlanner(p)
    states = [ManoeuvreState()]
    want = 2.0
    view = make_view([NOSE_IN], [[1.0, 5.0, np.pi]], boxes=[WALL])
    idx = np.array([0])
    raw = np.zeros((1, 2))
    out = planner.step(view, idx, raw, states, np.array([True]), None, None, np.array([True]),
                       np.array([want]))  # fmt: skip
    assert out.tolist() == [True] and raw[0, 0] < 0.0  # backing, on the first tick
    segs = states[0].segments
    assert [s[0] for s in segs] == ["reverse", "turn"]
    back = segs[0][2]
    assert abs(back[1] - NOSE_IN[1]) < 1e-9 and abs(back[2] - NOSE_IN[2]) < 1e-9  # straight
    assert WALL[0] - back[0] >= FOOTPRINT.reach_m  # where the turn is clear
    assert NOSE_IN[0] - back[0] <= p.escape_step_m * 2 + 1e-9  # and no farther than needed
    for _ in range(200):
        raw = np.zeros((1, 2))
        planner.step(view, idx, raw, states, np.array([True]), None, None, np.array([False]),
                     np.array([want]))  # fmt: skip
        view = advance(view, raw)
        if not states[0].running():
            break
    assert not states[0].running() and states[0].failed == 0
    assert abs(np.angle(np.exp(1j * (view.poses[0, 2] - want)))) < np.deg2rad(3.0)
    # Without the rule the same skid waits stuck_s before anything is planned.
    planner = ManoeuvrePlanner(ManoeuvreParams(cramped=False))
    states = [ManoeuvreState()]
    view = make_view([NOSE_IN], [[1.0, 5.0, np.pi]], boxes=[WALL])
    planner.step(view, idx, np.zeros((1, 2)), states, np.array([True]), None, None,
                 np.array([True]), np.array([want]))  # fmt: skip
    assert not states[0].running()


@pytest.mark.slow
def test_a_skid_parked_nose_to_a_wall_drives_out_and_parks():
    """A new user's site: one skid standing 5 cm from a wall, facing it, sent to a spot 11 m
    behind it. The field turned it broadside to the wall, where it shuffled for 20 s until
    its manoeuvre (60.05 s to park against a bound of 22.9 s)."""
    data = {
        "name": "nose-to-wall",
        "seed": 0,
        "dt_s": 0.05,
        "duration_s": 80,
        "map": {"size_m": [20, 14], "walls": hall_walls(20, 14)},
        "robots": [{"id": "k4", "pose": [0.95, 8.0, 180.0]}],
        "commands": [
            {
                "at_s": 0,
                "park": {"robots": ["k4"], "boundary": [[11, 4], [17, 4], [17, 10], [11, 10]]},
            }
        ],
    }
    r = run_world(build_world(parse_scenario(data))).result
    assert r["success"] and r["collisions"] == [] and r["deadlocks"] == []
    assert r["time_to_park_s"] < 40.0


def test_a_way_in_round_the_back_beyond_the_window_is_not_walled_in():
    """A spot in a column of parked skids, one parked in front of it too: the way in is round
    the column's end and back in from behind, which leaves the skid's own window (here 1 m).
    The wider window finds it, so the skid is not taken for walled in (which would make the
    column open across its middle); with the wider window off, it is."""
    goal = [6.0, 3.0, 0.0]
    parked = [[6.0, 4.05, 0.0], [6.0, 1.95, 0.0], [4.6, 3.0, 0.0]]
    poses = [[2.0, 3.0, 0.0], *parked]
    settled = np.array([False, True, True, True])

    def start(params):
        view = make_view(poses, [goal, *parked], active=[True, False, False, False])
        planner = ManoeuvrePlanner(params)
        st = ManoeuvreState()
        planner._start(view, 0, st, settled=settled)
        return st

    narrow = ManoeuvreParams(window_margin_m=1.0, wide_margin_m=0.0)
    st = start(narrow)
    assert st.walled and st.segments is None
    st = start(ManoeuvreParams(window_margin_m=1.0, wide_margin_m=3.5))
    assert not st.walled and st.segments
    # It ends on the spot, and backs in from behind the column (east of it).
    end = st.segments[-1][2]
    assert np.hypot(end[0] - goal[0], end[1] - goal[1]) < 0.06
    assert st.segments[-1][0] == "reverse"
    assert max(s[2][0] for s in st.segments) > goal[0] + 0.6


def test_a_manoeuvre_the_long_way_round_a_skid_on_the_move_waits_for_it():
    """A wall across the hall with a door, and a way round its end: another skid stands
    across the door. On the move, it will be gone: the way round the wall's end takes far
    longer than the way through the door, so the skid plans no manoeuvre now and tries again
    after ``retry_s`` (not a failure). The same skid standing still is an obstacle like the
    wall, and the skid goes round; after ``detour_wait_s`` on the same goal it goes round
    too."""
    p = ManoeuvreParams(window_margin_m=3.5)
    walls = [(3.9, 0.0, 4.1, 2.2), (3.9, 3.8, 4.1, 4.7)]
    poses = [[2.8, 3.0, 0.0], [4.0, 3.0, np.pi / 2]]
    goal = [5.4, 3.0, 0.0]

    def start(vel, t=0.0, st=None):
        view = make_view(poses, [goal, poses[1]], boxes=walls, vel=vel, t=t)
        st = ManoeuvreState() if st is None else st
        ManoeuvrePlanner(p)._start(view, 0, st)
        return st

    moving = [[0.0, 0.0], [0.3, 0.0]]
    st = start(moving)
    assert st.segments is None and st.failed == 0
    assert st.retry_t == pytest.approx(p.retry_s)
    # Standing still: round the wall's end, above it.
    still = start([[0.0, 0.0], [0.0, 0.0]])
    assert still.segments and max(s[2][1] for s in still.segments) > 4.7
    assert still.segments[-1][2][:2] == pytest.approx(goal[:2], abs=0.06)
    # Waited detour_wait_s for that goal: it goes round.
    st = start(moving, t=p.detour_wait_s, st=st)
    assert st.segments and max(s[2][1] for s in st.segments) > 4.7
    # Off: it goes round at once.
    p = ManoeuvreParams(window_margin_m=3.5, detour_ratio=0.0)
    assert start(moving).segments
