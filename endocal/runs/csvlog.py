"""Import a lab's CSV log into a run folder, through a map that names its columns.

Labs log their rigs as plain CSV: a clock (or none), knob positions in whatever unit the
servo reports, perhaps the goals sent and the motor currents, and the raw EM poses of the tip
and base sensors. A bending axis may be driven by a linear stage pulling its tendon instead of
a knob (``unit = "mm"``, ``"m"`` or ``"um"``): its command stays in millimetres through the run
(``<axis>_goal_mm``, ``<axis>_cmd_mm``, ``drive_units`` in ``run.json``), and the models fitted
on it record the unit (:mod:`endocal.runs.aligned`). A *map* (TOML, see
``configs/csv-map.example.toml``) says which column is what and in which unit; :func:`import_csv`
converts everything to the run format's units (:mod:`endocal.runs.format`), and the bending
angles are computed by thesis eq. 1 from the poses exactly as for endocal's own runs (the
aligned table is built by the same code).

Rows
----
A row with every mapped knob position is a motor sample; a row with any pose cell is a tracker
frame (both at the row's time). A log with one row per motor tick and the latest pose repeated
is read as it is; a log with separate motor and tracker rows (empty cells where a device did
not report) is read exactly. A frame whose sensor has an empty cell or a quaternion that is no
rotation (zeros, for a sensor out of the field) is invalid: kept in the tracker stream as a
dropout (NaN, ``valid`` false), left out of the aligned table and counted; rows with some knob
cells but not every position are no motor sample, and are counted too. Motor samples in a gap
of the readings longer than :data:`~endocal.runs.csvchecks.MAX_GAP_S` (or outside their span)
have nothing to interpolate and are left out of the aligned table: counted, with the first one's
line and the longest gap, for a warning.

Plausibility
------------
A unit mistake in a map gives numbers no rig produces, refused in one line naming the map key
before anything is written (:mod:`endocal.runs.csvchecks`). The run folder is written beside
``out`` and renamed into place, so a failure while writing leaves nothing behind.

Measured angles instead of poses
--------------------------------
A rig that measures the bending angle itself (a joint encoder, a camera, a protractor on a
tendon-sheath bench) maps ``[angles.AXIS]`` columns instead of ``[tip]`` and ``[base]``. There
is no tracker stream to keep, so the import is an aligned table (``.parquet`` or ``.csv``): the
angles interpolated onto the motor samples as :func:`endocal.runs.aligned.align` does with
eq. 1's. ``extras`` names further numeric columns (a sheath configuration, a load) carried
into the aligned table, where models take them as covariates (``load:COLUMN``).

Duplicated time stamps (ROS bridges often write them) are refused by default, with their
count and the first line; ``dedupe=True`` drops rows that repeat an earlier row in every
column the map uses, merges rows of one stamp that fill different columns (a motor tick and a
tracker frame logged in the same millisecond) and says how many, and still refuses a stamp
shared by rows with different values in one mapped column (columns the map does not use, such
as a ROS header's arrival time and sequence number, are not compared).
"""

from __future__ import annotations

import hashlib
import time
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from endocal.errors import OutputExistsError, OutputPathError, RunFormatError
from endocal.probe import TRANSLATION, ProbeConfig, load_probe
from endocal.runs.aligned import CMD_SUFFIXES, CSV_SUFFIXES, MEAS, check_aligned, cmd_column, load_aligned, measured_at
from endocal.runs.csvchecks import (MAX_GAP_S, ReadingGaps, check_aligned_rows, check_base_order, check_distance,
                                    check_knob_to_bend, check_knobs, check_rate, check_unit_names,
                                    measured_angle_warnings, reading_gaps)
from endocal.runs.format import (atomic_write_bytes, check_parent, parquet_bytes, prepare_output, sample_rate_hz,
                                 software_versions)
from endocal.runs.imported import tracker_stream, write_imported_run
from endocal.runs.textable import line_numbers, read_csv_table

#: What a drafted map (:mod:`endocal.runs.mapdraft`) writes where it could not place a column.
UNFILLED = "FILL IN"
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "datetime": None}  # s per unit; datetime: text stamps
ANGLE_UNITS = ("deg", "rad", "ticks")
_SCALE = {"deg": 1.0, "rad": 180.0 / np.pi, "mm": 1.0, "m": 1000.0, "um": 1e-3}  # to the run's deg or mm
#: mm per unit of a length: a stage's travel or an EM position (``um``: micrometres, a piezo stage's)
LENGTH_UNITS = {"mm": 1.0, "m": 1000.0, "um": 1e-3}
#: Units of a bending axis' drive: a knob's angle (kept in deg), or a linear stage's tendon
#: displacement (kept in mm).
DRIVE_UNITS = (*ANGLE_UNITS, *LENGTH_UNITS)
CURRENT_UNITS = {"mA": 1.0, "A": 1000.0}
QUAT_ORDERS = ("xyzw", "wxyz")
_MAP_KEYS = {"probe", "time", "knobs", "tip", "base", "angles", "extras"}
_ANGLE_KEYS = {"column", "unit", "direction", "zero"}
TABLE_SUFFIXES = (".parquet", ".csv")
_TIME_KEYS = {"column", "unit", "sample_rate_hz"}
_KNOB_KEYS = {"position", "goal", "current", "unit", "zero", "zero_ticks", "ticks_per_rev", "direction", "current_unit"}
_POSE_KEYS = {"position", "unit", "quaternion", "order", "valid", "fixed_position", "fixed_quaternion"}

#: The smallest quaternion norm of a valid tracker reading. Every reader normalises the
#: quaternion (scipy's Rotation), so its norm carries no rotation and a log scaled throughout
#: still reads right; only one too short to have a direction is no rotation: the zeros a tracker
#: or ROS bridge writes for a sensor out of the field. A unit quaternion logged to even three
#: decimals has norm 1 within 2e-3; below 0.5 the reading is invalid.
QUAT_MIN_NORM = 0.5


