"""Import a ROS bag recorded on a rig into a run folder (the ``ros`` extra: ``rosbags``).

A lab that already drives its probe from ROS records what ``endocal excite`` would log:

``sensor_msgs/msg/JointState`` on the joint topic
    knob positions (rad, REP 103) and, when filled, velocities (rad/s); a prismatic
    translation joint in m;
``sensor_msgs/msg/JointState`` on the goal topic (optional)
    the knob goals sent to the servos, same units; the last goal before each joint sample
    is its command. Without a goal topic the measured knob position is the command (the
    servo's own lag then disappears from the data), and ``run.json`` says so;
``geometry_msgs/msg/PoseStamped`` or ``TransformStamped`` on the tip and base topics
    the EM sensors' poses in the tracker frame (m, unit quaternion).

Times are the messages' header stamps (the bag's receive time where a stamp is 0), from
the first joint sample on. The NDI Aurora measures both sensors in one frame; ROS drivers
publish them as two messages, so each base pose is paired with the tip pose nearest in time
(within ``pair_tolerance_s``) and the pair gets the tip's time. The run folder then has the
same motor and tracker streams and aligned table as a simulated or hardware run
(:mod:`endocal.runs.format`), with ``backend.name = "rosbag"`` and the bag's SHA-256 in
``run.json``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from endocal.errors import RunFormatError
from endocal.probe import TRANSLATION, ProbeConfig
from endocal.runs.format import prepare_output, sha256_of
from endocal.runs.imported import tracker_stream, write_imported_run

JOINT_STATE = "sensor_msgs/msg/JointState"
POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/TransformStamped")


@dataclass(frozen=True)
class RosTopics:
    """Where the streams are in the bag (see the module docstring for the message types)."""

    joints: str = "/joint_states"
    tip: str = "/aurora/tip"
    base: str = "/aurora/base"
    goals: str | None = None


@dataclass(frozen=True)
class ImportResult:
    """What :func:`import_rosbag` wrote."""

    run_dir: Path
    motor_rows: int
    tracker_frames: int
    aligned_rows: int
    unpaired_frames: int
    alignment_error: str | None


def _reason(exc: Exception) -> str:
    """A third-party exception on one line (YAML and database errors span several)."""
    return f"{type(exc).__name__}: {' '.join(str(exc).split())[:240]}"


def _reader(bag: Path):
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise RunFormatError("reading ROS bags needs the ros extra: pip install 'endocal-toolkit[ros]'") from None
    if not bag.exists():
        raise RunFormatError(f"{bag} does not exist: give a ROS 1 .bag file or a ROS 2 bag folder")
    try:
        reader = AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as exc:  # rosbags raises its own error classes per format
        raise RunFormatError(f"{bag} is not a readable ROS bag ({_reason(exc)})") from None
    return reader


def _stamp_ns(msg, bag_ns: int) -> int:
    """Header stamp (ns, an integer: wall-clock seconds as floats keep only ~0.2 us)."""
    header = getattr(msg, "header", None)
    if header is not None:
        ns = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
        if ns > 0:
            return ns
    return int(bag_ns)


def _messages(reader, bag: Path, topic: str, types: tuple[str, ...]):
    """``(stamp_ns, message)`` of one topic, in time order."""
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        have = ", ".join(sorted({c.topic for c in reader.connections})) or "none"
        raise RunFormatError(f"{bag}: no topic '{topic}' (the bag has: {have}); name the right one with its option")
    wrong = [c.msgtype for c in conns if c.msgtype not in types]
    if wrong:
        raise RunFormatError(f"{bag}: topic '{topic}' carries {wrong[0]}, expected {' or '.join(types)}")
    try:
        out = [(_stamp_ns(msg, ns), msg) for conn, ns, raw in reader.messages(connections=conns)
               for msg in (reader.deserialize(raw, conn.msgtype),)]
    except Exception as exc:  # noqa: BLE001 -- rosbags and its storage raise their own classes on damaged bytes
        raise RunFormatError(f"{bag}: a message of topic '{topic}' cannot be read ({_reason(exc)}); "
                             "the bag is damaged or was not closed: record it again, or cut the damaged part "
                             "(ros2 bag convert)") from None
    if not out:
        raise RunFormatError(f"{bag}: topic '{topic}' has no messages")
    out.sort(key=lambda tm: tm[0])
    return out


def _unit(dof: str, probe: ProbeConfig) -> tuple[str, float]:
    """Unit suffix and factor from ROS units (rad, m) for a degree of freedom."""
    if dof == TRANSLATION:
        return "mm", 1000.0
    return probe.unit(dof), math.degrees(1.0)


def _joint_columns(msgs, ns0: int, bag: Path, topic: str, joints: dict[str, str], probe: ProbeConfig, what: str):
    """Times (s after ``ns0``) and per-DoF arrays (``pos``, ``vel``) of the named joints from JointState messages."""
    t = np.array([(tm[0] - ns0) * 1e-9 for tm in msgs])
    pos = {dof: np.full(t.size, np.nan) for dof in joints}
    vel = {dof: np.full(t.size, np.nan) for dof in joints}
    for i, (_, msg) in enumerate(msgs):
        names = list(msg.name)
        for dof, joint in joints.items():
            if joint not in names:
                continue
            k = names.index(joint)
            if len(msg.position) > k:
                pos[dof][i] = msg.position[k]
            if len(msg.velocity) > k:
                vel[dof][i] = msg.velocity[k]
    for dof, joint in joints.items():
        if np.all(np.isnan(pos[dof])):
            seen = sorted({n for _, m in msgs for n in m.name})
            raise RunFormatError(f"{bag}: no {what} of joint '{joint}' (for {dof}) on '{topic}'; the joints there are: "
                                 f"{', '.join(seen) or 'none'}; map it with --joint {dof}=NAME")
        _, factor = _unit(dof, probe)
        pos[dof] *= factor
        vel[dof] *= factor
    return t, pos, vel


def _pose_rows(msgs, ns0: int) -> np.ndarray:
    """(n, 8) array ``t_s, x_mm, y_mm, z_mm, qw, qx, qy, qz`` of pose messages (time in s after ``ns0``)."""
    rows = np.empty((len(msgs), 8))
    for i, (ns, msg) in enumerate(msgs):
        t = (ns - ns0) * 1e-9
        if hasattr(msg, "pose"):
            p, q = msg.pose.position, msg.pose.orientation
        else:  # TransformStamped
            p, q = msg.transform.translation, msg.transform.rotation
        rows[i] = (t, 1000.0 * p.x, 1000.0 * p.y, 1000.0 * p.z, q.w, q.x, q.y, q.z)
    return rows


def _pair(tip: np.ndarray, base: np.ndarray, tolerance_s: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Tip rows and, for each, the base row nearest in time within ``tolerance_s`` (the tip's time kept)."""
    tb = base[:, 0]
    idx = np.clip(np.searchsorted(tb, tip[:, 0]), 1, max(tb.size - 1, 1))
    left = np.clip(idx - 1, 0, tb.size - 1)
    right = np.clip(idx, 0, tb.size - 1)
    near = np.where(np.abs(tb[left] - tip[:, 0]) <= np.abs(tb[right] - tip[:, 0]), left, right)
    ok = np.abs(tb[near] - tip[:, 0]) <= tolerance_s
    paired_base = base[near[ok]].copy()
    paired_base[:, 0] = tip[ok, 0]
    return tip[ok], paired_base, int((~ok).sum())


