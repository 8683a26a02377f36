"""`import csv --draft-map` across the variety of real lab logs (endocal/runs/mapdraft.py, colnames.py).

A generator writes the tendon bench of tests/test_linear_drive.py (slack, sheath friction, a
bend of 11 deg per mm pulled, 0.08 deg of noise) as many labs would log it, each factor varied
on its own: the clock's name and unit (seconds, ms, ROS-ish epoch stamps in ns or s), the drive's
name and unit (a linear stage in mm, m or µm, a pulley in deg, rad or servo ticks), distractor columns
that must never become the drive (currents, torques, forces, loads, a tension, a voltage, a
temperature, the goal sent), the measured bend (an angle column, a camera's three angles, or tip
and base EM poses in three spellings), the separator (``,``, ``;``, tab, ``;`` with decimal
commas) and what precedes the header (comment lines; a units row, which the reader refuses).

For each shape a user runs the draft through the command line, fixes only the lines it marks
CHECK or FILL IN (from the generator's ground truth, :func:`review`), imports two logs, fits
the first and validates on the second. Asserted: every line the draft leaves unmarked is right
(a wrong unmarked guess is the worst failure: the user is told nothing), the drive is never a
distractor, the imported command is the drive's (or its goal's) values in the right unit, the fit
finds the bench's gain, and the validation reaches the noise floor.
"""

from __future__ import annotations

import json
import re
import tomllib
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from endocal.models import load_model
from endocal.runs.aligned import load_aligned
from tests._cli import endocal, one_line_exit_2
from tests.test_linear_drive import GAIN_DEG_PER_MM, NOISE_DEG, SLACK_MM, tendon_log

#: clock columns: name, and how it is written (s since start, ms, or epoch stamps in ns or s)
TIMES = [("Time", "s"), ("time_s", "s"), ("t", "s"), ("Timestamp (ms)", "ms"), ("elapsed [s]", "s"), ("Time", "ms"),
         ("stamp", "epoch-ns"), ("stamp", "epoch-s"), ("timestamp", "epoch-ms")]
#: drive columns: name and unit (linear stages in mm, m or µm, pulleys in deg, rad or ticks)
DRIVES = [("Tendon Disp.", "mm"), ("stage_pos_mm", "mm"), ("Displacement [mm]", "mm"), ("carriage position (m)", "m"),
          ("actuator_x", "mm"), ("tendon_pull_m", "m"), ("Stage Position [\u00b5m]", "um"), ("motor_angle_deg", "deg"),
          ("Knob1 (rad)", "rad"), ("enc_ticks", "ticks"), ("servo_pos", "deg"), ("pulley_angle", "deg")]
#: a pulley turns 10 deg per mm of tendon (a radius of 5.7 mm)
DEG_PER_MM = 10.0
#: columns that are never the drive (a motor current is its knob's `current`)
DISTRACTORS = ["Motor Curr.", "current_mA", "motor_current_A", "torque_Nm", "Motor Torque (Nm)", "Force (N)",
               "actuator_force_N", "load_cell", "servo_load", "tension", "voltage", "motor_voltage", "temp_c",
               "motor_temp", "stage_temp_c", "motor_speed_rpm", "stage_vel_mm_s"]
#: the motor currents (one per log), and their units
CURRENTS = {"Motor Curr.": "A", "current_mA": "mA", "motor_current_A": "A"}
GOALS = ["setpoint", "goal", "cmd_pos", "target"]
#: how the bend is measured: an angle column (deg or rad), a camera's three angles, or EM poses
MEASURED = ["Angle y", "bend_deg", "theta (rad)", "Bending Angle (deg)", "angle_deg", "poses:tip_x_mm",
            "poses:Tip Pos x", "poses:tip.pose.position.x"]
SEPARATORS = [",", ";", "\t", ";decimal-comma"]
PREAMBLES = ["", "", "", "comments"]
#: a stage holds its goal to a few microns: the goal's tracking error (mm)
GOAL_ERR_MM = 0.003


@dataclass(frozen=True)
class Shape:
    """One log shape: each factor chosen independently."""

    time: tuple[str, str]
    drive: tuple[str, str]
    distractors: tuple[str, ...]
    goal: str | None
    measured: str
    sep: str
    preamble: str
    rate_hz: float

    @property
    def poses(self) -> bool:
        return self.measured.startswith("poses:")

    def __str__(self) -> str:
        return (f"{self.time[0]}({self.time[1]})|{self.drive[0]}({self.drive[1]})|{','.join(self.distractors)}|"
                f"goal={self.goal}|{self.measured}|{self.sep!r}|{self.preamble}|{self.rate_hz:g}Hz")