@dataclass(frozen=True)
class CsvImportResult:
    """What :func:`import_csv` wrote, and what it left out.

    ``tracker_frames`` counts the rows with a pose (angle readings with an angles map), valid
    or not; ``tracker_invalid`` those left out of the aligned table (a sensor flagged, missing,
    or with a quaternion that is no rotation). ``motor_rows_incomplete`` counts rows with some
    knob cells but not every knob position (not motor samples), ``rows_unused`` rows that are
    neither a motor sample nor a frame; ``motor_rows_unaligned`` motor samples left out of the
    aligned table for want of a reading (in a gap of the readings over :data:`MAX_GAP_S`, or
    outside their span), ``longest_gap_s`` the longest such gap (s); each ``*_line`` is the first
    such row's line in the log (None when there is none). ``unit_warnings``: measured angles whose
    numbers look like a unit mistake, one line each (:func:`~endocal.runs.csvchecks.measured_angle_warnings`).
    ``axes``: the bending axes a hysteresis model can be fitted to (measured, and commanded through a
    range), in the probe's order.
    """

    run_dir: Path
    rows: int
    angles_measured: bool
    motor_rows: int
    tracker_frames: int
    aligned_rows: int
    duplicates_dropped: int
    rows_merged: int
    duration_s: float
    rate_hz: float | None
    columns: dict
    alignment_error: str | None
    motor_rows_incomplete: int = 0
    motor_rows_incomplete_line: int | None = None
    tracker_invalid: int = 0
    tracker_invalid_line: int | None = None
    rows_unused: int = 0
    rows_unused_line: int | None = None
    motor_rows_unaligned: int = 0
    motor_rows_unaligned_line: int | None = None
    longest_gap_s: float = 0.0
    unit_warnings: tuple[str, ...] = ()
    axes: tuple[str, ...] = ()

    @property
    def gap_warning(self) -> str | None:
        """One line saying which motor samples the aligned table left out for want of a reading
        (None when it kept them all)."""
        if not self.motor_rows_unaligned:
            return None
        what = "angle reading" if self.angles_measured else "tracker frame"
        return (f"{self.motor_rows_unaligned} motor sample(s) were left out of the aligned table, with no {what} to "
                f"interpolate (a gap over {MAX_GAP_S:g} s, or outside the {what}s' span; the longest gap "
                f"{self.longest_gap_s:.2f} s); the first at line {self.motor_rows_unaligned_line}")


@dataclass(frozen=True)
class _Knob:
    position: str
    unit: str
    goal: str | None
    current: str | None
    zero: float  # the reading with the knob at 0 (probe straight), in ``unit`` (zero_ticks for ticks)
    ticks_per_rev: float
    direction: float
    current_factor: float

    @property
    def run_unit(self) -> str:
        """The run's unit of this drive: ``mm`` for a length (a linear stage, the insertion), else ``deg``."""
        return "mm" if self.unit in LENGTH_UNITS else "deg"

    @property
    def per_unit(self) -> float:
        """Run units (deg or mm) per unit of the column, signed by ``direction``."""
        return (360.0 / self.ticks_per_rev if self.unit == "ticks" else _SCALE[self.unit]) * self.direction

    def convert(self, v: np.ndarray) -> np.ndarray:
        """Raw column values in the run's unit: deg (knobs, rotation) or mm (translation); a reading too large to
        convert (beyond 1e308 after scaling) is not finite, as an empty cell is."""
        with np.errstate(over="ignore", invalid="ignore"):
            return (v - self.zero) * self.per_unit


@dataclass(frozen=True)
class _Angle:
    column: str
    unit: str
    factor: float
    direction: float
    zero: float

    def convert(self, v: np.ndarray) -> np.ndarray:
        """Raw readings as the bending angle in degrees (one too large to convert is not finite, as an empty cell)."""
        with np.errstate(over="ignore", invalid="ignore"):
            return (v - self.zero) * self.factor * self.direction


@dataclass(frozen=True)
class _Pose:
    """A sensor's pose columns, or (``fixed``) one pose for a sensor that never moves."""

    position: list[str]
    factor: float
    quaternion: list[str]
    order: str
    valid: str | None
    fixed: tuple[float, ...] | None = None  # x, y, z (the map's unit), quaternion (the map's order)


@dataclass(frozen=True)
class CsvMap:
    """A validated column map.

    Attributes
    ----------
    probe : ProbeConfig
    time_column : str or None
        With ``time_factor`` (s per unit, None for date-time text such as
        ``2026-11-24 15:09:47.123``); None when ``sample_rate_hz`` gives the clock.
    sample_rate_hz : float or None
    knobs : dict
        Degree of freedom -> knob columns and unit.
    tip, base : pose columns and units, or None
        None when ``angles`` gives the bending angles directly.
    angles : dict
        Bending axis -> the column measuring its angle, and its unit (empty with poses).
    extras : tuple of str
        Further numeric columns carried into the aligned table.
    source : str
        The map file (for messages and run.json).
    raw : dict
        The map as read.
    """

    probe: ProbeConfig
    time_column: str | None
    time_factor: float | None
    sample_rate_hz: float | None
    knobs: dict
    tip: _Pose | None
    base: _Pose | None
    angles: dict
    extras: tuple[str, ...]
    source: str
    raw: dict

    def roles(self) -> list[tuple[str, str]]:
        """Every CSV column the map names, with the map key that names it (``[knobs.ap] position``)."""
        out = [("[time] column", self.time_column)] if self.time_column else []
        for dof, k in self.knobs.items():
            out += [(f"[knobs.{dof}] {key}", c) for key, c in (("position", k.position), ("goal", k.goal),
                                                             ("current", k.current)) if c]
        for name, p in (("tip", self.tip), ("base", self.base)):
            if p is not None:
                out += [(f"[{name}] {key}", c) for key, cols in (("position", p.position), ("quaternion", p.quaternion),
                                                               ("valid", [p.valid] if p.valid else [])) for c in cols]
        out += [(f"[angles.{axis}] column", a.column) for axis, a in self.angles.items()]
        return out + [("extras", c) for c in self.extras]

    def columns(self) -> list[str]:
        """Every CSV column the map names."""
        return [c for _, c in self.roles()]

    def role_of(self, column: str) -> str:
        """The map key naming ``column`` (the first, when several do)."""
        return next(role for role, c in self.roles() if c == column)

    def unit(self, dof: str) -> str:
        """The run's unit of degree of freedom ``dof``: ``mm`` for a bending axis driven by a linear
        stage (and the insertion), else the probe's (:meth:`~endocal.probe.ProbeConfig.unit`)."""
        k = self.knobs.get(dof)
        return k.run_unit if k is not None else self.probe.unit(dof)

    def drive_units(self) -> dict[str, str]:
        """Bending axis -> the unit its drive is commanded in, as ``run.json`` records it."""
        return {a: self.unit(a) for a in self.probe.bending_axes}


def _table(d, key: str, where: str, known: set[str]) -> dict:
    v = d.get(key)
    if not isinstance(v, dict):
        raise RunFormatError(f"{where}: a [{key}] table is required")
    unknown = sorted(set(v) - known)
    if unknown:
        raise RunFormatError(f"{where}: unknown key(s) {', '.join(unknown)} in [{key}]; it takes {', '.join(sorted(known))}")
    return v


def _unfilled(where: str, role: str) -> RunFormatError:
    return RunFormatError(f"{where}: {role}: a column is still '{UNFILLED}' (a drafted map): name the log's column "
                          "for that role, or delete the role if the log has none")


