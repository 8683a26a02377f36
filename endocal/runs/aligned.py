"""The aligned table: motor commands and measured bending angles on one clock.

Every command downstream of ``excite`` reads data through :func:`load_aligned`, which takes
a run folder or an aligned table recorded elsewhere (Parquet or CSV with the same columns):

``t_s``
    seconds, strictly increasing;
``<axis>_cmd_deg`` (or ``<axis>_cmd_mm``), ``<axis>_meas_deg``
    per bending axis: the drive command and the bending angle measured from the tracker
    (thesis eq. 1, in the base sensor's frame);
anything else numeric
    kept (knob positions, currents, ``sheath_wrap_deg``, ``contact_force_n``, ...).

The drive of a bending axis is a knob or pulley turned by a servo, commanded in degrees, or a
tendon pulled by a linear stage, commanded in millimetres (tendon-sheath benches and continuum
robots are often built so): the command column names its unit (:data:`DRIVE_UNITS`), and
:attr:`AlignedData.drive_units` carries it to the models, which record it and refuse data of
another unit. The hysteresis maths is the same in either unit; the bending angle is always deg.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from endocal.errors import RunFormatError
from endocal.kinematics.bending import bending_angles_deg, tip_in_base_mm
from endocal.probe import ProbeConfig
from endocal.runs.format import ALIGNED, MOTOR, RUN_JSON, TRACKER, read_run_json, sha256_of
from endocal.runs.textable import line_numbers, read_csv_table
from endocal.streams import DROPOUT_STATUSES

if TYPE_CHECKING:  # pandas is imported where a DataFrame is made: loading a record and fitting or validating it
    import pandas as pd  # reads its columns without it (0.15 s of every such command; bench/bench_loop.py)

#: file suffixes read as CSV text tables (delimiter sniffed: endocal.runs.textable)
CSV_SUFFIXES = (".csv", ".txt", ".tsv", ".dat")

CMD, MEAS = "_cmd_deg", "_meas_deg"
#: Units a bending axis' drive command may be in: a knob or pulley's angle, or a linear stage's tendon
#: displacement. An axis' command column is ``<axis>_cmd_<unit>``.
DRIVE_UNITS = ("deg", "mm")
CMD_SUFFIXES = tuple(f"_cmd_{u}" for u in DRIVE_UNITS)


def cmd_column(axis: str, unit: str = "deg") -> str:
    """The aligned table's command column of ``axis`` driven in ``unit`` (:data:`DRIVE_UNITS`)."""
    return f"{axis}_cmd_{unit}"


def drive_units_of(columns) -> dict[str, str]:
    """Bending axis -> the unit of its command, for every axis with a command and a measured
    angle among ``columns`` (names; a DataFrame or a mapping of columns gives its own) (an axis with two
    command columns is refused by :func:`check_aligned`)."""
    cols = [str(c) for c in columns]
    have = set(cols)
    out: dict[str, str] = {}
    for c in cols:
        for unit, suffix in zip(DRIVE_UNITS, CMD_SUFFIXES):
            axis = c[: -len(suffix)]
            if c.endswith(suffix) and axis and axis + MEAS in have:
                out.setdefault(axis, unit)
    return out


@dataclass
class Alignment:
    """The aligned table of a run and what alignment dropped."""

    table: pd.DataFrame
    tracker_frames: int
    tracker_invalid: int
    ticks_dropped: int
    max_gap_s: float
    #: invalid sensor rows by the tracker's ``status`` (hardware runs: ``missing``, ``out_of_volume``,
    #: ``partly_out_of_volume``); empty when the stream has no ``status`` column
    invalid_by_status: dict = field(default_factory=dict)

    def counts(self) -> dict[str, int]:
        return {
            "tracker_frames": self.tracker_frames,
            "tracker_invalid_dropped": self.tracker_invalid,
            **{f"tracker_{status}_dropped": n for status, n in self.invalid_by_status.items()},
            "aligned_rows": len(self.table),
            "motor_ticks_without_tracking": self.ticks_dropped,
        }


