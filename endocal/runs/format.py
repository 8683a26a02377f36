"""The run format: one folder per excitation run.

::

    RUN/
      run.json          what was run: protocol + parameters, probe, backend, seed, versions,
                        start/end time (UTC), units, each bending axis' drive unit, status,
                        row counts
      motor/            motor stream, a Parquet dataset (part-NNNNNN.parquet, one per flush)
      tracker/          EM-tracker stream, a Parquet dataset (long format, one row per sensor frame)
      truth/            simulator ground truth (simulator runs only)
      aligned.parquet   one row per motor tick: t_s, <axis>_cmd_deg, <axis>_meas_deg, + numeric extras

A bending axis is driven by a knob (its command and motor columns in deg: ``ap_goal_deg``,
``ap_cmd_deg``) or, in a lab's imported log, by a linear stage pulling its tendon (in mm:
``ap_goal_mm``, ``ap_cmd_mm``); ``run.json``'s ``drive_units`` records which
(:mod:`endocal.runs.aligned`).

The streams are folders of Parquet parts so that a crash (``kill -9``) loses at most the
part being buffered: each part is written to a hidden temporary name and renamed into
place, and both ``pyarrow.dataset.dataset(RUN/"motor")`` and ``pandas.read_parquet`` read
the folder as one table (they skip hidden files). ``run.json`` is rewritten atomically.
``status`` is ``running`` while logging, then ``complete``, ``interrupted`` (Ctrl-C) or
``failed``; a run left ``running`` was killed, and readers rebuild its aligned table from
the streams.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import platform
import secrets
import shutil
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from endocal import __version__
from endocal.errors import OutputExistsError, OutputPathError, RunFormatError
from endocal.files import atomic_write_bytes

FORMAT_NAME = "endocal-run"
FORMAT_VERSION = 1
#: Sample rates a knob log can have, Hz. The slowest device of these rigs, the EM tracker,
#: reports at 40 Hz and servo loops run at 100-1000 Hz: a record under 1 Hz follows no
#: hysteresis loop, and is what a clock in ms read as s makes of 100 Hz (0.1 Hz). 10 kHz is ten
#: times the fastest servo loop (a 1 kHz Dynamixel sync read) and a tenth of what a clock in ms
#: read as us makes of 100 Hz (100 kHz). Import refuses a rate outside it, its map draft reads a
#: clock's unit by it, fit and validate question a record below it.
LOG_RATE_RANGE_HZ = (1.0, 10_000.0)
RUN_JSON = "run.json"
MOTOR = "motor"
TRACKER = "tracker"
TRUTH = "truth"
ALIGNED = "aligned.parquet"
STREAMS = (MOTOR, TRACKER, TRUTH)

UNITS = {
    "t_s": "seconds, monotonic from run start (motor clock)",
    "*_deg": "degrees (knob angles, probe rotation, bending angles)",
    "*_mm": "millimetres (positions, insertion, a linear stage's tendon displacement)",
    "*_dps": "degrees per second",
    "*_mmps": "millimetres per second",
    "*_ma": "milliamperes",
    "*_n": "newtons",
    "qw qx qy qz": "unit quaternion, sensor to tracker rotation, scalar first",
}


def sample_rate_hz(*t_s) -> float | None:
    """The rate of the clock records were sampled on, Hz: one over the median spacing of their times.

    Every command that states a record's rate states this one (``import`` records it in
    ``run.json``, ``info`` prints it, ``fit`` prints it for the records it fitted), so one log
    has one rate. The median, not rows over span: a log that dropped rows, or a table whose
    glitches were left out, was still sampled on its clock's period, and a logger's jitter
    (a period of 1.9996 ms or 2.0004 ms) moves the median by that much only.

    Parameters
    ----------
    *t_s : (n,) arrays
        Times of each record (s); the spacings of all of them are pooled.

    Returns
    -------
    float or None
        None when no record holds two samples at different times.
    """
    steps = [np.diff(np.asarray(t, dtype=float)) for t in t_s]
    steps = np.concatenate(steps) if steps else np.zeros(0)
    steps = steps[np.isfinite(steps) & (steps > 0)]
    return float(1.0 / np.median(steps)) if steps.size else None


def utc_now() -> str:
    """Current time as an ISO 8601 UTC string with a ``Z`` suffix."""
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def software_versions() -> dict[str, str]:
    """Versions of endocal and of the libraries that shape its numbers, for provenance."""
    import pandas
    import pyarrow
    import scipy

    return {
        "endocal": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "pandas": pandas.__version__,
        "pyarrow": pyarrow.__version__,
    }


def sha256_of(path: Path) -> str:
    """Hex SHA-256 of a file's bytes, or of every file of a folder (sorted by relative path)."""
    h = hashlib.sha256()
    path = Path(path)
    files = sorted(p for p in path.rglob("*") if p.is_file() and not p.name.startswith(".")) if path.is_dir() else [path]
    for f in files:
        if path.is_dir():
            h.update(str(f.relative_to(path)).encode())
        with open(f, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


def parquet_bytes(df, metadata: dict | None = None) -> bytes:
    """A table as the bytes of a Parquet file (for :func:`atomic_write_bytes`), with ``metadata``
    (JSON) under the schema key ``endocal`` when given."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.Table.from_pandas(df, preserve_index=False)
    if metadata is not None:
        table = table.replace_schema_metadata({**(table.schema.metadata or {}),
                                               b"endocal": json.dumps(metadata, default=_json_default).encode()})
    buf = io.BytesIO()
    pq.write_table(table, buf)
    return buf.getvalue()


def _json_default(obj):
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def write_json(path: Path, obj: dict) -> None:
    """Atomically write ``obj`` as indented JSON."""
    atomic_write_bytes(path, (json.dumps(obj, indent=2, default=_json_default) + "\n").encode())


def read_run_json(run_dir: Path) -> dict:
    """Read and check ``RUN/run.json``.

    Raises
    ------
    RunFormatError
        Missing, not JSON, not an endocal run, or from a newer format version.
    """
    path = Path(run_dir) / RUN_JSON
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise RunFormatError(f"{run_dir} is not a run folder: it has no {RUN_JSON}") from None
    except UnicodeDecodeError as exc:
        raise RunFormatError(f"{path} is not a text file (byte {exc.start} is no UTF-8): record or import the run "
                             "again") from None
    except json.JSONDecodeError as exc:
        raise RunFormatError(f"{path} is not valid JSON (line {exc.lineno}): {exc.msg}") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        meta = meta if isinstance(meta, dict) else {}
        raise RunFormatError(f"{path} is not an endocal run file (format is {meta.get('format')!r}, expected {FORMAT_NAME!r})")
    version = meta.get("version")
    if version is None:
        raise RunFormatError(f"{path} records no run format version, which every run endocal writes has: the file was "
                             "edited or not written by endocal; record or import the run again")
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise RunFormatError(
            f"{path} has run format version {version!r}; this endocal reads up to {FORMAT_VERSION}: upgrade endocal"
        )
    wrong = [k for k in _RUN_JSON_OBJECTS if k in meta and not isinstance(meta[k], dict)]
    if wrong:
        raise RunFormatError(f"{path}: field(s) {', '.join(wrong)} must be objects; the file was edited or damaged: "
                             "restore it, or record or import the run again")
    return meta


#: Fields of run.json that are JSON objects when present.
_RUN_JSON_OBJECTS = ("protocol", "probe", "backend", "software", "units", "streams", "counts", "drive_units")


def _is_run_folder(path: Path) -> bool:
    """True when ``path`` holds a ``run.json`` of the endocal run format."""
    try:
        return json.loads((path / RUN_JSON).read_text()).get("format") == FORMAT_NAME
    except (OSError, ValueError, AttributeError):
        return False


def prepare_output(out: Path, force: bool) -> None:
    """Check that ``out`` can become a new run folder (without creating it).

    Raises
    ------
    OutputExistsError
        ``out`` exists and ``force`` is false.
    OutputPathError
        ``out`` exists as a file, or its parent cannot be created or written.
    """
    out = Path(out)
    if out.exists():
        if not force:
            raise OutputExistsError(f"output {out} already exists: choose a new --out or pass --force to replace it")
        if not out.is_dir():
            raise OutputPathError(f"output {out} exists and is not a folder: choose another --out")
        if any(out.iterdir()) and not _is_run_folder(out):
            # --force replaces runs, never an arbitrary folder (think `--out . --force`).
            raise OutputPathError(f"output {out} is a non-empty folder that is not an endocal run: --force only replaces runs")
    check_parent(out)


def check_parent(out: Path) -> None:
    """Check that ``out`` (a folder or a file) can be created: its nearest existing ancestor is a
    writable folder.

    Raises
    ------
    OutputPathError
    """
    out = Path(out)
    probe_dir = out.parent if str(out.parent) else Path(".")
    while not probe_dir.exists():
        probe_dir = probe_dir.parent
    if not probe_dir.is_dir():
        raise OutputPathError(f"cannot create {out}: {probe_dir} is not a folder")
    if not os.access(probe_dir, os.W_OK | os.X_OK):
        raise OutputPathError(f"cannot create {out}: {probe_dir} is not writable")


def run_meta(*, protocol: dict, probe, backend: dict, seed, realtime: bool, command: str | None,
             sample_rate_hz, planned_duration_s: float, drive_units: dict[str, str] | None = None) -> dict:
    """The ``run.json`` of a run about to be logged (``status: running``; the logger completes it).

    ``drive_units`` maps each bending axis to the unit its drive is commanded in (``deg`` for a
    knob, ``mm`` for a linear stage; default deg for every axis).
    """
    return {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "status": "running",
        "protocol": protocol,
        "probe": probe.to_dict(),
        "backend": backend,
        "seed": seed,
        "realtime": bool(realtime),
        "software": software_versions(),
        "command": command or " ".join(sys.argv),
        "sample_rate_hz": sample_rate_hz,
        "planned_duration_s": planned_duration_s,
        "units": UNITS,
        "drive_units": {a: (drive_units or {}).get(a, "deg") for a in probe.bending_axes},
        "streams": {"motor": MOTOR + "/", "tracker": TRACKER + "/", "aligned": ALIGNED},
    }


def write_folder_staged(out: Path, write):
    """Have ``write(stage)`` fill a hidden folder beside ``out``, then rename it to ``out``; on any
    failure (an error, Ctrl-C) the stage is removed and ``out`` is as it was. Returns what
    ``write`` returns.

    A folder written in place and stopped halfway would be left with ``run.json`` ``running``,
    which readers take for a killed recording and which blocks the next import. An existing
    ``out`` (a run :func:`prepare_output` allowed to replace) is moved aside first and removed
    only once the new one is in place.
    """
    out = Path(out)
    token = secrets.token_hex(4)
    stage = out.parent / f".{out.name}.writing-{token}"
    aside = out.parent / f".{out.name}.replaced-{token}"
    try:
        result = write(stage)
        try:
            if out.exists():
                os.replace(out, aside)
            try:
                os.replace(stage, out)
            except OSError:
                if aside.exists():
                    os.replace(aside, out)
                raise
        except OSError as exc:
            raise OutputPathError(f"cannot create {out}: {exc.strerror or exc}") from None
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    shutil.rmtree(aside, ignore_errors=True)
    return result


def create_run_folder(out: Path) -> None:
    """Create ``out`` empty (replacing a run :func:`prepare_output` allowed to replace)."""
    try:
        if out.exists():
            shutil.rmtree(out)
        out.mkdir(parents=True)
    except OSError as exc:
        raise OutputPathError(f"cannot create {out}: {exc.strerror}") from None