def import_rosbag(bag: str | Path, out: str | Path, probe: ProbeConfig, joints: dict[str, str], *,
                  topics: RosTopics = RosTopics(), pair_tolerance_s: float = 0.005, force: bool = False,
                  command: str | None = None) -> ImportResult:
    """Convert a ROS bag into a run folder.

    Parameters
    ----------
    bag : path
        A ROS 1 ``.bag`` file or a ROS 2 bag folder.
    out : path
        Run folder to create.
    probe : ProbeConfig
        Gives the bending axes (both must be mapped) and the other DoFs.
    joints : dict
        Degree of freedom -> joint name in the JointState messages, e.g. ``{"ap": "knob_ap"}``.
    topics : RosTopics
    pair_tolerance_s : float
        Largest time between a tip and a base pose that still count as one tracker frame.
    force : bool
        Replace an existing run folder.

    Raises
    ------
    RunFormatError
        Not a bag, a topic or joint missing, a wrong message type; before anything is written.
    """
    bag, out = Path(bag), Path(out)
    unknown = [d for d in joints if d not in probe.dofs]
    if unknown:
        raise RunFormatError(f"--joint {unknown[0]}=...: probe '{probe.name}' has no axis '{unknown[0]}' "
                             f"(it has {', '.join(probe.dofs)})")
    missing = [a for a in probe.bending_axes if a not in joints]
    if missing:
        raise RunFormatError(f"no joint named for bending axis '{missing[0]}': give --joint {missing[0]}=JOINT_NAME")
    if not (pair_tolerance_s > 0 and math.isfinite(pair_tolerance_s)):
        raise RunFormatError(f"the tip/base pairing tolerance must be a positive number of seconds, got {pair_tolerance_s}")
    prepare_output(out, force)
    wall0 = time.monotonic()
    reader = _reader(bag)
    try:
        joint_msgs = _messages(reader, bag, topics.joints, (JOINT_STATE,))
        goal_msgs = _messages(reader, bag, topics.goals, (JOINT_STATE,)) if topics.goals else None
        tip_msgs = _messages(reader, bag, topics.tip, POSE_TYPES)
        base_msgs = _messages(reader, bag, topics.base, POSE_TYPES)
    finally:
        reader.close()

    ns0 = joint_msgs[0][0]
    tip, base = _pose_rows(tip_msgs, ns0), _pose_rows(base_msgs, ns0)
    t, pos, vel = _joint_columns(joint_msgs, ns0, bag, topics.joints, joints, probe, "position")
    keep = np.ones(t.size, bool)
    goal = pos
    if goal_msgs is not None:
        tg, goal_at, _ = _joint_columns(goal_msgs, ns0, bag, topics.goals, joints, probe, "goal")
        k = np.searchsorted(tg, t, side="right") - 1  # the last goal sent at or before each sample
        keep = k >= 0
        goal = {dof: np.where(keep, g[np.clip(k, 0, None)], np.nan) for dof, g in goal_at.items()}
    for dof in joints:  # a sample without this joint's reading (JointState may list a subset)
        keep &= np.isfinite(pos[dof]) & np.isfinite(goal[dof])
    if not keep.any():
        raise RunFormatError(f"{bag}: no joint sample has every mapped joint and a goal before it; check the topics")
    t0 = float(t[keep][0])
    motor = {"t_s": t[keep] - t0}
    for dof in joints:
        u, _ = _unit(dof, probe)
        motor[f"{dof}_goal_{u}"] = goal[dof][keep]
        motor[f"{dof}_pos_{u}"] = pos[dof][keep]
        if np.all(np.isfinite(vel[dof][keep])):
            motor[f"{dof}_vel_{u}ps"] = vel[dof][keep]
    tip_ok, base_ok, unpaired = _pair(tip, base, pair_tolerance_s)
    n = tip_ok.shape[0]
    if n == 0:
        raise RunFormatError(f"{bag}: no tip pose has a base pose within {pair_tolerance_s:g} s ({tip.shape[0]} tip, "
                             f"{base.shape[0]} base poses); if the driver stamps them further apart, raise --pair-tolerance")
    tip_ok[:, 0] -= t0
    base_ok[:, 0] -= t0
    tracker = tracker_stream(tip_ok, base_ok)

    backend = {"name": "rosbag", "topics": {"joints": topics.joints, "goals": topics.goals, "tip": topics.tip,
                                            "base": topics.base},
               "joints": dict(joints), "pair_tolerance_s": pair_tolerance_s, "unpaired_tip_frames": unpaired,
               "command_source": "goal topic" if goal_msgs is not None else
               "knob position (no goal topic: the servo's lag is not in the data)"}
    meta = write_imported_run(out, motor, tracker, probe, source={"name": "ros-import", "source": str(bag),
                                                                  "sha256": sha256_of(bag)},
                              backend=backend, command=command, wall0=wall0)
    return ImportResult(out, meta["motor_rows"], n, meta["counts"].get("aligned_rows", 0), unpaired,
                        meta.get("alignment_error"))