def read_parquet(source: Path | list[Path], where: str | None = None) -> pd.DataFrame:
    """Read a Parquet file (or the parts of one dataset) as a DataFrame.

    Raises
    ------
    RunFormatError
        The file is missing, not Parquet (a text file renamed ``.parquet``) or corrupt:
        the message names the file and pyarrow's reason.
    """
    with _parquet_errors(where or str(source)):
        if isinstance(source, list):
            return pq.read_table(source).to_pandas()
        # converted column by column, each Arrow column released once pandas has it (to_pandas() would hold
        # the Arrow table and a consolidated copy at once: 3x the table's size)
        return _read_columns_arrow(source).to_pandas(self_destruct=True, split_blocks=True)


def read_columns(source: Path, where: str | None = None) -> dict[str, np.ndarray]:
    """Read a Parquet file as its columns, name -> (n,) array, as :func:`read_parquet` reads them into a DataFrame
    (the same values and dtypes: a float column that has nulls holds NaN; text is an object array), without pandas.

    Raises
    ------
    RunFormatError
        As :func:`read_parquet`.
    """
    with _parquet_errors(where or str(source)):
        pf = pq.ParquetFile(source)
        return {name: _to_numpy(pf.read(columns=[name], use_threads=False).column(0)) for name in pf.schema_arrow.names}


def _read_columns_arrow(source: Path) -> pa.Table:
    """A Parquet file's table, decoded one column at a time (decoding a whole file at once holds its pages and the
    decoded table together)."""
    pf = pq.ParquetFile(source)
    schema = pf.schema_arrow
    return pa.Table.from_arrays([pf.read(columns=[name], use_threads=False).column(0) for name in schema.names],
                                schema=schema)


def _to_numpy(column: pa.ChunkedArray) -> np.ndarray:
    """An Arrow column as a writable numpy array: integers and floats without nulls straight from their buffers
    (pyarrow's own conversion loads pandas, 0.15 s), anything else through pyarrow."""
    kind = column.type
    if not (pa.types.is_integer(kind) or pa.types.is_floating(kind)) or column.null_count:
        return column.to_numpy()
    dtype = np.dtype(kind.to_pandas_dtype())
    parts = [np.frombuffer(c.buffers()[1], dtype, count=len(c), offset=c.offset * dtype.itemsize) for c in column.chunks]
    return np.concatenate(parts) if parts else np.empty(0, dtype)


@contextmanager
def _parquet_errors(where: str):
    """pyarrow's and the file system's errors on the file ``where`` names as one RunFormatError line."""
    try:
        yield
    except FileNotFoundError:
        raise RunFormatError(f"{where} does not exist") from None
    except (pa.ArrowException, OSError) as exc:
        reason = " ".join(str(exc).split())
        raise RunFormatError(
            f"{where} cannot be read as Parquet ({reason}); was it written completely, and is it a Parquet file?"
        ) from None


def read_stream(run_dir: Path, name: str) -> pd.DataFrame:
    """Read one stream folder of a run (all its parts) as a DataFrame sorted by ``t_s``.

    Raises
    ------
    RunFormatError
        The folder is missing or holds no part yet.
    """
    folder = Path(run_dir) / name
    parts = sorted(folder.glob("part-*.parquet")) if folder.is_dir() else []
    if not parts:
        raise RunFormatError(f"{run_dir}: no {name} samples were logged ({folder} is missing or empty)")
    df = read_parquet(parts if len(parts) > 1 else parts[0], where=str(folder))
    _check_stream(df, name, str(folder))
    return df.sort_values("t_s", kind="stable").reset_index(drop=True)


#: Columns every tracker stream has (a tracker may log more, e.g. its port status).
TRACKER_COLUMNS = ("t_s", "sensor", "x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz", "valid")
#: Name endings of the run format's units (:data:`endocal.runs.format.UNITS`): such a column holds numbers.
_UNIT_SUFFIXES = ("_s", "_deg", "_mm", "_dps", "_degps", "_mmps", "_ma", "_n", "_rad")


