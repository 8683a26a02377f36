"""A first column map for a lab's CSV log, guessed from its header and its numbers.

``endocal import csv LOG.csv --draft-map MAP.toml`` writes the map that
:func:`endocal.runs.csvlog.read_map` reads, filled in from what the log shows, so a user edits
a map rather than writing one from the documentation. Each role is matched by the words of
the column names (``stamp_ms``, ``ap_present_ticks``, ``tip_qw``, ``joint_deg``: split at
underscores, spaces, dots and case changes) and each unit by a word of the name when there is
one, else by the numbers:

- the clock: epoch-sized stamps tell their unit by magnitude (1.7e9 s, 1.7e12 ms, 1.7e15 us,
  1.7e18 ns), others by their median step (a sample rate of 1 Hz to 10 kHz); text stamps are
  date-times; no clock gives ``sample_rate_hz``;
- knob positions: a column named for a probe axis (``ap_present_ticks``), else per-motor columns
  numbered by a suffix as ROS writes a JointState (``position0``, ``goal1``: motor 0 is the
  probe's first axis, marked CHECK; a numbered ``effort`` is its current, as Dynamixel drivers
  publish it, marked CHECK), else a bench's one drive: a column named for the driving side
  (``knob``, ``motor``, ``pulley``), else like a linear drive's travel (``Tendon Disp.``,
  ``stroke``, ``extension``), else like a position (``pos``, ``position``), the choice marked
  CHECK unless one name says knob or motor; whole numbers within one servo turn are ticks (zero at
  mid-turn, 4096 per turn, as the XM430 the thesis uses), values within +-2 pi are radians, else
  degrees; a displacement is millimetres when its numbers plainly are (a travel of 0.2 to 200)
  and ``FILL IN`` otherwise; a column of an EM pose, a component of an x/y/z triple (``Pos x``) or a
  column named like a current, torque, force or load (``Motor Curr.``), or like a speed,
  temperature, voltage or power (``motor_temp``, ``stage_vel_mm_s``), is never a knob position
  (a bench's motor current becomes its knob's ``current``); a numbered knob alone (``Knob1``)
  takes an unnumbered goal and current;
- EM positions: below 2 in magnitude are metres, else millimetres;
- a measured angle within +-pi is radians, else degrees; of several angle columns (``Angle x``,
  ``Angle y``, ``Angle z``) the one that follows the drive best, marked CHECK.

Every line decided by the numbers, or by a default, is marked ``CHECK`` with the evidence,
and every role the import needs that nothing matched (a knob per bending axis with poses: the
user deletes the table of an axis the bench does not drive) is left as ``"FILL IN"``, which the
import refuses naming the role. The remaining numeric columns
that fill every row, but for clocks and counters (a ROS header's ``stamp`` and ``seq``) and the
components of x/y/z triples (a tip's pose: what the model predicts, no covariate), become
``extras`` (covariates for ``load:COLUMN``).
"""

from __future__ import annotations

import os
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from endocal.probe import load_probe
from endocal.runs.colnames import ANGLE_UNIT_WORDS, DISPLACEMENT_WORDS, EFFORT_WORDS, STATE_WORDS, unit_named, words
from endocal.runs.csvlog import UNFILLED as FILL, read_log_table
from endocal.runs.format import LOG_RATE_RANGE_HZ

_TIME = {"t", "time", "stamp", "timestamp", "ts", "clock", "datetime", "date", "sec", "secs", "seconds", "elapsed"}
_TIME_UNIT = {"s": "s", "sec": "s", "secs": "s", "seconds": "s", "ms": "ms", "msec": "ms", "millis": "ms",
              "milliseconds": "ms", "us": "us", "usec": "us", "micros": "us", "ns": "ns", "nsec": "ns",
              "nanos": "ns", "nanoseconds": "ns"}