def _choice(value, choices, what: str, where: str):
    if value == UNFILLED:
        raise RunFormatError(f"{where}: the {what} is still '{UNFILLED}' (a drafted map): give the column's "
                             f"{what}, one of {', '.join(map(str, choices))}")
    if not isinstance(value, (str, int, float)) or value not in choices:
        raise RunFormatError(f"{where}: unknown {what} {value!r}; use one of {', '.join(map(str, choices))}")
    return value


def _names(value, n: int, what: str, where: str) -> list[str]:
    if not (isinstance(value, list) and len(value) == n and all(isinstance(c, str) and c for c in value)):
        raise RunFormatError(f"{where}: {what} must list {n} column names")
    return list(value)


def _is_number(x) -> bool:
    """A finite TOML number (a bool is not one, though Python counts it as an int)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and bool(np.isfinite(x))


def _numbers(v, n: int) -> bool:
    return isinstance(v, list) and len(v) == n and all(_is_number(x) for x in v)


def _number(t: dict, key: str, w: str, default: float, what: str, positive: bool = False) -> float:
    """``t[key]`` as a float (``default`` when absent), refused in one line naming the key when it is
    not a finite number, or not positive where ``positive``."""
    v = t.get(key, default)
    if not _is_number(v) or (positive and not v > 0):
        raise RunFormatError(f"{w}: {key} must be a {'positive ' if positive else ''}number ({what}), got {v!r}")
    return float(v)


def _column(t: dict, key: str, w: str, what: str, required: bool = True) -> str | None:
    """``t[key]`` as a column name: a non-empty string (None when absent and not ``required``)."""
    v = t.get(key)
    if v is None and not required:
        return None
    if not (isinstance(v, str) and v):
        raise RunFormatError(f"{w}: {key} must name a column ({what}), got {v!r}")
    return v


def _pose(d: dict, key: str, where: str) -> _Pose:
    if not isinstance(d.get(key), dict):
        raise RunFormatError(f"{where}: a [{key}] table is required (the EM sensor's pose columns), or, for a rig that "
                             "measures the bend itself, [angles.AXIS] tables instead of [tip] and [base] "
                             "(configs/csv-map.angles.example.toml)")
    t = _table(d, key, where, _POSE_KEYS)
    w = f"{where} [{key}]"
    unit = _choice(t.get("unit", "mm"), LENGTH_UNITS, "length unit", w)
    order = _choice(t.get("order", "xyzw"), QUAT_ORDERS, "quaternion order", w)
    fixed = [k for k in ("fixed_position", "fixed_quaternion") if k in t]
    if fixed:
        # one sensor on a clamped base: its pose, recorded once, stands for every frame
        if len(fixed) < 2 or any(k in t for k in ("position", "quaternion", "valid")):
            raise RunFormatError(f"{w}: a fixed pose takes fixed_position (3 numbers) and fixed_quaternion (4), "
                                 "instead of position and quaternion columns")
        pos, quat = t["fixed_position"], t["fixed_quaternion"]
        if not (_numbers(pos, 3) and _numbers(quat, 4)) or not np.isclose(np.linalg.norm(quat), 1.0, atol=1e-3):
            raise RunFormatError(f"{w}: fixed_position must be 3 numbers and fixed_quaternion a unit quaternion of 4 "
                                 f"(got {pos!r} and {quat!r})")
        return _Pose([], LENGTH_UNITS[unit], [], order, None, tuple(float(v) for v in [*pos, *quat]))
    valid = _column(t, "valid", w, "0 where the tracker flagged the reading", required=False)
    return _Pose(_names(t.get("position"), 3, "position", w), LENGTH_UNITS[unit],
                 _names(t.get("quaternion"), 4, "quaternion", w), order, valid)


def _direction(t: dict, w: str) -> float:
    direction = t.get("direction", 1)
    if isinstance(direction, bool) or direction not in (1, -1):
        raise RunFormatError(f"{w}: direction must be 1 or -1, got {direction!r}")
    return float(direction)


def _angles(d: dict, probe: ProbeConfig, where: str) -> dict[str, _Angle]:
    """The ``[angles.AXIS]`` tables: bending angles measured directly, in deg or rad."""
    angles_d = d.get("angles")
    if angles_d is None:
        return {}
    if "tip" in d or "base" in d:
        raise RunFormatError(f"{where}: give either [tip] and [base] EM poses or [angles.AXIS] columns of measured "
                             "bending angles, not both")
    if not isinstance(angles_d, dict) or not angles_d:
        raise RunFormatError(f"{where}: [angles] needs one [angles.AXIS] table per measured bending axis "
                             f"({', '.join(probe.bending_axes)})")
    out = {}
    for axis, a in angles_d.items():
        w = f"{where} [angles.{axis}]"
        if axis not in probe.bending_axes:
            raise RunFormatError(f"{w}: probe '{probe.name}' has no bending axis '{axis}' "
                                 f"(it has {', '.join(probe.bending_axes)})")
        a = _table(angles_d, axis, f"{where} [angles]", _ANGLE_KEYS)
        column = _column(a, "column", w, "the measured angle")
        if column == UNFILLED:  # the column before its unit
            raise _unfilled(where, f"[angles.{axis}] column")
        if isinstance(a.get("unit"), str) and a["unit"] in LENGTH_UNITS:
            raise RunFormatError(f"{w}: unit = {a['unit']!r}, but a bending angle is measured in deg or rad: a length "
                                 "is a linear drive's, given in [knobs.AXIS] unit (a tendon displacement); give the "
                                 "angle column's unit, deg or rad")
        unit = _choice(a.get("unit", "deg"), ("deg", "rad"), "angle unit", w)
        zero = _number(a, "zero", w, 0.0, "the reading when the section is straight")
        out[axis] = _Angle(column, unit, _SCALE[unit], _direction(a, w), zero)
    return out


def _extras(d: dict, where: str) -> tuple[str, ...]:
    extras = d.get("extras", [])
    if not (isinstance(extras, list) and all(isinstance(c, str) and c for c in extras)):
        raise RunFormatError(f"{where}: extras must list column names, e.g. extras = [\"sheath_wrap_deg\"]")
    clash = [c for c in extras if c == "t_s" or c.endswith((*CMD_SUFFIXES, MEAS))]
    if clash:
        raise RunFormatError(f"{where}: extra column '{clash[0]}' would pass for an aligned table's own column; "
                             "rename it in the log")
    return tuple(extras)


def read_map(path: str | Path) -> CsvMap:
    """Load and check a CSV map (TOML).

    Raises
    ------
    RunFormatError
        Unreadable TOML, a missing or unknown key, an unknown unit or quaternion order, a
        measured angle without a knob table (with poses: no bending axis with one; an axis without one
        is not driven, its command 0), ticks without ``zero_ticks`` and
        ``ticks_per_rev`` (or those keys with another unit), a number that is not finite (or
        not positive: ``ticks_per_rev``, ``sample_rate_hz``), a time ``unit`` with ``sample_rate_hz``
        (it would be ignored), a column name that is not text,
        a role still ``FILL IN`` or a column named for two roles (each naming the map key).
    """
    path = Path(path)
    where = str(path)
    try:
        d = tomllib.loads(path.read_text())
    except OSError as exc:
        raise RunFormatError(f"{where}: cannot read the map ({exc.strerror or exc})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise RunFormatError(f"{where}: not valid TOML ({exc})") from None
    unknown = sorted(set(d) - _MAP_KEYS)
    if unknown:
        raise RunFormatError(f"{where}: unknown key(s) {', '.join(unknown)}; a map has {', '.join(sorted(_MAP_KEYS))}")
    probe = load_probe(d.get("probe"))
    t = _table(d, "time", where, _TIME_KEYS)
    column, rate = t.get("column"), t.get("sample_rate_hz")
    if (column is None) == (rate is None):
        raise RunFormatError(f"{where} [time]: give either column (with unit s, ms, us, ns or datetime) or sample_rate_hz "
                             "(a log without a clock)")
    factor = TIME_UNITS[_choice(t.get("unit", "s"), TIME_UNITS, "time unit", f"{where} [time]")]
    if rate is not None:
        rate = _number(t, "sample_rate_hz", f"{where} [time]", 0.0, "rows per second", positive=True)
        if "unit" in t:  # it would be ignored: rows are 1/rate s apart whatever it says
            raise RunFormatError(f"{where} [time]: unit applies to a time column, not to sample_rate_hz (rows "
                                 f"1/sample_rate_hz s apart): delete unit = {t['unit']!r}, or give column instead of "
                                 "sample_rate_hz")
    if column is not None:
        column = _column(t, "column", f"{where} [time]", "the clock")
    knobs_d = d.get("knobs")
    if not isinstance(knobs_d, dict) or not knobs_d:
        raise RunFormatError(f"{where}: a [knobs.AXIS] table is required per bending axis ({', '.join(probe.bending_axes)})")
    knobs = {}
    for dof, k in knobs_d.items():
        w = f"{where} [knobs.{dof}]"
        if dof not in probe.dofs:
            raise RunFormatError(f"{w}: probe '{probe.name}' has no axis '{dof}' (it has {', '.join(probe.dofs)})")
        if not isinstance(k, dict):
            raise RunFormatError(f"{w}: must be a table")
        bad = sorted(set(k) - _KNOB_KEYS)
        if bad:
            raise RunFormatError(f"{w}: unknown key(s) {', '.join(bad)}; it takes {', '.join(sorted(_KNOB_KEYS))}")
        if k.get("position") == UNFILLED:  # the column before its unit
            raise _unfilled(where, f"[knobs.{dof}] position")
        units = (DRIVE_UNITS if dof in probe.bending_axes else tuple(LENGTH_UNITS) if dof == TRANSLATION
                 else ANGLE_UNITS)
        unit = _choice(k.get("unit", "deg"), units, "unit", w)
        if unit == "ticks" and ("zero_ticks" not in k or "ticks_per_rev" not in k):
            raise RunFormatError(f"{w}: unit 'ticks' needs zero_ticks and ticks_per_rev (e.g. 2048 and 4096)")
        if unit == "ticks" and "zero" in k:
            raise RunFormatError(f"{w}: a knob in ticks takes its zero as zero_ticks, not zero")
        if unit != "ticks" and ("zero_ticks" in k or "ticks_per_rev" in k):
            # nothing is silently ignored: a map with tick keys but another unit was most likely
            # meant for ticks (a drafted map's unit edited, or the keys copied from the example)
            raise RunFormatError(f"{w}: zero_ticks and ticks_per_rev apply to unit = \"ticks\" only, but unit is "
                                 f"'{unit}': if the column holds servo ticks set unit = \"ticks\", else delete them")
        direction = _direction(k, w)
        position = _column(k, "position", w, "the measured knob position")
        goal = _column(k, "goal", w, "the goal sent to the motor", required=False)
        current = _column(k, "current", w, "the motor current", required=False)
        cur_unit = _choice(k.get("current_unit", "mA"), CURRENT_UNITS, "current unit", w)
        zero = (_number(k, "zero_ticks", w, 0.0, "the tick count with the knob at 0 deg") if unit == "ticks" else
                _number(k, "zero", w, 0.0, "the reading with the knob at 0 (probe straight)"))
        per_rev = _number(k, "ticks_per_rev", w, 4096.0, "ticks per knob revolution, 4096 for an XM430", positive=True)
        knobs[dof] = _Knob(position, unit, goal, current, zero, per_rev, float(direction), CURRENT_UNITS[cur_unit])
    angles = _angles(d, probe, where)
    # with poses, an axis without a knob table is not driven (a bench pulling one tendon): its command is 0
    missing = [a for a in angles if a not in knobs] if angles else (
        [] if set(knobs) & set(probe.bending_axes) else list(probe.bending_axes))
    if missing:
        whose = ("every measured angle" if angles else
                 f"the drive of a bending axis of probe '{probe.name}' (an axis without one is not driven)")
        raise RunFormatError(f"{where}: no [knobs.{missing[0]}] table: {whose} "
                             f"({', '.join(angles or probe.bending_axes)}) needs its knob column")
    tip, base = (None, None) if angles else (_pose(d, "tip", where), _pose(d, "base", where))
    cmap = CsvMap(probe, column, factor, float(rate) if rate is not None else None, knobs, tip, base, angles,
                  _extras(d, where), where, d)
    unfilled = [role for role, c in cmap.roles() if c == UNFILLED]
    if unfilled:
        raise _unfilled(where, unfilled[0])
    check_unit_names(cmap, where)
    # a column that fills a role is no extra (a drafted map lists every column it could not place as one,
    # and the user then names one of them as the knob or the angle): the role keeps it
    placed = {c for role, c in cmap.roles() if role != "extras"}
    cmap = replace(cmap, extras=tuple(c for c in cmap.extras if c not in placed))
    valid = {p.valid for p in (tip, base) if p is not None and p.valid}  # one flag may serve both sensors
    named = [(role, c) for role, c in cmap.roles() if c not in valid]
    cols = [c for _, c in named]
    twice = next((c for c in cols if cols.count(c) > 1), None)
    if twice is not None:
        roles = [role for role, c in named if c == twice]
        raise RunFormatError(f"{where}: column '{twice}' is named for two roles ({roles[0]} and {roles[1]}); "
                             "each role needs its own column")
    return cmap


def _read_csv(raw: bytes, where: str) -> pd.DataFrame:
    try:
        df = read_csv_table(raw)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise RunFormatError(f"{where}: not a CSV table ({str(exc).splitlines()[0]})") from None
    if df.shape[1] < 2 or df.empty:
        raise RunFormatError(f"{where}: not a CSV table of a log (found {df.shape[1]} column(s), {len(df)} row(s))")
    # rows keep their line numbers in the file as the index, for messages (line 1 is the header)
    df.index = line_numbers(raw, len(df), df.attrs.get("headerless", False))
    _refuse_units_row(df, where)
    return df


def _refuse_units_row(df: pd.DataFrame, where: str) -> None:
    """Refuse a second header row (the units under the names, as LabVIEW and many data loggers
    write them): text in most columns on the first row, numbers below it. One header row is read;
    a unit belongs in its column's name (``Time (s)``), where the draft and the checks read it."""
    if len(df) < 3:
        return
    first = df.iloc[0]

    def numbers(cells: pd.Series) -> pd.Series:  # a decimal comma too: the units row kept the column text
        return pd.to_numeric(cells.astype(str).str.strip().str.replace(",", ".", regex=False), errors="coerce")

    text = [c for c in df.columns if isinstance(first[c], str) and first[c].strip()
            and pd.isna(numbers(df[c].iloc[:1]).iloc[0])
            and numbers(df[c].iloc[1:].dropna()).notna().sum() >= 0.9 * df[c].iloc[1:].notna().sum() > 0]
    if len(text) >= max(2, 0.5 * df.shape[1]):
        cells = ", ".join(repr(first[c]) for c in text[:4])
        raise RunFormatError(f"{where}: line {df.index[0]} under the header holds text over numbers ({cells}...): a "
                             "units row? endocal reads one header row: delete that line and put each unit in its "
                             "column's name (Time (s), stage_pos_mm)")