def _check_stream(df: pd.DataFrame, name: str, where: str) -> None:
    """A stream's parts have the columns its readers need, and numbers where the name says a unit.

    Raises
    ------
    RunFormatError
    """
    import pandas as pd

    need = TRACKER_COLUMNS if name == TRACKER else ("t_s",)
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise RunFormatError(f"{where}: the {name} stream lacks column(s) {', '.join(missing)}; the parts were not "
                             "written by endocal or were changed: record or import the run again")
    numeric = [c for c in df.columns if c.endswith(_UNIT_SUFFIXES) or c in TRACKER_COLUMNS[2:]]
    text = [c for c in numeric if not (pd.api.types.is_numeric_dtype(df[c]) or pd.api.types.is_bool_dtype(df[c]))]
    if text:
        raise RunFormatError(f"{where}: column(s) {', '.join(text)} of the {name} stream hold text where numbers "
                             "belong; the parts were changed or damaged: record or import the run again")


def measured_at(t_frames: np.ndarray, t: np.ndarray, max_gap_s: float) -> np.ndarray:
    """Which instants ``t`` a measurement sampled at ``t_frames`` covers (bool mask).

    An instant is covered inside the measured span and between two samples at most
    ``max_gap_s`` apart, where linear interpolation of the measurement is trusted.
    """
    ok = np.zeros(t.size, bool)
    if t_frames.size >= 2:
        idx = np.searchsorted(t_frames, t, side="right")
        inside = (idx > 0) & (idx < t_frames.size)
        lo = np.clip(idx - 1, 0, t_frames.size - 1)
        hi = np.clip(idx, 0, t_frames.size - 1)
        ok = (inside & (t_frames[hi] - t_frames[lo] <= max_gap_s)) | (t == t_frames[-1])
    return ok


def align(motor: pd.DataFrame, tracker: pd.DataFrame, probe: ProbeConfig, max_gap_s: float = 0.2) -> Alignment:
    """Put tracker-measured bending angles on the motor clock.

    Frames flagged invalid are dropped (on hardware: missing, out of the field volume or
    partly out of it, counted by the tracker stream's ``status``), as is any instant where
    the tip or base frame is missing. For each remaining frame the tip position is expressed in the base sensor's
    frame and turned into the two projected bending angles (thesis eq. 1); these are
    interpolated linearly onto the motor ticks. Motor ticks outside the tracked span, or
    inside a tracking gap longer than ``max_gap_s``, have no measurement and are dropped.

    Parameters
    ----------
    motor : DataFrame
        Motor stream (``t_s``, ``<dof>_goal_<u>``, ...).
    tracker : DataFrame
        Tracker stream (``t_s``, ``sensor``, ``x_mm``.., ``qw``.., ``valid``).
    probe : ProbeConfig
        Gives the bending axis names (first: y-z plane, second: x-z plane).
    max_gap_s : float
        Longest tracking gap to interpolate across, seconds.
    """
    import pandas as pd

    missing = [s for s in ("tip", "base") if s not in set(tracker["sensor"].astype(str))]
    if missing:
        raise RunFormatError(f"tracker stream has no '{missing[0]}' sensor frames: eq. 1 needs both tip and base sensors")
    valid = tracker["valid"].astype(bool).to_numpy()
    n_invalid = int((~valid).sum())
    by_status = {}
    if "status" in tracker.columns:
        status = tracker["status"].astype(str).to_numpy()
        by_status = {s: int(((status == s) & ~valid).sum()) for s in DROPOUT_STATUSES}
    good = tracker.loc[valid]
    cols = ["t_s", "x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz"]
    tip = good.loc[good["sensor"].astype(str) == "tip", cols]
    base = good.loc[good["sensor"].astype(str) == "base", cols]
    pairs = tip.merge(base, on="t_s", suffixes=("_tip", "_base")).sort_values("t_s")
    n_frames = int((tracker["sensor"].astype(str) == "tip").sum())
    xyz = ["x_mm", "y_mm", "z_mm"]
    p = tip_in_base_mm(
        pairs[[c + "_tip" for c in xyz]].to_numpy(),
        pairs[[c + "_base" for c in xyz]].to_numpy(),
        pairs[["qw_base", "qx_base", "qy_base", "qz_base"]].to_numpy(),
    )
    theta_first, theta_second = bending_angles_deg(p)  # thesis eq. 1
    t_frames = pairs["t_s"].to_numpy(float)

    t = motor["t_s"].to_numpy(float)
    ok = measured_at(t_frames, t, max_gap_s)
    out = {"t_s": t[ok]}
    first, second = probe.bending_axes
    goals = []
    for axis, theta in ((first, theta_first), (second, theta_second)):
        # a knob's goal in deg, or a linear stage's in mm (a lab's CSV log: endocal.runs.csvlog)
        unit = next((u for u in DRIVE_UNITS if f"{axis}_goal_{u}" in motor.columns), "deg")
        goals.append(f"{axis}_goal_{unit}")
        out[cmd_column(axis, unit)] = motor[goals[-1]].to_numpy(float)[ok]
        out[axis + MEAS] = np.interp(t[ok], t_frames, theta) if t_frames.size else np.empty(0)
    for col in motor.columns:
        if col == "t_s" or col in goals:
            continue
        if pd.api.types.is_numeric_dtype(motor[col]) and not pd.api.types.is_bool_dtype(motor[col]):
            out[col] = motor[col].to_numpy(float)[ok]
    return Alignment(pd.DataFrame(out), n_frames, n_invalid, int((~ok).sum()), max_gap_s, by_status)


