"""Recording a run as MCAP (ROS 2 types) and reading it back; replay's errors for bad files."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from helpers import DATA, ROOT

from swarmpark.record import messages as m
from swarmpark.record.reader import RecordingError, load_recording, read_channels, scans

SCENARIO = DATA / "rec-small.yaml"
ROBOTS = ["s1", "s2", "s3"]


def _cli(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "swarmpark.apps.cli", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=cwd,
    )


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """``swarmpark run --record`` on a short scenario with sensing, a person, a refused
    command; also its trajectories.npz and result.json."""
    d = tmp_path_factory.mktemp("rec")
    mcap = d / "run.mcap"
    p = _cli("run", str(SCENARIO), "--record", str(mcap), "--out", str(d / "out"), "--quiet")
    assert p.returncode in (0, 1), p.stderr
    return mcap, d / "out"


def test_every_channel_is_there_with_monotonic_stamps(recorded):
    mcap, _ = recorded
    rec = load_recording(mcap)
    expected = {
        "/map", "/world", "/tf_static", "/tf", "/footprints", "/people", "/goals",
        "/boundary", "/paths", "/swarmpark/state", "/swarmpark/commands",
        "/swarmpark/operator", "/swarmpark/alarms",
    } | {f"/{r}/{k}" for r in ROBOTS for k in ("odom", "scan", "cmd_vel")}  # fmt: skip
    assert set(rec.types) == expected
    assert rec.types["/s1/scan"] == "sensor_msgs/msg/LaserScan"
    assert rec.types["/tf"] == "tf2_msgs/msg/TFMessage"
    assert rec.types["/goals"] == "visualization_msgs/msg/MarkerArray"
    for topic, st in rec.stamps.items():
        if topic in ("/swarmpark/operator", "/swarmpark/alarms"):
            continue  # nothing to say in a headless run without contacts
        assert len(st) >= 1, topic
        assert np.all(np.diff(st) >= 0), topic
    # Poses at the record rate (10 Hz) over the whole run; scans at 5 Hz.
    assert len(rec.stamps["/tf"]) == len(rec.times) == 61
    assert 25 <= len(rec.stamps["/s2/scan"]) <= 31


def test_map_equals_the_scenarios_grid(recorded):
    from swarmpark.world.scenario import build_world, load_scenario

    rec = load_recording(recorded[0])
    grid = build_world(load_scenario(SCENARIO)).grid
    assert rec.resolution_m == pytest.approx(grid.resolution_m, rel=1e-7)  # float32 in ROS
    assert rec.origin == tuple(float(v) for v in grid.origin)
    np.testing.assert_array_equal(rec.occupied, grid.occupied)
    np.testing.assert_array_equal(rec.unknown, grid.unknown)


def test_poses_equal_the_trajectories(recorded):
    mcap, out = recorded
    rec = load_recording(mcap)
    tr = np.load(out / "trajectories.npz")
    assert list(tr["robot_ids"]) == rec.ids == ROBOTS
    k = np.searchsorted(tr["t_s"], rec.times - 1e-9)
    np.testing.assert_allclose(tr["t_s"][k], rec.times, atol=1e-9)
    np.testing.assert_allclose(rec.poses[:, :, :2], tr["poses"][k][:, :, :2], atol=1e-9)
    dyaw = np.angle(np.exp(1j * (rec.poses[:, :, 2] - tr["poses"][k][:, :, 2])))
    assert np.abs(dyaw).max() < 1e-9
    # The skids moved, so the comparison is not between two still pictures.
    assert np.ptp(rec.poses[:, :, 0], axis=0).min() > 1.0
    # The person walks and is where the simulator had her.
    j = np.searchsorted(tr["t_s"], rec.people_times - 1e-9)
    np.testing.assert_allclose(rec.people_xy, tr["people_xy"][j], atol=1e-9)
    # /tf says the same as odom.
    tf = [msg for _, _, _, msg in read_channels(mcap, ["/tf"])]
    last = tf[-1].transforms[1]
    assert last.header.frame_id == "map" and last.child_frame_id == "s2/base_link"
    assert last.transform.translation.x == pytest.approx(rec.poses[-1, 1, 0])


def test_commands_result_and_scans(recorded):
    mcap, out = recorded
    rec = load_recording(mcap)
    result = json.loads((out / "result.json").read_text())
    assert rec.result is not None and rec.result["success"] == result["success"]
    assert rec.result["path_length_m"] == result["path_length_m"]
    assert [(c["command"], c["accepted"]) for c in rec.commands] == [
        ("park", True),
        ("goto", False),
    ]
    assert "overlap" in rec.commands[1]["reason"]
    g = rec.goals[-1][1]
    assert not np.isnan(g).any()  # all three got goals from the park
    assert rec.groups[-1][1][0]["robots"] == ROBOTS
    t, ranges = scans(mcap, "s1")
    assert ranges.shape == (len(t), 180)
    finite = np.isfinite(ranges)
    assert finite.mean() > 0.5 and ranges[finite].max() <= 5.0 + 0.1


def test_ros2_tooling_decodes_the_file(recorded):
    """mcap-ros2-support (the ROS 2 decoder, independent of rosbags) reads every message."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    counts: dict[str, int] = {}
    with open(recorded[0], "rb") as f:
        rd = make_reader(f, decoder_factories=[DecoderFactory()])
        assert rd.get_header().profile == "ros2"
        for _, channel, _, msg in rd.iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "/s3/odom":
                assert msg.child_frame_id == "s3/base_link"
    assert counts["/map"] == 1 and counts["/s3/odom"] == 61