_GOAL = {"goal", "cmd", "command", "commanded", "target", "setpoint", "sp", "desired", "demand"}
_CURRENT = {"current", "cur", "curr", "ma", "amp", "amps", "effort"}  # a JointState's effort: a servo's current
#: words of a knob's position: those that name the driving side outright, then generic ones
_DRIVE = {"knob", "motor", "pulley", "input", "drive", "actuator", "servo", "present", "in"}
_POSITION = _DRIVE | {"pos", "position", "actual", "angle", "enc", "encoder"}
#: words of a linear drive's travel: a tendon pulled by a stage (``Tendon Disp.``)
_LINEAR = DISPLACEMENT_WORDS | {"tendon", "stage", "linear"}
_ANGLE_UNIT = ANGLE_UNIT_WORDS
#: a travel (1st to 99th percentile) plainly in millimetres: a tendon pulled 0.2 mm bends a section a
#: few degrees (57/r deg per mm at r mm off the axis), a stage moves at most a few tens of mm; below it
#: the numbers may be metres, above it micrometres, and the draft leaves the unit to fill in
_MM_SPAN = (0.2, 200.0)
_MEASURED = {"joint", "bend", "bending", "theta", "meas", "measured", "output", "camera", "angle"}
_SENSORS = {"tip": {"tip", "distal", "sensor1", "s1"}, "base": {"base", "proximal", "ref", "sensor0", "s0"}}
_AXES = {"x", "y", "z", "px", "py", "pz"}
_QUAT = {"qw": "w", "qx": "x", "qy": "y", "qz": "z", "q0": "w", "q1": "x", "q2": "y", "q3": "z"}
_ROTATION = {"q", "quat", "quaternion", "orientation", "rotation", "rot"}
_LENGTH_UNIT = {"mm": "mm", "m": "m", "um": "um"}
#: words of an EM sensor's pose columns (``field.base.pose.position.x``): never a knob
_POSE_WORDS = {"tip", "distal", "base", "proximal", "pose", "orientation", "quaternion", "quat", "quality"}
#: words of columns that are never a knob's position: a goal, what the drive exerts (current, torque,
#: force, load) or logs about itself (speed, temperature, voltage), a measured bend, a pose
_NOT_KNOB = _GOAL | _CURRENT | EFFORT_WORDS | STATE_WORDS | (_MEASURED - {"angle"}) | _POSE_WORDS
#: words of columns that are no covariate: clocks, and counters such as a ROS header's seq
_NOT_EXTRA = _TIME | {"seq", "sequence", "index", "idx", "counter", "header"}
#: a word ending in a motor's number, as ROS writes the arrays of a JointState: position0, goal1
_NUMBERED = re.compile(r"([a-z]+?)(\d+)")


def components(cols: list[str]) -> set[str]:
    """The columns that are one component of an x/y/z triple (``Pos x``, ``Pos y``, ``Pos z``;
    ``angle_x`` ...): a pose's position or orientation, never a drive or a covariate."""
    out = set()
    for c in cols:
        ws = words(c)
        if not ws or ws[-1] not in ("x", "y", "z"):
            continue
        stem = ws[:-1]
        triple = [d for d in cols if words(d)[:-1] == stem and words(d)[-1:] in (["x"], ["y"], ["z"])]
        if len({words(d)[-1] for d in triple}) == 3:
            out.add(c)
    return out


@dataclass
class Draft:
    """A drafted map: its TOML text, what was decided how, and what is left to check."""

    text: str
    roles: dict[str, str] = field(default_factory=dict)
    checks: list[str] = field(default_factory=list)
    unmatched: list[str] = field(default_factory=list)
    #: the map gives measured ``[angles]`` (the import writes an aligned table), not EM poses (a run folder)
    angles: bool = False
    #: rows whose time stamp an earlier row has already (the import refuses them without --dedupe)
    repeated_stamps: int = 0


def import_out(log: str | Path, angles: bool) -> Path:
    """What ``--out`` the import of ``log`` through its drafted map can take: beside the log (in
    the working folder when the log's folder is read-only, as a shared data folder is) and named
    after it, an aligned table (``.parquet``) for an ``[angles]`` map, else a run folder."""
    log = Path(log)
    if log.parent.is_dir() and not os.access(log.parent, os.W_OK):
        log = Path(log.name)
    if angles:
        return log.with_suffix(".parquet")
    return log.with_suffix("") if log.suffix else log.with_name(log.name + "-run")


def _values(df: pd.DataFrame, col: str) -> np.ndarray:
    v = pd.to_numeric(df[col], errors="coerce").to_numpy(dtype=float)
    return v[np.isfinite(v)]


