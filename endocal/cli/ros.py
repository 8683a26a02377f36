"""``endocal import-ros``: turn a ROS bag recorded on a rig into a run folder."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Optional

import typer

from endocal.cli._common import cli_errors, err, out
from endocal.cli.messages import EXPLAIN_HELP, keyed_lines


@cli_errors
def import_ros(
    bag: Path = typer.Argument(..., help="ROS 1 .bag file or ROS 2 bag folder."),
    out_dir: Path = typer.Option(..., "--out", "-o", help="Run folder to create."),
    joint: list[str] = typer.Option([], "--joint", help="AXIS=JOINT_NAME: which JointState joint is a knob (or translation, rotation); repeatable, both bending axes required."),
    probe: str = typer.Option("tee", "--probe", help="Probe preset (`tee`: ap/ml, `duodenoscope`: ud/lr) or a probe .toml."),
    joint_topic: str = typer.Option("/joint_states", "--joint-topic", help="sensor_msgs/JointState topic with the knob positions (rad)."),
    goal_topic: Optional[str] = typer.Option(None, "--goal-topic", help="sensor_msgs/JointState topic with the knob goals (rad); without it the knob position is the command."),
    tip_topic: str = typer.Option("/aurora/tip", "--tip-topic", help="PoseStamped or TransformStamped of the tip sensor (m)."),
    base_topic: str = typer.Option("/aurora/base", "--base-topic", help="PoseStamped or TransformStamped of the base sensor (m)."),
    pair_tolerance: float = typer.Option(0.005, "--pair-tolerance", help="Largest time (s) between a tip and a base pose of one tracker frame."),
    force: bool = typer.Option(False, "--force", help="Replace --out if it is a run folder."),
    explain: bool = typer.Option(False, "--explain", "-v", help=EXPLAIN_HELP),
) -> None:
    """Convert a ROS bag into a run folder (motor and tracker streams + aligned table).

    Every later command then reads it like a run of `endocal excite`. Needs the `ros` extra.
    """
    from endocal.errors import RunFormatError
    from endocal.probe import load_probe
    from endocal.runs.rosbag import RosTopics, import_rosbag

    joints = {}
    for item in joint:
        axis, sep, name = item.partition("=")
        if not sep or not axis.strip() or not name.strip():
            raise RunFormatError(f"--joint {item!r}: write AXIS=JOINT_NAME, e.g. --joint ap=knob_ap")
        joints[axis.strip()] = name.strip()
    topics = RosTopics(joints=joint_topic, tip=tip_topic, base=base_topic, goals=goal_topic)
    probe_cfg = load_probe(probe)
    res = import_rosbag(bag, out_dir, probe_cfg, joints, topics=topics, pair_tolerance_s=pair_tolerance,
                        force=force, command="endocal " + " ".join(sys.argv[1:]))
    out.print(f"imported {bag} -> {res.run_dir}: {res.motor_rows} motor samples, {res.tracker_frames} tracker frames, "
              f"{res.aligned_rows} aligned rows")
    note = (f"{res.unpaired_frames} tip poses had no base pose within {pair_tolerance:g} s and were dropped"
            if res.unpaired_frames else "")
    warning = f"no aligned table: {res.alignment_error}" if res.alignment_error else ""
    if explain:
        for kind, text in (("note", note), ("warning", warning)):
            if text:
                err.print(f"{kind}: {text}")
    else:
        for line in keyed_lines([("unpaired-poses", note)], "note") + keyed_lines([("no-aligned-table", warning)]):
            err.print(line, markup=False)
    if not res.alignment_error:
        axes = [a for a in probe_cfg.bending_axes if a in joints]
        err.print(f"next: endocal fit hysteresis {shlex.quote(str(res.run_dir))} --axis {axes[0] if axes else 'AXIS'} "
                  "--out MODEL.json", markup=False)
