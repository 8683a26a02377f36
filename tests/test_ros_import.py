"""`endocal import-ros`: a ROS bag of a rig's topics becomes the same run as the one it was recorded from.

The bag is written here from a simulated run's streams, as a ROS driver stack would record
it: JointState of the knob positions and of the goals (rad), the two EM sensors as
PoseStamped (m), the base pose stamped 1 ms after the tip's (separate driver messages).
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from endocal.runs.aligned import load_aligned, read_stream
from tests._cli import endocal  # in-process: the same parsing, errors and exit codes, without a start-up per call
from tests.test_cli_excite import one_line_error

rosbags = pytest.importorskip("rosbags")
from rosbags.rosbag2 import Writer  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

TS = get_typestore(Stores.ROS2_HUMBLE)
T0_NS = 1_700_000_000_250_000_000  # wall-clock stamps (ns), as a live system writes them
JOINTS = {"ap": "knob_ap_joint", "ml": "knob_ml_joint"}


def _stamp(t_s):
    Time = TS.types["builtin_interfaces/msg/Time"]
    ns = T0_NS + int(round(t_s * 1e9))
    return TS.types["std_msgs/msg/Header"](stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="")


def _joint_state(t_s, names, pos_rad, vel_rad_s=()):
    return TS.types["sensor_msgs/msg/JointState"](
        header=_stamp(t_s), name=list(names), position=np.asarray(pos_rad, float),
        velocity=np.asarray(vel_rad_s, float), effort=np.empty(0))


def _pose(t_s, row):
    m = TS.types
    pose = m["geometry_msgs/msg/Pose"](
        position=m["geometry_msgs/msg/Point"](x=row.x_mm / 1000, y=row.y_mm / 1000, z=row.z_mm / 1000),
        orientation=m["geometry_msgs/msg/Quaternion"](x=row.qx, y=row.qy, z=row.qz, w=row.qw))
    return m["geometry_msgs/msg/PoseStamped"](header=_stamp(t_s), pose=pose)


def write_bag(run, bag, base_lag_s=0.001, extra_joint=True):
    motor, tracker = read_stream(run, "motor"), read_stream(run, "tracker")
    with Writer(bag, version=9) as w:
        conns = {name: w.add_connection(topic, typ, typestore=TS) for name, topic, typ in (
            ("joints", "/joint_states", "sensor_msgs/msg/JointState"),
            ("goals", "/knob_goals", "sensor_msgs/msg/JointState"),
            ("tip", "/aurora/tip", "geometry_msgs/msg/PoseStamped"),
            ("base", "/aurora/base", "geometry_msgs/msg/PoseStamped"))}
        msgs = []
        names = list(JOINTS.values()) + (["camera_tilt"] if extra_joint else [])  # a joint endocal does not use
        for row in motor.itertuples():
            pos = [np.radians(row.ap_pos_deg), np.radians(row.ml_pos_deg)] + ([0.3] if extra_joint else [])
            vel = [np.radians(row.ap_vel_degps), np.radians(row.ml_vel_degps)] + ([0.0] if extra_joint else [])
            msgs.append((row.t_s, "joints", _joint_state(row.t_s, names, pos, vel)))
            msgs.append((row.t_s, "goals", _joint_state(row.t_s, list(JOINTS.values()),
                                                        np.radians([row.ap_goal_deg, row.ml_goal_deg]))))
        for row in tracker.itertuples():
            t = row.t_s + (base_lag_s if row.sensor == "base" else 0.0)
            msgs.append((t, row.sensor, _pose(t, row)))
        msgs.sort(key=lambda m: m[0])
        for t, name, msg in msgs:
            typ = conns[name].msgtype
            w.write(conns[name], T0_NS + int(round((t + 0.002) * 1e9)), bytes(TS.serialize_cdr(msg, typ)))
    return motor, tracker


@pytest.fixture(scope="module")
def sim_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("ros") / "sine"
    proc = endocal("excite", "sine", "--out", run, "--seed", "3", "--set", "cycles=1", "--set", "frequency_hz=0.25",
                   "--axes", "ap,ml", "--amplitude", "40")
    assert proc.returncode == 0, proc.stderr
    return run


def test_bag_of_a_run_imports_to_the_same_aligned_table(sim_run, tmp_path):
    bag = tmp_path / "bag"
    motor, _ = write_bag(sim_run, bag)
    run = tmp_path / "imported"
    proc = endocal("import-ros", bag, "--out", run, "--joint", "ap=knob_ap_joint", "--joint", "ml=knob_ml_joint",
                   "--goal-topic", "/knob_goals")
    assert proc.returncode == 0, proc.stderr
    # nothing left out, nothing to warn of: the summary's only other line is the next command
    assert "aligned rows" in proc.stdout
    assert proc.stderr.splitlines() == [f"next: endocal fit hysteresis {run} --axis ap --out MODEL.json"], proc.stderr
    want, got = load_aligned(sim_run).table, load_aligned(run).table
    assert len(got) == len(want) == len(motor)
    # times from nanosecond stamps; angles through rad and m and back
    assert np.max(np.abs(got["t_s"].to_numpy() - want["t_s"].to_numpy())) < 2e-9
    for col in ("ap_cmd_deg", "ml_cmd_deg", "ap_pos_deg", "ml_vel_degps"):
        assert np.max(np.abs(got[col].to_numpy() - want[col].to_numpy())) < 1e-9, col
    # eq. 1 on the same poses: the base pose paired with its tip pose 1 ms apart
    for col in ("ap_meas_deg", "ml_meas_deg"):
        assert np.max(np.abs(got[col].to_numpy() - want[col].to_numpy())) < 1e-6, col
    meta = json.loads((run / "run.json").read_text())
    assert meta["status"] == "complete" and meta["backend"]["name"] == "rosbag"
    assert meta["backend"]["command_source"] == "goal topic" and len(meta["protocol"]["sha256"]) == 64
    assert meta["sample_rate_hz"] == pytest.approx(100.0)


def test_without_a_goal_topic_the_knob_position_is_the_command(sim_run, tmp_path):
    bag = tmp_path / "bag"
    write_bag(sim_run, bag, extra_joint=False)
    run = tmp_path / "imported"
    proc = endocal("import-ros", bag, "--out", run, "--joint", "ap=knob_ap_joint", "--joint", "ml=knob_ml_joint")
    assert proc.returncode == 0, proc.stderr
    got = load_aligned(run).table
    np.testing.assert_allclose(got["ap_cmd_deg"], got["ap_pos_deg"], atol=1e-12)
    assert "knob position" in json.loads((run / "run.json").read_text())["backend"]["command_source"]


def test_tip_and_base_poses_pair_within_the_tolerance(sim_run, tmp_path):
    # base poses 12 ms after their tip poses, frames 25 ms apart: the nearest base pose of
    # every tip pose is its own frame's, 12 ms away (the previous frame's is 13 ms away)
    bag = tmp_path / "bag"
    write_bag(sim_run, bag, base_lag_s=0.012)
    joints = ["--joint", "ap=knob_ap_joint", "--joint", "ml=knob_ml_joint", "--goal-topic", "/knob_goals"]
    one_line_error(endocal("import-ros", bag, "--out", tmp_path / "r", *joints), "no tip pose has a base pose within 0.005 s",
                   "--pair-tolerance")
    assert not (tmp_path / "r").exists()
    proc = endocal("import-ros", bag, "--out", tmp_path / "r", *joints, "--pair-tolerance", "0.0125")
    assert proc.returncode == 0, proc.stderr
    want, got = load_aligned(sim_run).table, load_aligned(tmp_path / "r").table
    assert np.max(np.abs(got["ap_meas_deg"].to_numpy() - want["ap_meas_deg"].to_numpy())) < 1e-6


@pytest.mark.parametrize("args, fragments", [
    (["--joint", "ap=knob_ap_joint"], ["bending axis 'ml'", "--joint ml="]),
    (["--joint", "ap=knob_ap_joint", "--joint", "ml=wrong_joint"], ["no position of joint 'wrong_joint'", "knob_ml_joint"]),
    (["--joint", "ap=knob_ap_joint", "--joint", "ml=knob_ml_joint", "--tip-topic", "/ndi/tip"],
     ["no topic '/ndi/tip'", "/aurora/tip"]),
    (["--joint", "ap=knob_ap_joint", "--joint", "ml=knob_ml_joint", "--joint-topic", "/aurora/tip"],
     ["carries geometry_msgs/msg/PoseStamped"]),
    (["--joint", "ap", "--joint", "ml=knob_ml_joint"], ["AXIS=JOINT_NAME"]),
    (["--joint", "up=knob_ap_joint", "--joint", "ml=knob_ml_joint"], ["no axis 'up'"]),
])
def test_bad_mappings_get_one_line_and_nothing_written(sim_run, tmp_path, args, fragments):
    bag = tmp_path / "bag"
    write_bag(sim_run, bag)
    run = tmp_path / "r"
    one_line_error(endocal("import-ros", bag, "--out", run, *args), *fragments)
    assert not run.exists()


def test_not_a_bag_gets_one_line(tmp_path):
    junk = tmp_path / "junk.bag"
    junk.write_text("not a bag")
    one_line_error(endocal("import-ros", junk, "--out", tmp_path / "r", "--joint", "ap=a", "--joint", "ml=b"),
                   "junk.bag", "not a readable ROS bag")
    one_line_error(endocal("import-ros", tmp_path / "missing", "--out", tmp_path / "r", "--joint", "ap=a",
                           "--joint", "ml=b"), "does not exist")


def test_existing_output_is_kept_without_force(sim_run, tmp_path):
    bag = tmp_path / "bag"
    write_bag(sim_run, bag)
    one_line_error(endocal("import-ros", bag, "--out", sim_run, "--joint", "ap=knob_ap_joint", "--joint",
                           "ml=knob_ml_joint"), "already exists")
    assert pd.read_parquet(sim_run / "aligned.parquet").shape[0] > 0