def columns_of(table) -> dict:
    """A table's columns, name -> (n,) array: a mapping of them as it is, a DataFrame's column by column."""
    if isinstance(table, Mapping):
        return dict(table)
    return {c: table[c].to_numpy() for c in table.columns}


def is_number_array(values: np.ndarray, *, bool_ok: bool = True) -> bool:
    """Whether a column holds numbers (integers, floats; booleans unless ``bool_ok`` is False), as its dtype says."""
    return np.asarray(values).dtype.kind in ("biufc" if bool_ok else "iufc")


@dataclass
class AlignedData:
    """An aligned table, checked, with where it came from.

    Attributes
    ----------
    columns : dict of str to array
        ``t_s``, ``<axis>_cmd_deg`` (or ``_cmd_mm``), ``<axis>_meas_deg`` per axis, and numeric extras, one
        (n,) array each. A DataFrame given here is read column by column (:func:`columns_of`).
    axes : list of str
        Bending axes present (those with both a command and a measurement column).
    source : Path
        The run folder or table file.
    sha256 : str
        Hash of the source (the table file, or the run's streams and run.json).
    meta : dict
        ``run.json`` for a run folder, empty for a bare table.
    drive_units : dict of str to str
        Axis -> the unit of its command (:data:`DRIVE_UNITS`); an axis missing is in the unit its
        command column names.
    """

    columns: dict
    axes: list[str]
    source: Path
    sha256: str
    meta: dict = field(default_factory=dict)
    drive_units: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.columns, Mapping):  # a DataFrame: the table view is the one given
            self.__dict__["table"] = self.columns
            self.columns = columns_of(self.columns)

    @cached_property
    def table(self) -> pd.DataFrame:
        """The columns as a DataFrame (made on first use: the commands that fit and validate never need one)."""
        import pandas as pd

        return pd.DataFrame(self.columns)

    @property
    def n_rows(self) -> int:
        """Samples (rows) of the table."""
        return len(self.columns["t_s"])

    def column(self, name: str) -> np.ndarray:
        """The column ``name`` as floats."""
        return np.asarray(self.columns[name], float)

    @property
    def extras(self) -> list[str]:
        """Numeric columns beyond time, commands and measurements."""
        core = {"t_s"} | {self.cmd_column(a) for a in self.axes} | {a + MEAS for a in self.axes}
        return [c for c in self.columns if c not in core]

    def drive_unit(self, axis: str) -> str:
        """The unit of ``axis``' command: ``deg`` (a knob) or ``mm`` (a linear stage pulling the tendon), as
        ``drive_units`` says, else as the table's command column names it."""
        axis = self._axis(axis)
        if axis in self.drive_units:
            return self.drive_units[axis]
        return next((u for u in DRIVE_UNITS if cmd_column(axis, u) in self.columns), "deg")

    def cmd_column(self, axis: str) -> str:
        """The command column of ``axis`` (``ap_cmd_deg``, ``ap_cmd_mm``)."""
        return cmd_column(axis, self.drive_unit(axis))

    def cmd(self, axis: str) -> np.ndarray:
        """The command of ``axis`` in its drive unit (:meth:`drive_unit`)."""
        return self.column(self.cmd_column(axis))

    def cmd_deg(self, axis: str) -> np.ndarray:
        """The command of a knob-driven ``axis`` in deg (an axis driven in mm is refused: :meth:`cmd`)."""
        if self.drive_unit(axis) != "deg":
            raise RunFormatError(f"{self.source}: the {axis} drive is commanded in {self.drive_unit(axis)}, not deg: "
                                 "read it with cmd(axis), in its own unit")
        return self.cmd(axis)

    def meas_deg(self, axis: str) -> np.ndarray:
        return self.column(self._axis(axis) + MEAS)

    @property
    def t_s(self) -> np.ndarray:
        return self.column("t_s")

    def _axis(self, axis: str) -> str:
        if axis not in self.axes:
            raise RunFormatError(f"{self.source}: no axis '{axis}' in the data (it has {', '.join(self.axes)})")
        return axis