def test_truncated_file_exit_2_one_line(recorded, tmp_path):
    data = recorded[0].read_bytes()
    bad = tmp_path / "cut.mcap"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingError, match="not a complete MCAP recording|cut short"):
        load_recording(bad)
    p = _cli("replay", str(bad), "--check")
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("swarmpark replay: error: ")
    assert "cut.mcap" in lines[0] and "Traceback" not in p.stderr


@pytest.mark.parametrize(
    ("content", "why"),
    [(b"", "not a complete MCAP"), (b"hello, this is text\n" * 10, "not a complete MCAP")],
)
def test_not_mcap_exit_2(tmp_path, content, why):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(content)
    p = _cli("replay", str(bad), "--check")
    assert p.returncode == 2 and why in p.stderr and len(p.stderr.strip().splitlines()) == 1


def test_missing_file_and_foreign_mcap(tmp_path):
    p = _cli("replay", str(tmp_path / "nope.mcap"), "--check")
    assert p.returncode == 2 and "no such file" in p.stderr
    from mcap.writer import Writer

    other = tmp_path / "other.mcap"
    with open(other, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="test")
        w.finish()
    with pytest.raises(RecordingError, match="not a swarmpark recording"):
        load_recording(other)


def test_replay_check_summary(recorded):
    p = _cli("replay", str(recorded[0]), "--check")
    assert p.returncode == 0, p.stderr
    assert "rec-small, 3 skids, 6.0 s, 61 pose samples" in p.stdout


def test_bad_record_options(tmp_path):
    p = _cli("run", str(SCENARIO), "--record", str(tmp_path / "x.mcap"), "--record-rate", "-1")
    assert p.returncode == 2 and "--record-rate" in p.stderr


def test_messages_round_trip():
    q = m.yaw_quaternion(np.array([0.3, -2.0]))
    np.testing.assert_allclose(m.quaternion_yaw(q), [0.3, -2.0])
    msg = m.laser_scan(
        5, "a/laser", np.array([1.0, np.nan, np.inf]), angle_min=-1, angle_increment=0.5,
        range_max=5, scan_time=0.2,
    )  # fmt: skip
    back = m.deserialize(m.serialize(msg, m.TYPES["scan"]), m.TYPES["scan"])
    assert back.angle_max == pytest.approx(0.0)
    assert back.ranges[0] == 1.0 and np.isinf(back.ranges[1:]).all()


def test_foxglove_layout_in_docs_is_the_generated_one():
    from swarmpark.record.foxglove_layout import fleet_layout

    doc = json.loads((ROOT / "docs" / "foxglove-layout.json").read_text())
    assert doc == fleet_layout([f"s{k}" for k in range(1, 7)])
    assert doc["configById"]["3D!fleet"]["followTf"] == "map"
    assert "/s3/scan" in doc["configById"]["3D!fleet"]["topics"]


def test_recording_does_not_change_the_run(tmp_path):
    """The recorder only reads (its taps keep references): same result with and without."""
    from swarmpark.apps.run import run_world
    from swarmpark.record import RecordConfig, Recorder
    from swarmpark.record.sinks import McapSink
    from swarmpark.world.scenario import build_world, load_scenario

    def result(observers):
        out = run_world(build_world(load_scenario(SCENARIO)), observers=observers)
        r = dict(out.result)
        r.pop("tick_ms")
        return r, out.poses

    plain, poses = result([])
    every_tick = RecordConfig(rate_hz=None, scan_rate_hz=None)
    recorded, poses_rec = result([Recorder([McapSink(tmp_path / "r.mcap")], every_tick)])
    assert recorded == plain
    np.testing.assert_array_equal(poses_rec, poses)


class _ListSink:
    """A sink that keeps (topic, t_ns) of what it is given; ``on`` says if anyone reads."""

    def __init__(self) -> None:
        self.topics: list[str] = []
        self.got: list[tuple[str, int]] = []
        self.on = False
        self.closed = False

    def channel(self, topic, typename):
        self.topics.append(topic)
        return len(self.topics) - 1

    def write(self, channel, t_ns, data):
        self.got.append((self.topics[channel], t_ns))

    def metadata(self, name, data):
        pass

    def active(self):
        return self.on

    def close(self):
        self.closed = True


def test_no_samples_while_nobody_reads_but_commands_and_latched_topics():
    from swarmpark.record import Recorder
    from swarmpark.supervisor.core import Supervisor
    from swarmpark.world.scenario import build_world, load_scenario

    sup = Supervisor(build_world(load_scenario(SCENARIO)))
    sink = _ListSink()
    rec = Recorder([sink], owned=[])
    rec.on_start(sup)
    for _ in range(12):  # past the park command at 0.5 s
        sup.tick()
        rec.on_tick(sup)
    topics = {t for t, _ in sink.got}
    assert {"/map", "/world", "/goals", "/swarmpark/commands"} <= topics
    assert not topics & {"/tf", "/s1/odom", "/s1/scan", "/footprints"}
    sink.on = True
    for _ in range(4):
        sup.tick()
        rec.on_tick(sup)
    topics = {t for t, _ in sink.got}
    assert {"/tf", "/s1/odom", "/s1/scan", "/footprints"} <= topics
    rec.on_end(sup, None)
    assert not sink.closed  # not owned: a live view outlives the run