def shapes(n: int = 64, seed: int = 26) -> list[Shape]:
    """``n`` shapes, each factor's levels spread evenly over them and shuffled independently."""
    rng = np.random.default_rng(seed)

    def spread(levels):
        reps = [levels[i % len(levels)] for i in range(n)]
        return [reps[i] for i in rng.permutation(n)]

    times, drives, measured = spread(TIMES), spread(DRIVES), spread(MEASURED)
    seps, pre, goals = spread(SEPARATORS), spread(PREAMBLES), spread([None, None, *GOALS])
    rates = spread([50.0, 50.0, 100.0])
    out = []
    for i in range(n):
        chosen = tuple(str(d) for d in rng.choice(DISTRACTORS, size=int(rng.integers(1, 5)), replace=False))
        currents = [d for d in chosen if d in CURRENTS]
        chosen = tuple(d for d in chosen if d not in currents[1:])  # one motor current per log
        out.append(Shape(times[i], drives[i], chosen, goals[i], measured[i], seps[i], pre[i], rates[i]))
    return out


@dataclass
class Log:
    """A generated log and what a user who knows the bench would answer for each map line."""

    table: pd.DataFrame
    truth: dict  # (table, key) -> value; None: the key must not be there
    cmd_run: np.ndarray  # the command the import must give, in the run's unit (mm or deg)
    run_unit: str