def _toml(value) -> str:
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, float):
        return repr(value)
    return str(value)


class _Writer:
    """TOML lines with a comment column; a guess is a ``CHECK`` comment and a line in the summary."""

    def __init__(self):
        self.lines: list[str] = []
        self.checks: list[str] = []

    def table(self, name: str, comment: str = "") -> None:
        self.lines += ["", f"[{name}]" + (f"  # {comment}" if comment else "")]

    def key(self, key: str, value, comment: str = "", check: str = "", where: str = "") -> None:
        line = f"{key} = {_toml(value)}"
        note = f"CHECK: {check}" if check else comment
        if check:
            self.checks.append(f"{where}{key}: {check}")
        self.lines.append(f"{line:<44}# {note}" if note else line)


def _time_unit(df: pd.DataFrame, col: str) -> tuple[str, str]:
    """The clock's unit and, when the name does not say, the evidence for it (empty when it does)."""
    for w in reversed(words(col)):
        if w in _TIME_UNIT:
            return _TIME_UNIT[w], ""
    v = _values(df, col)
    if v.size < 0.5 * len(df):
        return "datetime", "the stamps are text: read as ISO 8601 date-times"
    mag = float(np.median(np.abs(v))) if v.size else 0.0
    for unit, epoch in (("ns", 1e17), ("us", 1e14), ("ms", 1e11), ("s", 1e8)):
        if mag >= epoch:
            return unit, f"epoch-sized stamps ({mag:.3g}) read as {unit} since 1970"
    steps = np.diff(v)
    step = float(np.median(steps[steps > 0])) if np.any(steps > 0) else 0.0
    lo_hz, hi_hz = LOG_RATE_RANGE_HZ
    fits = [(unit, 1.0 / (step * scale)) for unit, scale in (("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9))
            if step and 1 / hi_hz <= step * scale <= 1 / lo_hz]
    if not fits:
        return "s", f"median step {step:.3g}: unit not recognised, seconds assumed"
    # a step of 1 is 1 Hz in s or 1 kHz in ms: the rate nearer a bench's usual 100 Hz, the other named
    unit, hz = min(fits, key=lambda f: abs(np.log10(f[1] / 100.0)))
    other = "".join(f"; or {u} ({r:.0f} Hz)?" for u, r in fits if u != unit)
    return unit, f"median step {step:.3g} {unit} = {hz:.0f} Hz{other}"


def _angle_unit(df: pd.DataFrame, col: str, ticks_ok: bool) -> tuple[str, str]:
    for w in reversed(words(col)):
        if w in _ANGLE_UNIT and (ticks_ok or _ANGLE_UNIT[w] != "ticks"):
            return _ANGLE_UNIT[w], ""
    v = _values(df, col)
    if v.size == 0:
        return "deg", "no numbers: degrees assumed"
    if ticks_ok and np.all(v == np.round(v)) and v.min() >= 0 and v.max() <= 4095 and np.ptp(v) > 20:
        return "ticks", f"whole numbers {v.min():.0f}..{v.max():.0f} read as servo ticks"
    lim = 2 * np.pi if ticks_ok else np.pi
    if np.max(np.abs(v)) <= lim:
        return "rad", f"values within +-{lim:.3g} ({v.min():.3g}..{v.max():.3g}) read as radians"
    return "deg", f"values {v.min():.3g}..{v.max():.3g} read as degrees"


def _pick(cols: list[str], want: set[str], *, avoid: set[str] = frozenset(), need: set[str] = frozenset(),
          taken: set[str]) -> str | None:
    """The first free column with a word of ``want`` (and of ``need``, when given) and none of ``avoid``."""
    for c in cols:
        ws = set(words(c))
        if c not in taken and ws & want and not ws & avoid and (not need or ws & need):
            return c
    return None


def _numbered(cols: list[str], taken: set[str]) -> dict[int, dict[str, str]]:
    """Per-motor knob columns numbered by a suffix (``field.position0``, ``field.goal1``): motor
    number -> ``position`` / ``goal`` -> column."""
    out: dict[int, dict[str, str]] = {}
    for c in cols:
        ws = words(c)
        if c in taken or set(ws) & _POSE_WORDS:
            continue
        for w in ws:
            m = _NUMBERED.fullmatch(w)
            role = m and ("goal" if m.group(1) in _GOAL else "position" if m.group(1) in _POSITION else
                          "current" if m.group(1) in _CURRENT else None)
            if role:
                out.setdefault(int(m.group(2)), {}).setdefault(role, c)
    return out


def _pose_columns(cols: list[str], sensor: str, taken: set[str]) -> tuple[list[str] | None, list[str] | None]:
    """x, y, z and w, x, y, z columns of one EM sensor, or None for each part not found."""
    pos, quat = {}, {}
    for c in cols:
        ws = words(c)
        if c in taken or not set(ws) & _SENSORS[sensor]:
            continue
        last = [w for w in ws if w not in _SENSORS[sensor] and w not in _LENGTH_UNIT]
        tag = last[-1] if last else ""
        if tag in _QUAT:  # tip_qw, tip_q0
            quat.setdefault(_QUAT[tag], c)
        elif set(ws) & _ROTATION and tag in ("w", "x", "y", "z"):  # tip.pose.orientation.w, tip_quat_x
            quat.setdefault(tag, c)
        elif tag in _AXES:  # tip_x_m, tip.pose.position.x, tip_px
            pos.setdefault(tag[-1], c)
    p = [pos[a] for a in "xyz"] if len(pos) == 3 else None
    q = [quat[a] for a in "wxyz"] if len(quat) == 4 else None
    return p, q


def draft_map(df: pd.DataFrame, log_name: str = "LOG.csv") -> Draft:
    """Guess a column map for the log ``df`` (as :func:`endocal.runs.textable.read_csv_table` reads it).

    Returns
    -------
    Draft
        The map's TOML text (every guess marked ``CHECK``), the roles found, the checks and
        the roles left ``FILL IN``.
    """
    return _Drafter(df, log_name).draft()


class _Drafter:
    """One log's map, drafted section by section; each section marks the columns it takes."""

    def __init__(self, df: pd.DataFrame, log_name: str):
        self.df, self.log_name = df, log_name
        self.cols = [str(c) for c in df.columns]
        words_all = {w for c in self.cols for w in words(c)}
        self.probe = load_probe("duodenoscope" if {"ud", "lr"} & words_all and not {"ap", "ml"} & words_all else "tee")
        self.w = _Writer()
        self.roles: dict[str, str] = {}
        self.unmatched: list[str] = []
        self.taken: set[str] = set()
        self.repeated_stamps = 0
        self.components = components(self.cols)
        self.knob_columns: dict[str, str] = {}  # axis -> the drafted knob position column

    def draft(self) -> Draft:
        w = self.w
        tip, base = _pose_columns(self.cols, "tip", self.taken), _pose_columns(self.cols, "base", self.taken)
        poses = tip[0] is not None and tip[1] is not None
        log, out = shlex.quote(self.log_name), shlex.quote(str(import_out(self.log_name, angles=not poses)))
        w.lines += [f"# Column map drafted by `endocal import csv {log} --draft-map`: read every line marked",
                    "# CHECK (guessed from the numbers, not the names) and every FILL IN, then import with",
                    f"# `endocal import csv {log} --map THIS.toml --out {out}` ("
                    + ("measured angles give an aligned table" if not poses else "a run folder")
                    + "). Keys: configs/csv-map.example.toml.", ""]
        w.key("probe", self.probe.name, "names the bending axes: tee has ap and ml, duodenoscope ud and lr")
        if poses:  # a pose's columns are taken before any other role can claim one
            self.taken |= {c for part in (*tip, *base) if part for c in part}
        self._time()
        knobs = self._knobs(poses)
        if poses:
            self._poses({"tip": tip, "base": base})
        else:
            self._angles(list(knobs) or list(self.probe.bending_axes[:1]))
        extras = [c for c in self.cols if c not in self.taken and not set(words(c)) & _NOT_EXTRA
                  and c not in self.components and _values(self.df, c).size == len(self.df) > 0]
        if extras:  # a top-level key: before the first table
            w.lines[5:5] = ["# further numeric columns, carried into the table (covariates for load:COLUMN): drop "
                            "what is not one (a column named below as the knob or the angle is no extra)",
                            "extras = [" + "".join(f"\n    {_toml(c)}," for c in extras) + "\n]"]
            self.roles["extras"] = ", ".join(extras)
        return Draft("\n".join(w.lines) + "\n", self.roles, w.checks, self.unmatched, angles=not poses,
                     repeated_stamps=self.repeated_stamps)

    def _time(self) -> None:
        df, w = self.df, self.w
        # a ROS message's header stamp is when the device measured; `%time` when the bridge got it
        col = _pick(self.cols, {"stamp"}, need={"header"}, taken=self.taken) or _pick(self.cols, _TIME, taken=self.taken)
        rising = ""
        if col is None:  # no name says clock: the first column whose numbers rise throughout
            col = next((c for c in self.cols if (v := _values(df, c)).size == len(df) > 1 and np.all(np.diff(v) > 0)),
                       None)
            rising = f"column '{col}' rises throughout, read as the clock" if col else ""
        w.table("time")
        if col is None:
            w.key("sample_rate_hz", 100.0, check="no clock column found: the rows are taken 1/rate apart; give "
                  "the logger's rate (or column = ... and unit = ...)", where="[time] ")
            self.roles["time"] = "none (sample_rate_hz)"
            return
        self.taken.add(col)
        self.repeated_stamps = int(df[col].dropna().duplicated().sum())
        unit, why = _time_unit(df, col)
        w.key("column", col, "the clock column", check=rising, where="[time] ")
        w.key("unit", unit, "s, ms, us, ns or datetime", check=why, where="[time] ")
        # the unit in brackets only when the name does not say it (`Time (s)` is not `Time (s) (s)`)
        self.roles["time"] = f"{col} ({unit})" if why else col

    def _knob(self, axis: str, pos: str, goal: str | None, cur: str | None, what: str, check: str = "") -> None:
        w = self.w
        self.taken |= {pos} | ({goal} if goal else set()) | ({cur} if cur else set())
        self.knob_columns[axis] = pos
        w.key("position", pos, what, check=check, where=f"[knobs.{axis}] ")
        _knob_unit(w, self.df, pos, axis)
        if goal:
            w.key("goal", goal, "the goal sent to the motor, same unit")
        if cur:
            w.key("current", cur, "motor current", where=f"[knobs.{axis}] ",
                  check="a JointState's effort read as the servo's current (Dynamixel drivers publish mA there); "
                        "delete the line if it is a torque" if "effort" in cur.lower() else "")
            cur_unit, why = _current_unit(self.df, cur)
            w.key("current_unit", cur_unit, "mA or A", check=why, where=f"[knobs.{axis}] ")
        self.roles[f"knob {axis}"] = pos + (f" (goal {goal})" if goal else "")

    def _knobs(self, poses: bool) -> list[str]:
        """The knob tables: a column per probe axis (``ap_present_ticks``), else numbered motors
        (``position0``), else a bench's one motor; with ``poses`` every bending axis needs a knob,
        and one no column matched is left ``FILL IN``."""
        axes, found = list(self.probe.bending_axes), []
        for axis in axes:
            goal = _pick(self.cols, _GOAL, need={axis}, taken=self.taken)
            pos = _pick(self.cols, _POSITION | _ANGLE_UNIT.keys() | _LINEAR | {"mm"}, avoid=_NOT_KNOB, need={axis},
                        taken=self.taken | ({goal} if goal else set()))
            if pos is None:
                pos, goal = goal, None
            if pos is None:
                continue
            cur = _pick(self.cols, _CURRENT, need={axis}, taken=self.taken | {pos, goal})
            self.w.table(f"knobs.{axis}")
            self._knob(axis, pos, goal, cur, "the knob's measured position (the command when there is no goal)")
            found.append(axis)
        if not found:
            numbered = _numbered(self.cols, self.taken)
            knobs = [n for n in numbered if "position" in numbered[n] or "goal" in numbered[n]]
            for axis, n in zip(axes, sorted(numbered)):
                pos, goal = numbered[n].get("position"), numbered[n].get("goal")
                cur = numbered[n].get("current")
                if len(knobs) == 1 and pos:  # one numbered knob (Knob1): its goal and current need no number
                    goal = goal or self._free_goal(pos)
                    cur = cur or self._free_current(pos, goal)
                if pos is None and goal is None:  # a motor that logged only its current is no knob
                    continue
                self.w.table(f"knobs.{axis}")
                self._knob(axis, pos or goal, goal if pos else None, cur,
                           "the knob's measured position (the command when there is no goal)",
                           check=f"motor {n} read as the {axis} knob (numbered motors in the order of the probe's "
                                 f"axes: {', '.join(axes)})")
                found.append(axis)
        if not found:
            found = self._bench_knob()
        for axis in axes if poses else []:
            if axis not in found and f"[knobs.{axis}] position" not in self.unmatched:
                self.w.table(f"knobs.{axis}")
                # a bench pulling one tendon of a probe whose bend the poses measure in two: no knob
                undriven = " (or delete this table: an axis without one is not driven, its command 0)" if found else ""
                self.w.key("position", FILL, "the knob's measured position: no column looked like it" + undriven)
                self.w.key("unit", FILL, "deg, rad, ticks or mm: that column's unit")
                self.unmatched.append(f"[knobs.{axis}] position"
                                      + (f" (or delete [knobs.{axis}] if that axis is not driven)" if found else ""))
        return found

    def _bench_knob(self) -> list[str]:
        """A bench's one drive, named for what it is rather than for a probe axis: the driving side
        (``knob``, ``motor``), else a linear drive's travel (``Tendon Disp.``), else a position; never
        a current, torque, force or load, nor a component of an x/y/z triple. The choice is marked
        CHECK unless one column names the driving side."""
        axes = list(self.probe.bending_axes)
        taken = self.taken | self.components
        goal = self._free_goal()
        check = ""
        drive = _candidates(self.cols, _DRIVE, avoid=_NOT_KNOB, taken=taken)
        linear = _candidates(self.cols, _LINEAR, avoid=_NOT_KNOB, taken=taken)
        # an angle named by nothing else may be the bend measured: after a position, an encoder's reading
        generic = sorted(_candidates(self.cols, _POSITION, avoid=_NOT_KNOB, taken=taken),
                         key=lambda c: not set(words(c)) & (_POSITION - {"angle"}))
        if drive:
            pos = drive[0]
            others = list(dict.fromkeys(c for c in drive + linear + generic if c != pos))
            if others:  # a motor's encoder and a stage's travel, say: which one the fit is to take is the user's
                check = f"the first named for the driving side is taken (also: {', '.join(others)})"
        elif linear:
            pos = linear[0]
            word = next((x for x in words(pos) if x in DISPLACEMENT_WORDS), None) or next(
                x for x in words(pos) if x in _LINEAR)
            others = list(dict.fromkeys(c for c in linear + generic if c != pos))
            check = (f"named like a linear drive's travel ({word}), read as the drive"
                     + (f" (also: {', '.join(others)})" if others else ""))
        elif generic:
            pos = generic[0]
            word = next(x for x in words(pos) if x in _POSITION)
            check = (f"named like a position ({word}), read as the drive"
                     + (f" (also: {', '.join(generic[1:])})" if len(generic) > 1 else ""))
        else:
            pos = goal
            if goal:
                check = "the only goal column, read as the drive's position (no column named for one)"
        self.w.table(f"knobs.{axes[0]}", "the one driven axis of a bench is the probe's first")
        if pos is None:
            self.w.key("position", FILL, "the driving knob, pulley or linear stage, as its encoder reads it")
            self.w.key("unit", FILL, "deg, rad, ticks or mm: that column's unit")
            self.unmatched.append(f"[knobs.{axes[0]}] position")
            return []
        cur = self._free_current(pos)
        self._knob(axes[0], pos, None if goal == pos else goal, cur,
                   "the driving knob, pulley or linear stage, as its encoder reads it", check=check)
        return [axes[0]]

    def _free_goal(self, *also_taken: str | None) -> str | None:
        """The first free column named like a goal sent to a motor (``setpoint``, ``cmd_pos``), never
        a current, torque, force or load, nor a component of an x/y/z triple."""
        return _pick(self.cols, _GOAL, avoid=_CURRENT | EFFORT_WORDS | STATE_WORDS | {"tip"},
                     taken=self.taken | self.components | {c for c in also_taken if c})

    def _free_current(self, *also_taken: str | None) -> str | None:
        """The first free column named like a motor current (``Motor Curr.``, ``current_mA``); a
        numbered ``effort`` is a servo's, not a bench's."""
        return _pick(self.cols, _CURRENT - {"effort"}, avoid=_GOAL | _POSE_WORDS,
                     taken=self.taken | self.components | {c for c in also_taken if c})

    def _poses(self, sensors: dict) -> None:
        w = self.w
        for sensor, (p, q) in sensors.items():
            w.table(sensor, f"the EM sensor at the {sensor} of the bending section")
            if p is None or q is None:
                w.key("position", [FILL] * 3, "x, y, z columns")
                w.key("unit", "mm", "mm or m")
                w.key("quaternion", [FILL] * 4, "w, x, y, z columns")
                w.key("order", "wxyz", "the order of the columns above")
                self.unmatched.append(f"[{sensor}] pose (or fixed_position/fixed_quaternion for a clamped base)")
                continue
            self.taken |= set(p) | set(q)
            unit = next((_LENGTH_UNIT[x] for x in reversed(words(p[0])) if x in _LENGTH_UNIT), None)
            why = ""
            if unit is None:
                v = np.concatenate([_values(self.df, c) for c in p])
                size = float(np.median(np.abs(v))) if v.size else 0.0
                unit = "m" if size < 2.0 else "mm"
                why = f"positions of median size {size:.3g} read as {'metres' if unit == 'm' else 'millimetres'}"
            w.key("position", p, "x, y, z in the tracker frame")
            w.key("unit", unit, "mm or m", check=why, where=f"[{sensor}] ")
            w.key("quaternion", q, "scalar first, as listed", where=f"[{sensor}] ",
                  check="q0 read as the scalar part (NDI's convention)" if words(q[0])[-1] == "q0" else "")
            w.key("order", "wxyz", "the order of the columns above")
            self.roles[sensor] = ", ".join(p + q)

    def _angles(self, axes: list[str]) -> None:
        w = self.w
        measured = [c for c in self.cols if c not in self.taken and set(words(c)) & _MEASURED
                    and _values(self.df, c).size]
        for i, axis in enumerate(axes):
            col = next((c for c in measured if axis in words(c)), None)
            check = ""
            if col is None and len(measured) > 1 and axis in self.knob_columns:
                col, check = _follows(self.df, measured, self.knob_columns[axis])
            elif col is None and i < len(measured):
                col = measured[i]
            w.table(f"angles.{axis}", "the measured bending angle (an encoder, a camera)")
            w.key("column", col or FILL, "", check=check, where=f"[angles.{axis}] ")
            if col is None:
                # no unit guessed for a column nobody named: one read wrongly imports at 57 times the angle
                w.key("unit", FILL, "deg or rad: that column's unit")
                w.key("zero", 0.0, "the reading when the section is straight (same unit)")
                w.key("direction", 1, "1, or -1 when the sensor counts the other way")
                self.unmatched.append(f"[angles.{axis}] column (or [tip] and [base] EM poses)")
                continue
            measured.remove(col)
            self.taken.add(col)
            unit, why = _angle_unit(self.df, col, ticks_ok=False)
            w.key("unit", unit, "deg or rad", check=why, where=f"[angles.{axis}] ")
            w.key("zero", 0.0, "the reading when the section is straight (same unit)")
            w.key("direction", 1, "1, or -1 when the sensor counts the other way")
            self.roles[f"angle {axis}"] = col


def _candidates(cols: list[str], want: set[str], *, avoid: set[str], taken: set[str]) -> list[str]:
    """Every free column with a word of ``want`` and none of ``avoid``, in the log's order."""
    return [c for c in cols if c not in taken and set(words(c)) & want and not set(words(c)) & avoid]


def _follows(df: pd.DataFrame, cols: list[str], knob: str) -> tuple[str, str]:
    """Of several angle columns, the one that follows the drive ``knob`` best (largest |correlation|),
    and the CHECK saying so: the bend moves with the drive, a pose's other angles barely do."""
    k = pd.to_numeric(df[knob], errors="coerce").to_numpy(float)
    r = {}
    for c in cols:
        v = pd.to_numeric(df[c], errors="coerce").to_numpy(float)
        ok = np.isfinite(k) & np.isfinite(v)
        r[c] = abs(float(np.corrcoef(k[ok], v[ok])[0, 1])) if ok.sum() > 2 and np.ptp(v[ok]) > 0 and np.ptp(k[ok]) > 0 \
            else 0.0
    best = max(cols, key=lambda c: r[c])
    others = ", ".join(f"{c} {r[c]:.2f}" for c in cols if c != best)
    return best, f"of {len(cols)} angle columns the one that follows '{knob}' (|r| = {r[best]:.2f}; {others})"


def _current_unit(df: pd.DataFrame, col: str) -> tuple[str, str]:
    """A current column's unit (mA or A) and, when the name does not say, the evidence for it."""
    ws = words(col)
    if ws[-1:] == ["a"] or {"amp", "amps", "ampere", "amperes"} & set(ws):
        return "A", ""
    if "ma" in ws or "effort" in ws:  # a JointState's effort: Dynamixel drivers publish mA
        return "mA", ""
    v = _values(df, col)
    size = float(np.quantile(np.abs(v), 0.99)) if v.size else 0.0
    # a motor drawing under 20 mA at its peak moves nothing: numbers that small are amperes
    return ("A", f"currents up to {size:.3g} read as amperes") if size < 20 else \
        ("mA", f"currents up to {size:.4g} read as milliamperes")


def _linear_unit(df: pd.DataFrame, col: str) -> tuple[str, str]:
    """A linear drive's unit: ``mm`` with the evidence when its travel is plainly millimetres
    (:data:`_MM_SPAN`), else ``FILL IN`` with why."""
    v = _values(df, col)
    if v.size == 0:
        return FILL, "no numbers: mm or m"
    lo, hi = np.quantile(v, [0.01, 0.99])
    span = float(hi - lo)
    if _MM_SPAN[0] <= span <= _MM_SPAN[1]:
        return "mm", f"a travel of {span:.3g} ({lo:.3g}..{hi:.3g}) read as millimetres"
    return FILL, (f"a travel of {span:.3g} ({lo:.3g}..{hi:.3g}): mm or m? (plainly mm would span "
                  f"{_MM_SPAN[0]:g} to {_MM_SPAN[1]:g})")


def _knob_unit(w: _Writer, df: pd.DataFrame, col: str, axis: str) -> str:
    """Write a knob's unit (and its tick keys, direction); return the unit written."""
    named = unit_named(col)
    if named in ("mm", "m", "um"):
        unit, why = named, ""
    elif named is None and set(words(col)) & _LINEAR:
        unit, why = _linear_unit(df, col)
    else:
        unit, why = _angle_unit(df, col, ticks_ok=True)
        if why and unit != "ticks":  # nothing in the name says angle or length
            why += "; or mm, if the drive is a linear stage"
    w.key("unit", unit, "deg, rad, ticks, or mm (m, um) for a linear drive", check=why, where=f"[knobs.{axis}] ")
    if unit == "ticks":
        w.key("zero_ticks", 2048, check="the tick count with the knob at 0 deg (probe straight)",
              where=f"[knobs.{axis}] ")
        w.key("ticks_per_rev", 4096, "XM430: 4096")
    w.key("direction", 1, "1, or -1 when a positive count bends the tip towards -y")
    return unit


def write_draft(log: str | Path, out: str | Path, *, force: bool = False) -> Draft:
    """Read ``log``, draft its map and write it to ``out`` (refused if it exists, unless ``force``).

    Raises
    ------
    RunFormatError
        ``log`` unreadable or not a table.
    OutputExistsError
        ``out`` exists and ``force`` is False.
    """
    from endocal.errors import OutputExistsError
    from endocal.runs.format import atomic_write_bytes, check_parent

    log, out = Path(log), Path(out)
    if out.exists() and not force:
        raise OutputExistsError(f"{out} already exists: choose another --draft-map or pass --force")
    check_parent(out)
    draft = draft_map(read_log_table(log)[0], log.name)
    atomic_write_bytes(out, draft.text.encode())
    return draft