def _read_table(path: Path) -> dict | pd.DataFrame:
    """An aligned table file's columns (Parquet), or the DataFrame its CSV text reads as."""
    suffix = path.suffix.lower()
    if suffix == ".parquet":
        return read_columns(path)
    if suffix not in CSV_SUFFIXES:
        raise RunFormatError(f"{path}: expected a run folder, a .parquet or a .csv aligned table (.txt, .tsv and .dat "
                             "read as CSV)")
    import pandas as pd

    try:
        return read_csv_table(path.read_bytes())
    except FileNotFoundError:
        raise RunFormatError(f"{path} does not exist") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, OSError) as exc:
        raise RunFormatError(f"{path} cannot be read as {suffix[1:].upper()}: {str(exc).splitlines()[0]}") from None


def _csv_line(path: Path, df: pd.DataFrame) -> Callable[[int], str]:
    """``row_name`` of a CSV table: the file's line of row ``i`` (read again only for a message)."""
    return lambda i: f"line {line_numbers(path.read_bytes(), i + 1, df.attrs.get('headerless', False))[i]}"


def check_aligned(table, where: str, row_name: Callable[[int], str] | None = None) -> list[str]:
    """Check an aligned table (a DataFrame, or its columns: :func:`columns_of`) and return its bending axes.

    Raises
    ------
    RunFormatError
        No ``t_s``, no axis with both command and measurement, an axis with a command in two
        units, non-numeric, NaN or infinite values in time/commands/measurements, or time that
        does not increase. ``row_name(i)`` names row ``i`` in those messages (default ``row i``; a CSV
        file's ``line N``, as an editor numbers it).
    """
    headerless = bool(getattr(table, "attrs", {}).get("headerless"))  # a CSV read without a header line
    df = columns_of(table)
    row_name = row_name or (lambda i: f"row {i}")
    if "t_s" not in df:
        if headerless:
            raise RunFormatError(f"{where}: no header line (the first line is numbers): an aligned table names its "
                                 "columns t_s, <axis>_cmd_deg, <axis>_meas_deg; add that line, or map the numbered "
                                 "columns (\"1\", \"2\", ...) with `endocal import csv --map`")
        raise RunFormatError(f"{where}: no 't_s' column (an aligned table needs t_s, <axis>_cmd_deg, <axis>_meas_deg; "
                             "a log with its own column names goes through `endocal import csv LOG --map MAP`)")
    units = drive_units_of(df)
    axes = list(units)
    if not axes:
        lonely = [c for c in df if str(c).endswith((*CMD_SUFFIXES, MEAS))]
        hint = f" (found only {', '.join(lonely)})" if lonely else ""
        raise RunFormatError(
            f"{where}: no bending axis with both '<axis>_cmd_deg' (or '<axis>_cmd_mm', a linear drive) and "
            f"'<axis>_meas_deg' columns{hint}"
        )
    twice = next((a for a in axes if all(cmd_column(a, u) in df for u in DRIVE_UNITS)), None)
    if twice is not None:
        raise RunFormatError(f"{where}: axis '{twice}' has a command in deg and one in mm "
                             f"({', '.join(cmd_column(twice, u) for u in DRIVE_UNITS)}): keep the one its drive "
                             "was commanded in")
    if len(df["t_s"]) == 0:
        raise RunFormatError(f"{where}: the table has no rows")
    for col in ["t_s"] + [c for a in axes for c in (cmd_column(a, units[a]), a + MEAS)]:
        if not is_number_array(df[col]):
            raise RunFormatError(f"{where}: column '{col}' is not numeric")
        values = np.asarray(df[col], float)
        bad = ~np.isfinite(values)
        if bad.any():
            i = int(np.argmax(bad))
            kind = "NaN" if np.isnan(values[i]) else "infinite"
            fix = (f"drop such rows (a tracker dropout), or import the table (`endocal import csv {where} --draft-map "
                   "map.toml`), which interpolates the angle across short dropouts and counts them"
                   if col.endswith(MEAS) and where.lower().endswith(CSV_SUFFIXES) else "drop or fill such rows first")
            raise RunFormatError(f"{where}: column '{col}' is {kind} at {row_name(i)}; {fix}")
    t = np.asarray(df["t_s"], float)
    steps = np.diff(t)
    if (steps <= 0).any():
        i = int(np.argmax(steps <= 0)) + 1
        raise RunFormatError(
            f"{where}: time must increase, but t_s goes from {t[i - 1]:g} to {t[i]:g} at {row_name(i)}; sort the table or fix "
            "its clock"
        )
    return axes