def _bench(shape: Shape, seed: int, kind: str) -> Log:
    """The bench's log in ``shape``: its columns, and the truth."""
    duration = 20.0 if kind == "damped" else 12.0  # the validation chirp: long enough for its regimes
    base = tendon_log(seed, kind, rate_hz=shape.rate_hz, duration_s=duration)
    rng = np.random.default_rng(seed + 7)
    n, t = len(base), base["Time"].to_numpy()
    x_mm = base["Tendon Disp."].to_numpy()
    bend_deg = base["Angle y"].to_numpy()
    cols: dict[str, np.ndarray] = {}
    truth: dict = {}

    tname, tunit = shape.time
    cols[tname] = {"s": t, "ms": np.round(1000.0 * t, 3), "epoch-ns": (1_732_000_000_000_000_000 + np.round(t * 1e9))
                   .astype(np.int64), "epoch-s": 1_732_000_000.0 + t, "epoch-ms": 1_732_000_000_000.0 + 1000 * t}[tunit]
    truth[("time", "column")] = tname
    truth[("time", "unit")] = tunit.removeprefix("epoch-")

    dname, dunit = shape.drive
    run_unit = "mm" if dunit in ("mm", "m", "um") else "deg"
    goal_mm = x_mm + rng.normal(0, GOAL_ERR_MM, n)

    def in_unit(mm):
        deg = DEG_PER_MM * mm
        return {"mm": np.round(mm, 4), "m": np.round(mm / 1000, 7), "um": np.round(1000 * mm, 1),
                "deg": np.round(deg, 3), "rad": np.round(np.radians(deg), 5),
                "ticks": np.round(2048 + deg * 4096 / 360)}[dunit]

    cols[dname] = in_unit(x_mm)
    truth[("knobs.ap", "position")] = dname
    truth[("knobs.ap", "unit")] = dunit
    truth[("knobs.ap", "direction")] = 1
    if dunit == "ticks":
        truth[("knobs.ap", "zero_ticks")] = 2048
        truth[("knobs.ap", "ticks_per_rev")] = 4096
    else:
        truth[("knobs.ap", "zero")] = 0.0
    truth[("knobs.ap", "goal")] = shape.goal
    if shape.goal:
        cols[shape.goal] = in_unit(goal_mm)
        cmd_mm = goal_mm
    else:
        cmd_mm = x_mm
    # the command as written (rounded as the logger writes it), in the run's unit: mm or deg
    written = in_unit(cmd_mm)
    cmd_run = {"mm": written, "m": 1000 * written, "um": written / 1000, "deg": written, "rad": np.degrees(written),
               "ticks": (written - 2048) * 360 / 4096}[dunit]

    amps = base["Motor Curr."].to_numpy()
    play_mm = bend_deg / GAIN_DEG_PER_MM
    torque = np.round(0.02 + 0.004 * np.abs(x_mm) + rng.normal(0, 1e-3, n), 5)
    force = np.round(1.5 + 0.6 * play_mm + rng.normal(0, 0.02, n), 4)  # follows the bend, and the drive
    temp = np.round(24.0 + 0.02 * t + rng.normal(0, 0.05, n), 2)
    distract = {"Motor Curr.": amps, "current_mA": np.round(1000 * amps, 1), "motor_current_A": amps,
                "torque_Nm": torque, "Motor Torque (Nm)": torque, "Force (N)": force, "actuator_force_N": force,
                "load_cell": np.round(812_000 + 9_000 * play_mm + rng.normal(0, 50, n)),  # raw counts
                "servo_load": np.round(100 * torque, 1),
                "tension": np.round(0.8 + 0.3 * np.abs(play_mm) + rng.normal(0, 0.01, n), 4),
                "voltage": np.round(12.0 + rng.normal(0, 0.02, n), 3),
                "motor_voltage": np.round(2.0 * x_mm + rng.normal(0, 0.05, n), 3),  # a drive's voltage follows it
                "temp_c": temp, "motor_temp": temp, "stage_temp_c": temp,
                "motor_speed_rpm": np.round(np.gradient(DEG_PER_MM * x_mm, t) / 6, 2),
                "stage_vel_mm_s": np.round(np.gradient(x_mm, t), 4)}
    truth[("knobs.ap", "current")] = None
    for d in shape.distractors:
        cols[d] = distract[d]
        if d in CURRENTS:
            truth[("knobs.ap", "current")] = d
            truth[("knobs.ap", "current_unit")] = CURRENTS[d]

    if shape.measured == "Angle y":  # a camera's pose: position and three angles, the bend about y
        for c in ("Pos x", "Pos y", "Pos z", "Angle x", "Angle y", "Angle z"):
            cols[c] = base[c].to_numpy()
        truth[("angles.ap", "column")], truth[("angles.ap", "unit")] = "Angle y", "deg"
    elif shape.measured == "bend_deg":
        cols["bend_deg"] = bend_deg
        truth[("angles.ap", "column")], truth[("angles.ap", "unit")] = "bend_deg", "deg"
    elif shape.measured in ("Bending Angle (deg)", "angle_deg"):
        cols[shape.measured] = bend_deg
        truth[("angles.ap", "column")], truth[("angles.ap", "unit")] = shape.measured, "deg"
    elif shape.measured == "theta (rad)":
        cols["theta (rad)"] = np.round(np.radians(bend_deg), 6)
        truth[("angles.ap", "column")], truth[("angles.ap", "unit")] = "theta (rad)", "rad"
    else:
        cols.update(_poses(shape.measured.split(":", 1)[1], bend_deg, truth))
    if not shape.poses:
        truth[("angles.ap", "zero")], truth[("angles.ap", "direction")] = 0.0, 1

    names = list(cols)
    order = [names[0]] + sorted(names[1:], key=lambda c: rng.random())  # the clock first, the rest in any order
    return Log(pd.DataFrame({c: cols[c] for c in order}), truth, np.asarray(cmd_run, float), run_unit)


#: the base sensor's pose in the tracker (mm, and a rotation): tilted so that a quaternion read
#: in the wrong order shows
BASE_MM = np.array([112.0, -35.0, -184.0])
BASE_ROT = Rotation.from_euler("xyz", [20.0, -35.0, 60.0], degrees=True)
SECTION_MM = 40.0  # the tip sensor's distance from the base sensor