def read_log_table(log: Path) -> tuple[pd.DataFrame, bytes]:
    """The log as a table (its index the rows' line numbers in the file, for messages), and its bytes.

    Raises
    ------
    RunFormatError
        Unreadable, or not a table of at least two columns and one row.
    """
    try:
        raw = Path(log).read_bytes()
    except OSError as exc:
        raise RunFormatError(f"{log}: cannot read the log ({exc.strerror or exc})") from None
    return _read_csv(raw, str(log)), raw


def _numeric(df: pd.DataFrame, col: str, where: str) -> np.ndarray:
    try:
        return pd.to_numeric(df[col], errors="raise").to_numpy(float)
    except (ValueError, TypeError):
        bad = pd.to_numeric(df[col], errors="coerce").isna() & df[col].notna()
        k = int(np.flatnonzero(bad.to_numpy())[0])
        raise RunFormatError(f"{where}: column '{col}' is not numeric (line {df.index[k]}: {df[col].iloc[k]!r})") from None


def _datetime_s(df: pd.DataFrame, col: str, where: str) -> np.ndarray:
    """Date-time text (ISO 8601 as loggers and spreadsheets write it) as seconds since the epoch."""
    raw = df[col]
    stamps = pd.to_datetime(raw, errors="coerce", format="ISO8601", utc=True)
    bad = stamps.isna().to_numpy() & raw.notna().to_numpy()
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise RunFormatError(f"{where}: time column '{col}' is not a date and time at line {df.index[k]} "
                             f"({raw.iloc[k]!r}); write it as 2026-11-24 15:09:47.123, or give its unit (s, ms, us, ns)")
    return (stamps - stamps.min()).dt.total_seconds().to_numpy(float)  # the origin is dropped later anyway