def load_aligned(path: str | Path, max_gap_s: float = 0.2) -> AlignedData:
    """Load and check the aligned table of a run folder or of a Parquet/CSV file.

    A run folder whose ``aligned.parquet`` is missing (the run was killed) has its table
    rebuilt from the logged streams.

    Raises
    ------
    RunFormatError
        Missing path, unreadable file, or a table that breaks the format (see
        :func:`check_aligned`).
    """
    path = Path(path)
    if path.is_dir():
        meta = read_run_json(path)
        if (path / ALIGNED).is_file():
            df = read_columns(path / ALIGNED)
            digest = sha256_of(path / ALIGNED)
        else:
            probe = ProbeConfig.from_dict(meta.get("probe"), where=str(path / RUN_JSON))
            motor = read_stream(path, MOTOR)
            try:
                df = align(motor, read_stream(path, TRACKER), probe, max_gap_s).table
            except KeyError as exc:
                raise RunFormatError(f"{path / MOTOR}: the motor stream lacks column {exc.args[0]!r} for the probe "
                                     f"'{probe.name}' its run.json names; record or import the run again") from None
            digest = sha256_of(path)
        axes = check_aligned(df, str(path))
        units = drive_units_of(df)
        recorded = meta.get("drive_units") or {}
        wrong = next((a for a in axes if a in recorded and recorded[a] != units[a]), None)
        if wrong is not None:
            raise RunFormatError(f"{path / RUN_JSON} records the {wrong} drive in {recorded[wrong]}, but its aligned "
                                 f"table commands it in {units[wrong]} ({cmd_column(wrong, units[wrong])}): the run "
                                 "was edited by hand; record or import it again")
        return AlignedData(df, axes, path, digest, meta, units)
    if not path.exists():
        raise RunFormatError(f"{path} does not exist: give a run folder or an aligned table (.parquet or .csv)")
    df = _read_table(path)
    axes = check_aligned(df, str(path), _csv_line(path, df) if path.suffix.lower() in CSV_SUFFIXES else None)
    return AlignedData(df, axes, path, sha256_of(path), {}, drive_units_of(df))