def _poses(spelling: str, bend_deg: np.ndarray, truth: dict) -> dict[str, np.ndarray]:
    """Tip and base EM poses whose eq. 1 angle (atan2(p_y, p_z) of the tip in the base frame) is
    ``bend_deg``, written in one of three spellings; the truth for their map lines."""
    th = np.radians(bend_deg)
    tip_in_base = SECTION_MM * np.column_stack([np.zeros_like(th), np.sin(th), np.cos(th)])
    tip_mm = BASE_MM + BASE_ROT.apply(tip_in_base)
    tip_q = (BASE_ROT * Rotation.from_rotvec(np.column_stack([-th, 0 * th, 0 * th]))).as_quat()  # xyzw
    base_mm = np.tile(BASE_MM, (len(th), 1))
    base_q = np.tile(BASE_ROT.as_quat(), (len(th), 1))
    out = {}
    for sensor, p, q in (("tip", tip_mm, tip_q), ("base", base_mm, base_q)):
        if spelling == "tip_x_mm":  # mm, xyzw columns
            pos = [f"{sensor}_{a}_mm" for a in "xyz"]
            quat = {a: f"{sensor}_q{a}" for a in "xyzw"}
            unit, scale = "mm", 1.0
        elif spelling == "Tip Pos x":  # metres, q0..q3 scalar first
            S = sensor.capitalize()
            pos = [f"{S} Pos {a}" for a in "xyz"]
            quat = {a: f"{S} q{i}" for i, a in enumerate("wxyz")}
            unit, scale = "m", 1e-3
        else:  # ROS: metres
            pos = [f"{sensor}.pose.position.{a}" for a in "xyz"]
            quat = {a: f"{sensor}.pose.orientation.{a}" for a in "xyzw"}
            unit, scale = "m", 1e-3
        for i, c in enumerate(pos):
            out[c] = np.round(p[:, i] * scale, 8)
        for i, a in enumerate("xyzw"):
            out[quat[a]] = np.round(q[:, i], 7)
        truth[(sensor, "position")] = pos
        truth[(sensor, "unit")] = unit
        truth[(sensor, "quaternion")] = [quat[a] for a in "wxyz"]
        truth[(sensor, "order")] = "wxyz"
    return out


def write_log(log: Log, shape: Shape, path) -> None:
    sep = shape.sep.split("decimal")[0]
    text = log.table.to_csv(index=False, sep=sep, decimal="," if "decimal-comma" in shape.sep else ".",
                            lineterminator="\n")
    if shape.preamble == "comments":
        text = "# tendon bench v2.1, operator JS\n# stage: PI M-111, camera 100 Hz\n" + text
    elif shape.preamble == "units-row":
        header, body = text.split("\n", 1)
        units = sep.join(["s"] + ["mm"] * (log.table.shape[1] - 1))
        text = header + "\n" + units + "\n" + body
    path.write_text(text)


_LINE = re.compile(r'^(\w+) = (".*?"|\[.*?\]|\S+)')


def review(text: str, truth: dict) -> tuple[str, list[str], list[str], list[str]]:
    """A user's pass over a drafted map, from what they know of the bench (``truth``): every line
    marked CHECK or FILL IN is checked and fixed when wrong (deleted when the log has no such
    column), and an unmarked line is left as it is. Returns the map, the lines marked, the lines
    fixed, and the unmarked lines that are wrong (what the user was not told)."""
    table, out, marked, fixed, silent, refixed = "", [], [], [], [], set()
    lines = text.splitlines()
    for line in lines:
        m = re.match(r"^\[(.+?)\]", line)
        if m:
            table = m.group(1)
        if table == "knobs.ml" and truth.get(("knobs.ml", "position")) is None:
            # the bench drives one axis: the draft asks for the other's knob (FILL IN, or delete the table)
            if "FILL IN" in line:
                marked.append(f"[{table}] {line.split(' =')[0]}")
                fixed.append(marked[-1])
            elif not m and _LINE.match(line):
                silent.append(f"[{table}]: {line}")
            continue
        kv = _LINE.match(line)
        if not kv:
            out.append(line)
            continue
        key = (table, kv.group(1))
        if key not in truth:
            out.append(line)
            continue
        value = tomllib.loads(f"v = {kv.group(2)}")["v"]
        want = truth[key]
        if "CHECK" in line or "FILL IN" in line or table in refixed:
            # a line of a table whose column the user has just fixed was guessed from the wrong column
            marked.append(f"[{table}] {key[1]}")
            if want is None:
                fixed.append(marked[-1])
                continue  # the user deletes it
            if value != want:
                line = f"{key[1]} = {json.dumps(want)}"
                fixed.append(marked[-1])
                if key[1] in ("position", "column"):
                    refixed.add(table)
        elif value != want:
            silent.append(f"[{table}] {key[1]} = {value!r}, truly {want!r}")
        out.append(line)
    draft = tomllib.loads(text)
    for (table, key), want in truth.items():  # a goal or a current the draft left out, unsaid
        if key in ("goal", "current") and want is not None and key not in draft["knobs"]["ap"]:
            silent.append(f"[{table}] {key} missing, truly {want!r}")
    return "\n".join(out) + "\n", marked, fixed, silent


