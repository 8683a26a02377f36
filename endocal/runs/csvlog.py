"""Import a lab's CSV log into a run folder, through a map that names its columns.

Labs log their rigs as plain CSV: a clock (or none), knob positions in whatever unit the
servo reports, perhaps the goals sent and the motor currents, and the raw EM poses of the tip
and base sensors. A *map* (TOML, see ``configs/csv-map.example.toml``) says which column is
what and in which unit; :func:`import_csv` converts everything to the run format's units
(:mod:`endocal.runs.format`), and the bending angles are computed by thesis eq. 1 from the
poses exactly as for endocal's own runs (the aligned table is built by the same code).

Rows
----
A row with every mapped knob position is a motor sample; a row with finite tip and base poses
is a tracker frame (both at the row's time). A log with one row per motor tick and the latest
pose repeated is read as it is; a log with separate motor and tracker rows (empty cells where
a device did not report) is read exactly.

Measured angles instead of poses
--------------------------------
A rig that measures the bending angle itself (a joint encoder, a camera, a protractor on a
tendon-sheath bench) maps ``[angles.AXIS]`` columns instead of ``[tip]`` and ``[base]``. There
is no tracker stream to keep, so the import is an aligned table (``.parquet`` or ``.csv``): the
angles interpolated onto the motor samples as :func:`endocal.runs.aligned.align` does with
eq. 1's. ``extras`` names further numeric columns (a sheath configuration, a load) carried
into the aligned table, where models take them as covariates (``load:COLUMN``).

Duplicated time stamps (ROS bridges often write them) are refused by default, with their
count and the first line; ``dedupe=True`` drops rows that repeat an earlier row exactly,
merges rows of one stamp that fill different columns (a motor tick and a tracker frame logged
in the same millisecond) and says how many, and still refuses a stamp shared by rows with
different values in one column.
"""

from __future__ import annotations

import hashlib
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from endocal.errors import OutputExistsError, OutputPathError, RunFormatError
from endocal.probe import TRANSLATION, ProbeConfig, load_probe
from endocal.runs.aligned import CMD, MEAS, check_aligned, load_aligned, measured_at
from endocal.runs.format import atomic_write_bytes, check_parent, parquet_bytes, prepare_output, software_versions
from endocal.runs.imported import tracker_stream, write_imported_run
from endocal.runs.textable import read_csv_table

#: What a drafted map (:mod:`endocal.runs.mapdraft`) writes where it could not place a column.
UNFILLED = "FILL IN"
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "datetime": None}  # s per unit; datetime: text stamps
ANGLE_UNITS = ("deg", "rad", "ticks")
_SCALE = {"deg": 1.0, "rad": 180.0 / np.pi, "mm": 1.0, "m": 1000.0}  # to the run's deg or mm
LENGTH_UNITS = {"mm": 1.0, "m": 1000.0}
CURRENT_UNITS = {"mA": 1.0, "A": 1000.0}
QUAT_ORDERS = ("xyzw", "wxyz")
_MAP_KEYS = {"probe", "time", "knobs", "tip", "base", "angles", "extras"}
_ANGLE_KEYS = {"column", "unit", "direction", "zero"}
TABLE_SUFFIXES = (".parquet", ".csv")
MAX_GAP_S = 0.2  # longest gap between angle readings to interpolate across, as align() for tracker frames
_TIME_KEYS = {"column", "unit", "sample_rate_hz"}
_KNOB_KEYS = {"position", "goal", "current", "unit", "zero_ticks", "ticks_per_rev", "direction", "current_unit"}
_POSE_KEYS = {"position", "unit", "quaternion", "order", "valid", "fixed_position", "fixed_quaternion"}


@dataclass(frozen=True)
class CsvImportResult:
    """What :func:`import_csv` wrote."""

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


@dataclass(frozen=True)
class _Knob:
    position: str
    unit: str
    goal: str | None
    current: str | None
    zero_ticks: float
    ticks_per_rev: float
    direction: float
    current_factor: float

    def convert(self, v: np.ndarray) -> np.ndarray:
        """Raw column values in the run's unit: deg (knobs, rotation) or mm (translation)."""
        if self.unit == "ticks":
            return (v - self.zero_ticks) * 360.0 / self.ticks_per_rev * self.direction
        return v * _SCALE[self.unit] * self.direction