@dataclass(frozen=True)
class _Stamps:
    """Where a row is in time, told so that a user finds it in the log: the clock cell as
    written and the seconds since the log's first row (an epoch stamp printed as
    ``1.73246e+09`` finds nothing)."""

    column: str
    t0_s: float

    def at(self, df: pd.DataFrame, t: np.ndarray, k: int) -> str:
        cell = df[self.column].iloc[k]
        if isinstance(cell, (float, np.floating)):
            cell = np.format_float_positional(cell, trim="-")  # every digit, never 1.73246e+18
        return f"{self.column} = {cell}, {t[k] - self.t0_s:.3f} s after the first row"


def _dedupe(df: pd.DataFrame, t: np.ndarray, lines: np.ndarray, dedupe: bool, used: dict[str, str],
            stamps: _Stamps, where: str) -> tuple[pd.DataFrame, np.ndarray, np.ndarray, int, int]:
    """Drop repeated rows and merge rows of one stamp (with ``dedupe``), then refuse any time
    stamp still shared.

    A logger writing one row per message puts a motor tick and a tracker frame that arrive in
    the same millisecond on two rows with one stamp, each with the other device's cells empty:
    ``dedupe`` merges such rows into one. Only the columns the map uses (``used``: column -> its
    map key, the clock aside) are compared: a ROS bridge's rows of one stamp differ in their
    arrival time, sequence number and frame name, which the import never reads. Rows of one
    stamp with different values in a used column are a conflict no merge can settle, and are
    refused.

    ``lines`` are the rows' line numbers in the file (for messages); returned filtered alike,
    with the number of repeats dropped (rows equal to an earlier one in every used column and
    the stamp) and of rows merged into an earlier one.
    """
    dropped = merged = 0
    if dedupe:
        keyed = df[list(used)].set_axis(range(len(used)), axis=1).assign(t=t)  # no name can clash with t
        exact = keyed.duplicated(keep="first").to_numpy()
        dropped = int(exact.sum())
        df, t, lines = df[~exact], t[~exact], lines[~exact]
        shared = np.concatenate([[False], np.diff(t) == 0])
        if shared.any():
            group = np.cumsum(~shared)  # t does not decrease here, or the log is refused next
            dup = shared | np.concatenate([shared[1:], [False]])  # every row of a shared stamp
            conflict = df[list(used)][dup].groupby(group[dup], sort=False).nunique(dropna=True).max(axis=1) > 1
            if conflict.any():
                g = int(conflict.index[np.argmax(conflict.to_numpy())])
                rows = np.flatnonzero(group == g)
                col = next(c for c in used if df.iloc[rows][c].dropna().nunique() > 1)
                vals = df[col].iloc[rows].to_numpy()
                filled = rows[pd.notna(vals)]
                a = filled[0]
                b = next(r for r in filled if df[col].iloc[r] != df[col].iloc[a])  # the first row to disagree
                raise RunFormatError(f"{where}: rows at lines {lines[a]} and {lines[b]} share a time stamp "
                                     f"({stamps.at(df, t, a)}) but differ in column '{col}' ({used[col]}); no merge "
                                     "can settle which is right: fix the log's clock, or, if its rows are evenly "
                                     "spaced in time, replace [time] column with sample_rate_hz in the map")
            merged = int(shared.sum())
            t, lines = t[~shared], lines[~shared]
            df = df.groupby(group, sort=False).first().set_axis(lines)
    same = np.concatenate([[False], np.diff(t) == 0])
    if same.any():
        first = int(np.flatnonzero(same)[0])
        raise RunFormatError(f"{where}: {int(same.sum())} row(s) repeat a time stamp (pass --dedupe to drop rows that "
                             "repeat an earlier row and merge rows of one stamp that fill different columns); "
                             f"the first at line {lines[first]} ({stamps.at(df, t, first)})")
    return df, t, lines, dropped, merged