def _tick_keys(text: str, unit: str) -> str:
    """What the import's refusal then tells the user: tick keys with ticks, none without."""
    if unit == "ticks" and "zero_ticks" not in text:
        return text.replace('unit = "ticks"', 'unit = "ticks"\nzero_ticks = 2048\nticks_per_rev = 4096', 1)
    if unit != "ticks":
        text = "\n".join(ln for ln in text.splitlines() if not ln.startswith(("zero_ticks", "ticks_per_rev"))) + "\n"
    return text


SHAPES = shapes()


def test_the_generator_varies_every_factor():
    """Every level of every factor is run, in at least 60 combinations, each different."""
    assert len(SHAPES) >= 60 and len({str(s) for s in SHAPES}) == len(SHAPES)
    for levels, got in ((TIMES, {s.time for s in SHAPES}), (DRIVES, {s.drive for s in SHAPES}),
                        (MEASURED, {s.measured for s in SHAPES}), (SEPARATORS, {s.sep for s in SHAPES}),
                        (DISTRACTORS, {d for s in SHAPES for d in s.distractors}), (GOALS, {s.goal for s in SHAPES})):
        assert set(levels) <= got, set(levels) - got


@pytest.mark.parametrize("i", range(len(SHAPES)), ids=[f"{i}" for i in range(len(SHAPES))])
def test_a_lab_log_is_drafted_reviewed_imported_fitted_and_validated(i, tmp_path):
    shape = SHAPES[i]
    est, val = _bench(shape, 100 + i, "damped"), _bench(shape, 500 + i, "chirp")
    write_log(est, shape, tmp_path / "est.csv")
    write_log(val, shape, tmp_path / "val.csv")

    proc = endocal("import", "csv", tmp_path / "est.csv", "--draft-map", tmp_path / "draft.toml")
    assert proc.returncode == 0, (str(shape), proc.stdout, proc.stderr)
    text = (tmp_path / "draft.toml").read_text()
    draft = tomllib.loads(text)
    # the drive is never a distractor, whether marked or not
    assert draft["knobs"]["ap"]["position"] not in (*DISTRACTORS, "FILL IN"), (str(shape), text)
    for d in shape.distractors:
        assert d not in [k.get("position") for k in draft["knobs"].values()], (str(shape), text)

    reviewed, _marked, fixed, silent = review(text, est.truth)
    assert silent == [], (str(shape), silent, text)  # every unmarked line is right
    reviewed = _tick_keys(reviewed, est.truth[("knobs.ap", "unit")])
    (tmp_path / "map.toml").write_text(reviewed)

    for name in ("est", "val"):
        proc = endocal("import", "csv", tmp_path / f"{name}.csv", "--map", tmp_path / "map.toml", "--out",
                       tmp_path / (f"{name}.parquet" if not shape.poses else name))
        assert proc.returncode == 0, (str(shape), fixed, reviewed, proc.stderr)
    data = tmp_path / ("est.parquet" if not shape.poses else "est")
    a = load_aligned(data)
    assert a.drive_units["ap"] == est.run_unit, (str(shape), a.drive_units)
    assert f"ap_cmd_{est.run_unit}" in a.table, (str(shape), list(a.table))
    # the command, in the run's unit: mm as the stage moved (m scaled by 1000), deg as the pulley turned
    want = np.interp(a.t_s, np.arange(len(est.cmd_run)) / shape.rate_hz, est.cmd_run)
    np.testing.assert_allclose(a.cmd("ap"), want, atol=1e-6 * max(1.0, np.ptp(want)), err_msg=str(shape))

    model_path = tmp_path / "m.json"
    proc = endocal("fit", "hysteresis", data, "--axis", "ap", "--model", "linear", "--effects", "deadzone", "--out",
                   model_path)
    assert proc.returncode == 0, (str(shape), proc.stderr)
    p = load_model(model_path).params_
    gain = GAIN_DEG_PER_MM / (DEG_PER_MM if est.run_unit == "deg" else 1.0)
    # the gain: 1000 samples over +-6 mm of travel with 0.08 deg of noise pin the slope to well under
    # 0.1 %; 1 % leaves room for the goal's tracking error and whole ticks, and catches any unit slip
    # (a radian read as a degree is 57 times, m as mm 1000 times)
    for branch in ("up", "down"):
        assert abs(p[f"linear_{branch}_slope"] / gain - 1) < 0.01, (str(shape), p)
    slack = SLACK_MM * (DEG_PER_MM if est.run_unit == "deg" else 1.0)
    assert abs(p["deadzone_slack_deg"] / slack - 1) < 0.05, (str(shape), p)

    proc = endocal("validate", model_path, tmp_path / ("val.parquet" if not shape.poses else "val"), "--json-out",
                   tmp_path / "v.json")
    assert proc.returncode == 0, (str(shape), proc.stderr)
    # the floor: the bend's noise, the goal's tracking error through the gain, whole ticks
    tick = 360 / 4096 * GAIN_DEG_PER_MM / DEG_PER_MM if shape.drive[1] == "ticks" else 0.0
    floor = np.sqrt(NOISE_DEG ** 2 + (GAIN_DEG_PER_MM * GOAL_ERR_MM * bool(shape.goal)) ** 2 + tick ** 2 / 12)
    rmse = json.loads((tmp_path / "v.json").read_text())["metrics"]["rmse_deg"]
    assert rmse < 1.3 * floor, (str(shape), rmse, floor)


