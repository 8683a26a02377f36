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

Duplicated time stamps (ROS bridges often write them) are refused by default, with their
count and the first line; ``dedupe=True`` drops rows that repeat an earlier row exactly and
says how many, and still refuses a stamp shared by rows that differ.
"""

from __future__ import annotations

import hashlib
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from endocal.errors import RunFormatError
from endocal.probe import TRANSLATION, ProbeConfig, load_probe
from endocal.runs.format import prepare_output
from endocal.runs.imported import tracker_stream, write_imported_run
from endocal.runs.textable import read_csv_table

TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
ANGLE_UNITS = ("deg", "rad", "ticks")
_SCALE = {"deg": 1.0, "rad": 180.0 / np.pi, "mm": 1.0, "m": 1000.0}  # to the run's deg or mm
LENGTH_UNITS = {"mm": 1.0, "m": 1000.0}
CURRENT_UNITS = {"mA": 1.0, "A": 1000.0}
QUAT_ORDERS = ("xyzw", "wxyz")
_MAP_KEYS = {"probe", "time", "knobs", "tip", "base"}
_TIME_KEYS = {"column", "unit", "sample_rate_hz"}
_KNOB_KEYS = {"position", "goal", "current", "unit", "zero_ticks", "ticks_per_rev", "direction", "current_unit"}
_POSE_KEYS = {"position", "unit", "quaternion", "order", "valid"}


@dataclass(frozen=True)
class CsvImportResult:
    """What :func:`import_csv` wrote."""

    run_dir: Path
    rows: int
    motor_rows: int
    tracker_frames: int
    aligned_rows: int
    duplicates_dropped: int
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
class _Pose:
    position: list[str]
    factor: float
    quaternion: list[str]
    order: str
    valid: str | None


@dataclass(frozen=True)
class CsvMap:
    """A validated column map.

    Attributes
    ----------
    probe : ProbeConfig
    time_column : str or None
        With ``time_factor`` (s per unit); None when ``sample_rate_hz`` gives the clock.
    sample_rate_hz : float or None
    knobs : dict
        Degree of freedom -> knob columns and unit.
    tip, base : pose columns and units
    source : str
        The map file (for messages and run.json).
    raw : dict
        The map as read.
    """

    probe: ProbeConfig
    time_column: str | None
    time_factor: float
    sample_rate_hz: float | None
    knobs: dict
    tip: _Pose
    base: _Pose
    source: str
    raw: dict

    def columns(self) -> list[str]:
        """Every CSV column the map names."""
        cols = [self.time_column] if self.time_column else []
        for k in self.knobs.values():
            cols += [c for c in (k.position, k.goal, k.current) if c]
        for p in (self.tip, self.base):
            cols += p.position + p.quaternion + ([p.valid] if p.valid else [])
        return cols


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


def _pose(d: dict, key: str, where: str) -> _Pose:
    t = _table(d, key, where, _POSE_KEYS)
    w = f"{where} [{key}]"
    unit = _choice(t.get("unit", "mm"), LENGTH_UNITS, "length unit", w)
    order = _choice(t.get("order", "xyzw"), QUAT_ORDERS, "quaternion order", w)
    valid = t.get("valid")
    if valid is not None and not isinstance(valid, str):
        raise RunFormatError(f"{w}: valid must name a column")
    return _Pose(_names(t.get("position"), 3, "position", w), LENGTH_UNITS[unit],
                 _names(t.get("quaternion"), 4, "quaternion", w), order, valid)


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
        raise RunFormatError(f"{where} [time]: give either column (with unit s, ms, us or ns) or sample_rate_hz "
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
        direction = k.get("direction", 1)
        if direction not in (1, -1):
            raise RunFormatError(f"{w}: direction must be 1 or -1, got {direction!r}")
        if not isinstance(k.get("position"), str):
            raise RunFormatError(f"{w}: position must name a column")
        cur_unit = _choice(k.get("current_unit", "mA"), CURRENT_UNITS, "current unit", w)
        knobs[dof] = _Knob(k["position"], unit, k.get("goal"), k.get("current"), float(k.get("zero_ticks", 0)),
                           float(k.get("ticks_per_rev", 4096)), float(direction), CURRENT_UNITS[cur_unit])
    missing = [a for a in probe.bending_axes if a not in knobs]
    if missing:
        raise RunFormatError(f"{where}: no [knobs.{missing[0]}] table: every bending axis of probe '{probe.name}' "
                             f"({', '.join(probe.bending_axes)}) needs its knob column")
    return CsvMap(probe, column, factor, float(rate) if rate is not None else None, knobs, _pose(d, "tip", where),
                  _pose(d, "base", where), where, d)


def _read_csv(raw: bytes, where: str) -> pd.DataFrame:
    try:
        df = read_csv_table(raw)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise RunFormatError(f"{where}: not a CSV table ({str(exc).splitlines()[0]})") from None
    if df.shape[1] < 2 or df.empty:
        raise RunFormatError(f"{where}: not a CSV table of a log (found {df.shape[1]} column(s), {len(df)} row(s))")
    return df


def _numeric(df: pd.DataFrame, col: str, where: str) -> np.ndarray:
    try:
        return pd.to_numeric(df[col], errors="raise").to_numpy(float)
    except (ValueError, TypeError):
        bad = pd.to_numeric(df[col], errors="coerce").isna() & df[col].notna()
        line = int(np.flatnonzero(bad.to_numpy())[0]) + 2
        raise RunFormatError(f"{where}: column '{col}' is not numeric (line {line}: {df[col].iloc[line - 2]!r})") from None


def _dedupe(df: pd.DataFrame, t: np.ndarray, lines: np.ndarray, dedupe: bool,
            where: str) -> tuple[pd.DataFrame, np.ndarray, np.ndarray, int]:
    """Drop exact duplicate rows (with ``dedupe``), then refuse any time stamp still shared.

    ``lines`` are the rows' line numbers in the file (for messages); returned filtered alike.
    """
    dropped = 0
    if dedupe:
        exact = df.duplicated(keep="first").to_numpy()
        dropped = int(exact.sum())
        df, t, lines = df[~exact].reset_index(drop=True), t[~exact], lines[~exact]
    same = np.concatenate([[False], np.diff(t) == 0])
    if same.any():
        first = int(np.flatnonzero(same)[0])
        what = ("row(s) that differ share a time stamp even after dropping exact repeats" if dedupe else
                "row(s) repeat a time stamp (pass --dedupe to drop rows that repeat an earlier row exactly)")
        raise RunFormatError(f"{where}: {int(same.sum())} {what}; the first at line {lines[first]} (t = {t[first]:g})")
    return df, t, lines, dropped


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
        Run folder to create.
    dedupe : bool
        Drop rows that repeat an earlier row exactly (else duplicated time stamps are refused).
    force : bool
        Replace an existing run folder.

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
    try:
        raw = log.read_bytes()
    except OSError as exc:
        raise RunFormatError(f"{where}: cannot read the log ({exc.strerror or exc})") from None
    df = _read_csv(raw, where)
    missing = [c for c in cmap.columns() if c not in df.columns]
    if missing:
        raise RunFormatError(f"{cmap.source} names column '{missing[0]}', which {log.name} does not have; its columns: "
                             f"{', '.join(map(str, df.columns))}")
    prepare_output(out, force)
    n_rows = len(df)
    lines = np.arange(len(df)) + 2  # line numbers in the file (line 1 is the header)
    if cmap.time_column:
        t = _numeric(df, cmap.time_column, where) * cmap.time_factor
        if not np.isfinite(t).all():
            line = int(lines[np.flatnonzero(~np.isfinite(t))[0]])
            raise RunFormatError(f"{where}: time column '{cmap.time_column}' is empty or not a number at line {line}")
        df, t, lines, dropped = _dedupe(df, t, lines, dedupe, where)
        back = np.flatnonzero(np.diff(t) < 0)
        if back.size:
            k = int(back[0])
            raise RunFormatError(f"{where}: time goes back at line {lines[k + 1]} ({t[k]:g} -> {t[k + 1]:g} s); "
                                 "sort the log by time")
    else:
        exact = df.duplicated(keep="first").to_numpy() if dedupe else np.zeros(len(df), bool)
        dropped = int(exact.sum())
        df = df[~exact].reset_index(drop=True)
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

    def pose_rows(pc: _Pose) -> np.ndarray:
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

    sha = hashlib.sha256(raw).hexdigest()
    map_text = Path(cmap.source).read_bytes() if Path(cmap.source).is_file() else b""
    source = {"name": "csv-import", "source": str(log), "sha256": sha, "map": cmap.source,
              "map_sha256": hashlib.sha256(map_text).hexdigest() if map_text else None}
    backend = {"name": "csv-import", "map": cmap.raw, "rows": n_rows, "duplicates_dropped": dropped,
               "command_source": ("goal columns" if all(k.goal for k in cmap.knobs.values()) else
                                  "knob position where no goal column is mapped (the servo's lag is not in the data)")}
    meta = write_imported_run(out, motor, tracker, probe, source=source, backend=backend, command=command, wall0=wall0)
    dt = np.diff(motor["t_s"])
    rate = float(1.0 / np.median(dt)) if dt.size and np.median(dt) > 0 else None
    return CsvImportResult(out, n_rows, meta["motor_rows"], int(is_frame.sum()), meta["counts"].get("aligned_rows", 0),
                           dropped, float(motor["t_s"][-1]), rate,
                           {"time": cmap.time_column or f"{cmap.sample_rate_hz:g} Hz",
                            **{d: k.position for d, k in cmap.knobs.items()}},
                           meta.get("alignment_error"))


__all__ = ["CsvImportResult", "CsvMap", "import_csv", "read_map"]