@dataclass(frozen=True)
class _Angle:
    column: str
    factor: float
    direction: float
    zero: float

    def convert(self, v: np.ndarray) -> np.ndarray:
        """Raw readings as the bending angle in degrees."""
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

    def columns(self) -> list[str]:
        """Every CSV column the map names."""
        cols = [self.time_column] if self.time_column else []
        for k in self.knobs.values():
            cols += [c for c in (k.position, k.goal, k.current) if c]
        for p in (self.tip, self.base):
            if p is not None:
                cols += p.position + p.quaternion + ([p.valid] if p.valid else [])
        return cols + [a.column for a in self.angles.values()] + list(self.extras)


def _table(d, key: str, where: str, known: set[str]) -> dict:
    v = d.get(key)
    if not isinstance(v, dict):
        raise RunFormatError(f"{where}: a [{key}] table is required")
    unknown = sorted(set(v) - known)
    if unknown:
        raise RunFormatError(f"{where}: unknown key(s) {', '.join(unknown)} in [{key}]; it takes {', '.join(sorted(known))}")
    return v


def _choice(value, choices, what: str, where: str):
    if value not in choices:
        raise RunFormatError(f"{where}: unknown {what} {value!r}; use one of {', '.join(map(str, choices))}")
    return value


def _names(value, n: int, what: str, where: str) -> list[str]:
    if not (isinstance(value, list) and len(value) == n and all(isinstance(c, str) and c for c in value)):
        raise RunFormatError(f"{where}: {what} must list {n} column names")
    return list(value)


def _numbers(v, n: int) -> bool:
    return isinstance(v, list) and len(v) == n and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)


def _pose(d: dict, key: str, where: str) -> _Pose:
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
    valid = t.get("valid")
    if valid is not None and not isinstance(valid, str):
        raise RunFormatError(f"{w}: valid must name a column")
    return _Pose(_names(t.get("position"), 3, "position", w), LENGTH_UNITS[unit],
                 _names(t.get("quaternion"), 4, "quaternion", w), order, valid)


def _direction(t: dict, w: str) -> float:
    direction = t.get("direction", 1)
    if direction not in (1, -1):
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
        if not isinstance(a.get("column"), str) or not a["column"]:
            raise RunFormatError(f"{w}: column must name the column of the measured angle")
        unit = _choice(a.get("unit", "deg"), ("deg", "rad"), "angle unit", w)
        zero = a.get("zero", 0.0)
        if not isinstance(zero, (int, float)):
            raise RunFormatError(f"{w}: zero must be a number (the reading when the section is straight), got {zero!r}")
        out[axis] = _Angle(a["column"], _SCALE[unit], _direction(a, w), float(zero))
    return out