@pytest.mark.parametrize("step, unit, other", [(1.0, "ms", "or s (1 Hz)?"), (0.01, "s", ""), (20.0, "ms", "")])
def test_a_clock_named_without_its_unit_is_read_by_its_step(step, unit, other):
    """A step of 1 is 1 Hz in seconds or 1 kHz in ms: the rate nearer a bench's 100 Hz is drafted,
    the other named in the CHECK."""
    from endocal.runs.mapdraft import draft_map

    log = pd.DataFrame({"Time": np.arange(200) * step, "stage_pos_mm": np.sin(np.arange(200) / 10),
                        "bend_deg": np.sin(np.arange(200) / 10)})
    d = draft_map(log)
    assert tomllib.loads(d.text)["time"]["unit"] == unit
    check = next(c for c in d.checks if c.startswith("[time] unit"))
    assert other in check and (other or "or " not in check), check


@pytest.mark.parametrize("sep", SEPARATORS)
def test_a_units_row_under_the_header_is_one_line(sep, tmp_path):
    """A units row (``s, mm, A, ...`` under the header, as LabVIEW writes it) is refused by the
    draft and the import alike, in one line saying where it is and what to do; nothing is written."""
    shape = Shape(("Time", "s"), ("Tendon Disp.", "mm"), ("Motor Curr.",), None, "bend_deg", sep, "units-row", 50.0)
    write_log(_bench(shape, 1, "damped"), shape, tmp_path / "u.csv")
    one_line_exit_2(endocal("import", "csv", tmp_path / "u.csv", "--draft-map", tmp_path / "d.toml"),
                    "line 2 under the header holds text over numbers ('s', 'mm'", "a units row?",
                    "delete that line and put each unit in its column's name")
    assert not (tmp_path / "d.toml").exists()
    (tmp_path / "map.toml").write_text('[time]\ncolumn = "Time"\n\n[knobs.ap]\nposition = "Tendon Disp."\n'
                                       'unit = "mm"\n\n[angles.ap]\ncolumn = "bend_deg"\n')
    one_line_exit_2(endocal("import", "csv", tmp_path / "u.csv", "--map", tmp_path / "map.toml", "--out",
                            tmp_path / "u.parquet"), "line 2 under the header", "a units row?")
    assert not (tmp_path / "u.parquet").exists()


def test_two_columns_that_could_each_be_the_drive_are_a_marked_choice():
    """A motor's encoder and the stage's travel of one drive (``Motor Pos``, ``Tendon Disp.``): the
    draft takes the one named for the driving side, and marks the choice naming the other."""
    from endocal.runs.mapdraft import draft_map

    log = tendon_log(3, duration_s=10.0)
    log.insert(2, "Motor Pos", DEG_PER_MM * log["Tendon Disp."])
    d = draft_map(log)
    assert tomllib.loads(d.text)["knobs"]["ap"]["position"] == "Motor Pos"
    check = next(c for c in d.checks if c.startswith("[knobs.ap] position"))
    assert "also: Tendon Disp." in check, check