def _clock(df: pd.DataFrame, cmap: CsvMap, dedupe: bool, where: str) -> tuple[pd.DataFrame, np.ndarray, int, int]:
    """The rows in time order with their times (s from the first row), after ``dedupe``; with the
    number of repeats dropped and of rows merged."""
    lines = df.index.to_numpy()  # line numbers in the file
    if cmap.time_column is None:
        # without a clock, two rows equal in the mapped columns may be two samples of a knob
        # holding still: only a row equal in every column (a counter too) is a repeat
        exact = df.duplicated(keep="first").to_numpy() if dedupe else np.zeros(len(df), bool)
        df = df[~exact]
        return df, np.arange(len(df)) / cmap.sample_rate_hz, int(exact.sum()), 0
    col = cmap.time_column
    t = _datetime_s(df, col, where) if cmap.time_factor is None else _numeric(df, col, where) * cmap.time_factor
    if not np.isfinite(t).all():
        line = int(lines[np.flatnonzero(~np.isfinite(t))[0]])
        raise RunFormatError(f"{where}: time column '{col}' is empty or not a number at line {line}")
    stamps = _Stamps(col, float(t[0]))
    used: dict[str, str] = {}  # column -> the first map key naming it, in the map's order
    for role, c in cmap.roles():
        if c != col:
            used.setdefault(c, role)
    df, t, lines, dropped, merged = _dedupe(df, t, lines, dedupe, used, stamps, where)
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        k = int(back[0])
        raise RunFormatError(f"{where}: time goes back {t[k] - t[k + 1]:.3g} s at line {lines[k + 1]} "
                             f"({stamps.at(df, t, k + 1)}; line {lines[k]} has {stamps.at(df, t, k)}); if rows were "
                             "written out of order, sort the log by time; if the clock itself was set back during "
                             "the recording, split the log there into two records")
    return df, t - t[0], dropped, merged


def _motor(df: pd.DataFrame, t: np.ndarray, cmap: CsvMap, where: str) -> tuple[dict, np.ndarray, np.ndarray]:
    """The motor stream (the run's units), which rows are motor samples, and which rows have a
    knob's cells but not every knob position (dropped, and counted)."""
    probe, lines = cmap.probe, df.index.to_numpy()
    pos = {dof: k.convert(_numeric(df, k.position, where)) for dof, k in cmap.knobs.items()}
    goal = {dof: k.convert(_numeric(df, k.goal, where)) for dof, k in cmap.knobs.items() if k.goal}
    is_motor = np.logical_and.reduce([np.isfinite(p) for p in pos.values()])
    touched = np.logical_or.reduce([np.isfinite(v) for v in [*pos.values(), *goal.values()]])
    if not is_motor.any():
        raise RunFormatError(f"{where}: no row has every knob position ({', '.join(k.position for k in cmap.knobs.values())})")
    motor = {"t_s": t[is_motor]}
    for dof in probe.dofs:
        u = cmap.unit(dof)
        k = cmap.knobs.get(dof)
        p = pos[dof][is_motor] if k is not None else np.zeros(int(is_motor.sum()))
        g = goal[dof][is_motor] if dof in goal else p
        if not np.isfinite(g).all():
            line = int(lines[is_motor][np.flatnonzero(~np.isfinite(g))[0]])
            raise RunFormatError(f"{where}: goal column '{k.goal}' is empty on a motor row (line {line})")
        motor[f"{dof}_goal_{u}"] = g
        motor[f"{dof}_pos_{u}"] = p
        motor[f"{dof}_vel_{u}ps"] = np.gradient(p, motor["t_s"]) if p.size > 1 else np.zeros_like(p)
        cur = (_numeric(df, k.current, where)[is_motor] * k.current_factor if k is not None and k.current
               else np.zeros_like(p))
        motor[f"{dof}_current_ma"] = np.nan_to_num(cur)
    for col in cmap.extras:
        motor[col] = _numeric(df, col, where)[is_motor]
    return motor, is_motor, touched & ~is_motor


def _frames(df: pd.DataFrame, t: np.ndarray, cmap: CsvMap, where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                                 np.ndarray]:
    """Tracker frames: the tip and base rows (n, 8: ``t_s``, mm, quaternion scalar first), each
    sensor's validity (n, 2), and which rows are frames.

    A row with any pose cell is a frame. A sensor's reading is invalid where the map's ``valid``
    column flags it, a cell is empty, or the quaternion is no rotation (its norm below
    :data:`QUAT_MIN_NORM`: zeros for a sensor out of the field); an unusable reading is stored
    as NaN with ``valid`` false, as endocal's own tracker streams carry a dropout, and the
    aligned table leaves it out (counted in ``run.json``).

    A log written one row per motor tick with the latest pose repeated holds each reading for
    several rows: a row whose logged poses equal the previous frame's in every cell is that
    reading held, not a new one (tracker noise never repeats 14 numbers), so only the row where
    a reading first appears is its frame. Stamped at every row it was held, the reading would be
    placed up to a tracker period late (25 ms at 40 Hz: 0.3 deg RMS on a moving bend).
    """
    rows, present = [], np.zeros(len(df), bool)
    for pc in (cmap.tip, cmap.base):
        if pc.fixed is not None:
            xyz = np.tile(np.array(pc.fixed[:3]) * pc.factor, (len(df), 1))
            q = np.tile(np.array(pc.fixed[3:]), (len(df), 1))
        else:
            xyz = np.column_stack([_numeric(df, c, where) for c in pc.position]) * pc.factor
            q = np.column_stack([_numeric(df, c, where) for c in pc.quaternion])
            present |= ~np.isnan(np.column_stack([xyz, q])).all(axis=1)
        rows.append(np.column_stack([t, xyz, q if pc.order == "wxyz" else q[:, [3, 0, 1, 2]]]))
    if cmap.tip.fixed is not None and cmap.base.fixed is not None:
        present[:] = True  # nothing logged: every row holds the one recorded pose
    else:
        logged = np.column_stack([r[:, 1:] for pc, r in zip((cmap.tip, cmap.base), rows) if pc.fixed is None])
        idx = np.flatnonzero(present)
        held = np.zeros(len(df), bool)
        held[idx[1:]] = (logged[idx[1:]] == logged[idx[:-1]]).all(axis=1)  # NaN never equals: a dropout is no hold
        present &= ~held
    valid = np.ones((len(df), 2), bool)
    for j, (pc, r) in enumerate(zip((cmap.tip, cmap.base), rows)):
        usable = np.isfinite(r).all(axis=1) & (np.linalg.norm(r[:, 4:], axis=1) >= QUAT_MIN_NORM)
        r[~usable, 1:] = np.nan
        valid[:, j] = usable
        if pc.valid:
            valid[:, j] &= np.nan_to_num(_numeric(df, pc.valid, where)) != 0
    return rows[0], rows[1], valid, present