def _extras(d: dict, where: str) -> tuple[str, ...]:
    extras = d.get("extras", [])
    if not (isinstance(extras, list) and all(isinstance(c, str) and c for c in extras)):
        raise RunFormatError(f"{where}: extras must list column names, e.g. extras = [\"sheath_wrap_deg\"]")
    clash = [c for c in extras if c == "t_s" or c.endswith((CMD, MEAS))]
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
        bending axis of the probe without a knob table, ticks without ``zero_ticks`` and
        ``ticks_per_rev``.
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
    if rate is not None and not (isinstance(rate, (int, float)) and rate > 0):
        raise RunFormatError(f"{where} [time]: sample_rate_hz must be a positive number, got {rate!r}")
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
        unit = _choice(k.get("unit", "deg"), ANGLE_UNITS if dof != TRANSLATION else ("mm", "m"), "unit", w)
        if unit == "ticks" and ("zero_ticks" not in k or "ticks_per_rev" not in k):
            raise RunFormatError(f"{w}: unit 'ticks' needs zero_ticks and ticks_per_rev (e.g. 2048 and 4096)")
        direction = _direction(k, w)
        if not isinstance(k.get("position"), str):
            raise RunFormatError(f"{w}: position must name a column")
        cur_unit = _choice(k.get("current_unit", "mA"), CURRENT_UNITS, "current unit", w)
        knobs[dof] = _Knob(k["position"], unit, k.get("goal"), k.get("current"), float(k.get("zero_ticks", 0)),
                           float(k.get("ticks_per_rev", 4096)), float(direction), CURRENT_UNITS[cur_unit])
    angles = _angles(d, probe, where)
    missing = [a for a in (angles or probe.bending_axes) if a not in knobs]
    if missing:
        whose = "every measured angle" if angles else f"every bending axis of probe '{probe.name}'"
        raise RunFormatError(f"{where}: no [knobs.{missing[0]}] table: {whose} "
                             f"({', '.join(angles or probe.bending_axes)}) needs its knob column")
    tip, base = (None, None) if angles else (_pose(d, "tip", where), _pose(d, "base", where))
    cmap = CsvMap(probe, column, factor, float(rate) if rate is not None else None, knobs, tip, base, angles,
                  _extras(d, where), where, d)
    if UNFILLED in cmap.columns():
        raise RunFormatError(f"{where}: a column is still '{UNFILLED}' (a drafted map): name the log's column for "
                             "that role, or delete the role if the log has none")
    valid = {p.valid for p in (tip, base) if p is not None and p.valid}  # one flag may serve both sensors
    named = [c for c in cmap.columns() if c not in valid]
    twice = sorted({c for c in named if named.count(c) > 1})
    if twice:
        raise RunFormatError(f"{where}: column '{twice[0]}' is named for two roles (e.g. the clock and a knob); "
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
    df.index = np.arange(len(df)) + (1 if df.attrs.get("headerless") else 2)
    return df


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


def _dedupe(df: pd.DataFrame, t: np.ndarray, lines: np.ndarray, dedupe: bool,
            where: str) -> tuple[pd.DataFrame, np.ndarray, np.ndarray, int, int]:
    """Drop exact duplicate rows and merge rows of one stamp (with ``dedupe``), then refuse any
    time stamp still shared.

    A logger writing one row per message puts a motor tick and a tracker frame that arrive in
    the same millisecond on two rows with one stamp, each with the other device's cells empty:
    ``dedupe`` merges such rows into one. Rows of one stamp with different values in the same
    column are a conflict no merge can settle, and are refused.

    ``lines`` are the rows' line numbers in the file (for messages); returned filtered alike,
    with the number of exact repeats dropped and of rows merged into an earlier one.
    """
    dropped = merged = 0
    if dedupe:
        exact = df.duplicated(keep="first").to_numpy()
        dropped = int(exact.sum())
        df, t, lines = df[~exact], t[~exact], lines[~exact]
        shared = np.concatenate([[False], np.diff(t) == 0])
        if shared.any():
            group = np.cumsum(~shared)  # t does not decrease here, or the log is refused next
            dup = shared | np.concatenate([shared[1:], [False]])  # every row of a shared stamp
            conflict = df[dup].groupby(group[dup], sort=False).nunique(dropna=True).max(axis=1) > 1
            if conflict.any():
                g = int(conflict.index[np.argmax(conflict.to_numpy())])
                rows = np.flatnonzero(group == g)
                col = next(c for c in df.columns if df.iloc[rows][c].dropna().nunique() > 1)
                raise RunFormatError(f"{where}: rows at lines {lines[rows[0]]} and {lines[rows[1]]} share a time stamp "
                                     f"(t = {t[rows[0]]:g}) but differ in column '{col}'; no merge can settle which "
                                     "is right: fix the log's clock, or, if its rows are evenly spaced in time, replace [time] column with "
                                     "sample_rate_hz in the map")
            merged = int(shared.sum())
            t, lines = t[~shared], lines[~shared]
            df = df.groupby(group, sort=False).first().set_axis(lines)
    same = np.concatenate([[False], np.diff(t) == 0])
    if same.any():
        first = int(np.flatnonzero(same)[0])
        raise RunFormatError(f"{where}: {int(same.sum())} row(s) repeat a time stamp (pass --dedupe to drop rows that "
                             "repeat an earlier row exactly and merge rows of one stamp that fill different columns); "
                             f"the first at line {lines[first]} (t = {t[first]:g})")
    return df, t, lines, dropped, merged


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
        Drop rows that repeat an earlier row exactly and merge rows of one stamp that fill
        different columns (else duplicated time stamps are refused).
    force : bool
        Replace an existing run folder (or table).

    Raises
    ------
    RunFormatError
        A bad map, a column the map names that the log lacks (listing those it has), a
        non-numeric column, time that does not increase, duplicated stamps; before anything
        is written.
    """
    log, out = Path(log), Path(out)
    cmap = mapping if isinstance(mapping, CsvMap) else read_map(mapping)
    where = str(log)
    wall0 = time.monotonic()
    df, raw = read_log_table(log)
    missing = [c for c in cmap.columns() if c not in df.columns]
    if missing:
        raise RunFormatError(f"{cmap.source} names column '{missing[0]}', which {log.name} does not have; its columns: "
                             f"{', '.join(map(str, df.columns))}")
    if cmap.angles:
        _prepare_table(out, force, cmap.source)
    else:
        prepare_output(out, force)
    n_rows = len(df)
    lines = df.index.to_numpy()  # line numbers in the file
    if cmap.time_column:
        t = (_datetime_s(df, cmap.time_column, where) if cmap.time_factor is None else
             _numeric(df, cmap.time_column, where) * cmap.time_factor)
        if not np.isfinite(t).all():
            line = int(lines[np.flatnonzero(~np.isfinite(t))[0]])
            raise RunFormatError(f"{where}: time column '{cmap.time_column}' is empty or not a number at line {line}")
        df, t, lines, dropped, merged = _dedupe(df, t, lines, dedupe, where)
        back = np.flatnonzero(np.diff(t) < 0)
        if back.size:
            k = int(back[0])
            raise RunFormatError(f"{where}: time goes back at line {lines[k + 1]} ({t[k]:g} -> {t[k + 1]:g} s); "
                                 "sort the log by time")
    else:
        exact = df.duplicated(keep="first").to_numpy() if dedupe else np.zeros(len(df), bool)
        dropped, merged = int(exact.sum()), 0
        df = df[~exact]
        t = np.arange(len(df)) / cmap.sample_rate_hz
    t0 = float(t[0])
    t = t - t0

    pos = {dof: k.convert(_numeric(df, k.position, where)) for dof, k in cmap.knobs.items()}
    is_motor = np.logical_and.reduce([np.isfinite(p) for p in pos.values()])
    if not is_motor.any():
        raise RunFormatError(f"{where}: no row has every knob position ({', '.join(k.position for k in cmap.knobs.values())})")
    probe = cmap.probe
    motor = {"t_s": t[is_motor]}
    for dof in probe.dofs:
        u = probe.unit(dof)
        k = cmap.knobs.get(dof)
        p = pos[dof][is_motor] if k is not None else np.zeros(int(is_motor.sum()))
        g = k.convert(_numeric(df, k.goal, where))[is_motor] if k is not None and k.goal else p
        if not np.isfinite(g).all():
            line = int(np.flatnonzero(~np.isfinite(g))[0])
            raise RunFormatError(f"{where}: goal column '{k.goal}' is empty on a motor row (sample {line})")
        motor[f"{dof}_goal_{u}"] = g
        motor[f"{dof}_pos_{u}"] = p
        motor[f"{dof}_vel_{u}ps"] = np.gradient(p, motor["t_s"]) if p.size > 1 else np.zeros_like(p)
        cur = (_numeric(df, k.current, where)[is_motor] * k.current_factor if k is not None and k.current
               else np.zeros_like(p))
        motor[f"{dof}_current_ma"] = np.nan_to_num(cur)
    for col in cmap.extras:
        motor[col] = _numeric(df, col, where)[is_motor]

    sha = hashlib.sha256(raw).hexdigest()
    map_text = Path(cmap.source).read_bytes() if Path(cmap.source).is_file() else b""
    source = {"name": "csv-import", "source": str(log), "sha256": sha, "map": cmap.source,
              "map_sha256": hashlib.sha256(map_text).hexdigest() if map_text else None}
    backend = {"name": "csv-import", "map": cmap.raw, "rows": n_rows, "duplicates_dropped": dropped,
               "rows_merged": merged,
               "command_source": ("goal columns" if all(k.goal for k in cmap.knobs.values()) else
                                  "knob position where no goal column is mapped (the servo's lag is not in the data)")}
    dt = np.diff(motor["t_s"])
    rate = float(1.0 / np.median(dt)) if dt.size and np.median(dt) > 0 else None
    columns = {"time": cmap.time_column or f"{cmap.sample_rate_hz:g} Hz", **{d: k.position for d, k in cmap.knobs.items()},
               **{f"{a}{MEAS}": ang.column for a, ang in cmap.angles.items()}}
    if cmap.angles:
        n_read, table = _angles_table(df, t, motor, cmap, where)
        _write_table(out, table, {"source": source, "backend": backend, "command": command,
                                  "software": software_versions()})
        return CsvImportResult(out, n_rows, True, len(motor["t_s"]), n_read, len(table), dropped, merged,
                               float(motor["t_s"][-1]), rate, columns, None)

    def pose_rows(pc: _Pose) -> np.ndarray:
        if pc.fixed is not None:
            xyz = np.tile(np.array(pc.fixed[:3]) * pc.factor, (len(df), 1))
            q = np.tile(np.array(pc.fixed[3:]), (len(df), 1))
        else:
            xyz = np.column_stack([_numeric(df, c, where) for c in pc.position]) * pc.factor
            q = np.column_stack([_numeric(df, c, where) for c in pc.quaternion])
        wxyz = q if pc.order == "wxyz" else q[:, [3, 0, 1, 2]]
        return np.column_stack([t, xyz, wxyz])

    tip, base = pose_rows(cmap.tip), pose_rows(cmap.base)
    valid = np.column_stack([np.ones(len(df), bool), np.ones(len(df), bool)])
    for j, pc in enumerate((cmap.tip, cmap.base)):
        if pc.valid:
            valid[:, j] = np.nan_to_num(_numeric(df, pc.valid, where)) != 0
    is_frame = np.isfinite(tip).all(axis=1) & np.isfinite(base).all(axis=1)
    if not is_frame.any():
        raise RunFormatError(f"{where}: no row has both the tip and the base pose")
    tracker = tracker_stream(tip[is_frame], base[is_frame], valid[is_frame])
    meta = write_imported_run(out, motor, tracker, probe, source=source, backend=backend, command=command, wall0=wall0)
    return CsvImportResult(out, n_rows, False, meta["motor_rows"], int(is_frame.sum()),
                           meta["counts"].get("aligned_rows", 0), dropped, merged, float(motor["t_s"][-1]), rate, columns,
                           meta.get("alignment_error"))


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


def _angles_table(df: pd.DataFrame, t: np.ndarray, motor: dict, cmap: CsvMap, where: str) -> tuple[int, pd.DataFrame]:
    """The aligned table of a log with measured angles, and how many rows held a reading.

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
    if not ok.any():
        raise RunFormatError(f"{where}: no motor sample lies within {MAX_GAP_S:g} s of an angle reading")
    probe = cmap.probe
    table = {"t_s": t_motor[ok]}
    for axis in cmap.angles:
        table[axis + CMD] = motor[f"{axis}_goal_deg"][ok]
        table[axis + MEAS] = np.interp(t_motor[ok], t_read, meas[axis][is_read])
    for dof, k in cmap.knobs.items():
        u = probe.unit(dof)
        if k.goal or dof not in cmap.angles:
            table[f"{dof}_pos_{u}"] = motor[f"{dof}_pos_{u}"][ok]
        if k.current:
            table[f"{dof}_current_ma"] = motor[f"{dof}_current_ma"][ok]
    for col in cmap.extras:
        table[col] = motor[col][ok]
    out = pd.DataFrame(table)
    check_aligned(out, where)
    return int(is_read.sum()), out


def _write_table(out: Path, table: pd.DataFrame, provenance: dict) -> None:
    """Write the aligned table whole or not at all; Parquet carries the provenance as metadata."""
    data = table.to_csv(index=False).encode() if out.suffix.lower() == ".csv" else parquet_bytes(table, provenance)
    atomic_write_bytes(out, data)


__all__ = ["CsvImportResult", "CsvMap", "import_csv", "read_map"]