def import_csv(log: str | Path, mapping: str | Path | CsvMap, out: str | Path, *, dedupe: bool = False,
               force: bool = False, command: str | None = None) -> CsvImportResult:
    """Convert a lab's CSV log into a run folder, through a column map.

    Parameters
    ----------
    log : path
        The CSV file (header row required).
    mapping : path or CsvMap
        The column map (:func:`read_map`).
    out : path
        Run folder to create; with a map of measured ``angles``, the aligned table to write
        (``.parquet`` or ``.csv``).
    dedupe : bool
        Drop rows that repeat an earlier row in every column the map uses and merge rows of one
        stamp that fill different columns (else duplicated time stamps are refused).
    force : bool
        Replace an existing run folder (or table).

    Returns
    -------
    CsvImportResult
        With what was dropped: motor rows missing a knob position, invalid tracker frames,
        rows with neither, motor samples left out of the aligned table for want of a reading
        (also recorded in ``run.json``'s ``backend``, or the Parquet table's metadata).

    Raises
    ------
    RunFormatError
        A bad map, a column the map names that the log lacks (listing those it has), a
        non-numeric column, time that does not increase, duplicated stamps, and numbers no rig
        logs (a unit mistake: knob positions far beyond the probe's limits, a sample rate (from the
        clock or ``sample_rate_hz``) outside :data:`~endocal.runs.format.LOG_RATE_RANGE_HZ`, sensors
        too near or too far apart, a base quaternion read in the wrong order, a knob whose bend moves
        many times as far as it does, fewer aligned rows than a fit can use:
        :mod:`endocal.runs.csvchecks`); before anything is written. Whatever fails while writing,
        nothing is left at ``out``.
    """
    log, out = Path(log), Path(out)
    cmap = mapping if isinstance(mapping, CsvMap) else read_map(mapping)
    where = str(log)
    wall0 = time.monotonic()
    df, raw = read_log_table(log)
    missing = [c for c in cmap.columns() if c not in df.columns]
    if missing:
        raise RunFormatError(f"{cmap.source} names column '{missing[0]}' ({cmap.role_of(missing[0])}), which {log.name} "
                             f"does not have; its columns: {', '.join(map(str, df.columns))}")
    if cmap.angles:
        _prepare_table(out, force, cmap.source)
    else:
        _prepare_run(out, force, cmap.source)
    n_rows = len(df)
    df, t, dropped, merged = _clock(df, cmap, dedupe, where)
    lines = df.index.to_numpy()
    motor, is_motor, incomplete = _motor(df, t, cmap, where)
    # with measured angles the probe only names the axes (a bench's pulley may turn past any probe
    # knob's limits): the knobs are checked against the limits of a probe's run only (a linear drive
    # against a tendon's travel either way)
    check_knobs(motor, cmap, where, probe_limits=not cmap.angles)
    check_rate(motor["t_s"], cmap, TIME_UNITS, where)
    probe = cmap.probe

    sha = hashlib.sha256(raw).hexdigest()
    map_text = Path(cmap.source).read_bytes() if Path(cmap.source).is_file() else b""
    source = {"name": "csv-import", "source": str(log), "sha256": sha, "map": cmap.source,
              "map_sha256": hashlib.sha256(map_text).hexdigest() if map_text else None}
    rate = sample_rate_hz(motor["t_s"])
    # a drive in another unit than the probe's knobs says so: "ap (mm) <- Tendon Disp."
    columns = {"time": cmap.time_column or f"{cmap.sample_rate_hz:g} Hz",
               **{d if cmap.unit(d) == probe.unit(d) else f"{d} ({cmap.unit(d)})": k.position
                  for d, k in cmap.knobs.items()},
               **{f"{a}{MEAS}": ang.column for a, ang in cmap.angles.items()}}
    first = (lambda mask: int(lines[np.argmax(mask)]) if mask.any() else None)

    def backend(unused: np.ndarray, invalid: np.ndarray, gaps: ReadingGaps) -> dict:
        return {"name": "csv-import", "map": cmap.raw, "rows": n_rows, "duplicates_dropped": dropped,
                "rows_merged": merged, "motor_rows_incomplete": int(incomplete.sum()),
                "tracker_frames_invalid": int(invalid.sum()), "rows_unused": int(unused.sum()),
                "motor_rows_unaligned": gaps.rows, "motor_rows_unaligned_line": gaps.first_line,
                "longest_gap_s": gaps.longest_s,
                "command_source": ("goal columns" if all(k.goal for k in cmap.knobs.values()) else
                                   "knob position where no goal column is mapped (the servo's lag is not in the data)")}

    def result(run_dir, n_read, n_aligned, invalid, unused, gaps: ReadingGaps, alignment_error=None) -> CsvImportResult:
        return CsvImportResult(run_dir, n_rows, bool(cmap.angles), len(motor["t_s"]), n_read, n_aligned, dropped,
                               merged, float(motor["t_s"][-1]), rate, columns, alignment_error,
                               int(incomplete.sum()), first(incomplete), int(invalid.sum()), first(invalid),
                               int(unused.sum()), first(unused), gaps.rows, gaps.first_line, gaps.longest_s,
                               axes=_fittable_axes(motor, cmap))

    if cmap.angles:
        is_read, covered, table, unit_warnings = _angles_table(df, t, motor, cmap, where)
        gaps = reading_gaps(covered, t[is_read], motor["t_s"], lines[is_motor])
        unused, invalid = ~(is_motor | incomplete | is_read), np.zeros(len(df), bool)
        _write_table(out, table, {"source": source, "backend": backend(unused, invalid, gaps), "command": command,
                                  "drive_units": {a: cmap.unit(a) for a in cmap.angles},
                                  "software": software_versions()})
        return replace(result(out, int(is_read.sum()), len(table), invalid, unused, gaps),
                       unit_warnings=tuple(unit_warnings))

    tip, base, valid, is_frame = _frames(df, t, cmap, where)
    good = is_frame & valid.all(axis=1)
    if not good.any():
        why = (f" ({int(is_frame.sum())} row(s) hold a pose, each with a sensor missing, flagged invalid or with a "
               "quaternion that is no rotation)" if is_frame.any() else "")
        raise RunFormatError(f"{where}: no row has both the tip and the base pose{why}")
    check_distance(tip, base, good, cmap, LENGTH_UNITS, where)
    check_base_order(tip, base, good, cmap, where)
    check_knob_to_bend(motor, tip, base, good, cmap, where)
    # the aligned rows align() will make: motor samples within MAX_GAP_S of a frame with both sensors
    covered = measured_at(t[good], motor["t_s"], MAX_GAP_S)
    check_aligned_rows(int(covered.sum()), motor["t_s"], t[good], "tracker frame", cmap, where)
    gaps = reading_gaps(covered, t[good], motor["t_s"], lines[is_motor])
    invalid, unused = is_frame & ~good, ~(is_motor | incomplete | is_frame)
    tracker = tracker_stream(tip[is_frame], base[is_frame], valid[is_frame])
    meta = write_imported_run(out, motor, tracker, probe, source=source, backend=backend(unused, invalid, gaps),
                              command=command, wall0=wall0, drive_units=cmap.drive_units())
    return result(out, int(is_frame.sum()), meta["counts"].get("aligned_rows", 0), invalid, unused, gaps,
                  meta.get("alignment_error"))


def _prepare_run(out: Path, force: bool, map_source: str) -> None:
    """Check that ``out`` can become a run folder (without creating it): a pose map's import is
    a run folder (motor and tracker streams, aligned table), never a table file."""
    if out.suffix.lower() in (".parquet", *CSV_SUFFIXES):
        raise OutputPathError(f"{map_source} maps EM poses, so the import is a run folder (motor and tracker streams "
                              f"and their aligned table), not a {out.suffix} table: give --out a folder name (got {out})")
    prepare_output(out, force)


def _prepare_table(out: Path, force: bool, map_source: str) -> None:
    """Check that ``out`` can become an aligned table file (without creating it)."""
    if out.suffix.lower() not in TABLE_SUFFIXES:
        raise OutputPathError(f"{map_source} maps measured angles, not EM poses, so the import is an aligned table: "
                              f"give --out a .parquet or .csv file name (got {out})")
    if out.is_dir():
        raise OutputPathError(f"output {out} is a folder: choose a .parquet or .csv file name for --out")
    if out.exists() and not force:
        raise OutputExistsError(f"output {out} already exists: choose a new --out or pass --force to replace it")
    if out.exists() and not _is_aligned_table(out):
        # --force replaces an aligned table, never a lab's own file that happens to end in .csv
        raise OutputPathError(f"output {out} exists and is not an aligned table (t_s, <axis>_cmd_deg, <axis>_meas_deg): "
                              "--force only replaces tables; choose another --out")
    check_parent(out)


def _is_aligned_table(path: Path) -> bool:
    """Whether ``path`` holds an aligned table, as every command that reads one checks it."""
    try:
        load_aligned(path)
    except RunFormatError:
        return False
    return True


def _angles_table(df: pd.DataFrame, t: np.ndarray, motor: dict, cmap: CsvMap,
                  where: str) -> tuple[np.ndarray, np.ndarray, pd.DataFrame, list[str]]:
    """Which rows hold every measured angle, which motor samples those readings cover, the
    aligned table of a log with measured angles (the covered motor samples), and what looks like
    a unit mistake in it (:func:`~endocal.runs.csvchecks.measured_angle_warnings`).

    The readings are interpolated onto the motor samples inside their span, across gaps of
    at most :data:`MAX_GAP_S` (as tracker frames are in :func:`endocal.runs.aligned.align`).
    """
    meas = {a: ang.convert(_numeric(df, ang.column, where)) for a, ang in cmap.angles.items()}
    is_read = np.logical_and.reduce([np.isfinite(v) for v in meas.values()])
    if not is_read.any():
        raise RunFormatError(f"{where}: no row has every measured angle "
                             f"({', '.join(a.column for a in cmap.angles.values())})")
    t_read, t_motor = t[is_read], motor["t_s"]
    ok = measured_at(t_read, t_motor, MAX_GAP_S)
    check_aligned_rows(int(ok.sum()), t_motor, t_read, "angle reading", cmap, where)
    table = {"t_s": t_motor[ok]}
    for axis in cmap.angles:
        u = cmap.unit(axis)
        table[cmd_column(axis, u)] = motor[f"{axis}_goal_{u}"][ok]
        table[axis + MEAS] = np.interp(t_motor[ok], t_read, meas[axis][is_read])
    for dof, k in cmap.knobs.items():
        u = cmap.unit(dof)
        if k.goal or dof not in cmap.angles:
            table[f"{dof}_pos_{u}"] = motor[f"{dof}_pos_{u}"][ok]
        if k.current:
            table[f"{dof}_current_ma"] = motor[f"{dof}_current_ma"][ok]
    for col in cmap.extras:
        table[col] = motor[col][ok]
    out = pd.DataFrame(table)
    check_aligned(out, where)
    warnings = measured_angle_warnings({dof: motor[f"{dof}_pos_{cmap.unit(dof)}"][ok] for dof in cmap.knobs},
                                       {axis: table[axis + MEAS] for axis in cmap.angles}, cmap, where)
    return is_read, ok, out, warnings


def _fittable_axes(motor: dict[str, np.ndarray], cmap: CsvMap) -> tuple[str, ...]:
    """The bending axes of an import a model can be fitted to: measured (an [angles] column, or both
    poses for every bending axis) and commanded through a range (a knob held still has no loop)."""
    measured = [a for a in cmap.probe.bending_axes if a in cmap.knobs and (not cmap.angles or a in cmap.angles)]
    return tuple(a for a in measured if float(np.ptp(motor[f"{a}_goal_{cmap.unit(a)}"])) > 0)


def _write_table(out: Path, table: pd.DataFrame, provenance: dict) -> None:
    """Write the aligned table whole or not at all; Parquet carries the provenance as metadata."""
    data = table.to_csv(index=False).encode() if out.suffix.lower() == ".csv" else parquet_bytes(table, provenance)
    atomic_write_bytes(out, data)


__all__ = ["CsvImportResult", "CsvMap", "import_csv", "read_map"]
