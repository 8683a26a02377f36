"""A fleet's check history: one Parquet dataset, hive-partitioned ``probe=ID/month=YYYY-MM``.

::

    DIR/
      probe=TEE-0042/
        month=2026-11/
          checks.parquet          one row per check of that probe in that month (UTC)
          _runs/CHECK_ID/         the check's run folder, kept beside its row
        _checks.parquet           every row of the probe in one file: a copy the readers here use
      probe=TEE-0043/...

Any engine reads it as one dataset (``pyarrow.dataset.dataset(DIR, partitioning="hive")``,
``duckdb``'s ``read_parquet('DIR/*/*/*.parquet', hive_partitioning = true)``, Spark); the
partition columns ``probe`` and ``month`` come from the paths and are not stored in the files.
Folders starting with ``_`` and hidden files are skipped by those readers, so run folders and
temporary files never enter the table.

One file per probe and month keeps a fleet's two years of daily checks at some 2,400 files, not
70,000. Opening 2,400 files is still most of a query's time (DuckDB: seconds), so each probe
also keeps its rows in one file, ``_checks.parquet`` (with a ``month`` column), rewritten with
every append; it records the size and modification time of every month file it copies, and a
reader uses it only while they all match, else it reads that probe's month files (a month file
restored or edited by hand is never shadowed by a stale copy). Other engines skip it (``_``). An append rewrites that month's file (at most 31 rows) to a hidden temporary name and
renames it into place, under a lock on the folder: a reader sees the old file or the new one,
and a crash leaves no half-written row. The run folder is moved into ``_runs`` before the row
is written; if the row cannot be written, it is removed again.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from endocal.errors import OutputPathError, RunFormatError

ROWS_FILE = "checks.parquet"
RUNS = "_runs"
#: A probe's rows in one file, kept in step with its month files (see the module docstring).
PROBE_FILE = "_checks.parquet"
#: Key of the copy's Parquet metadata that lists the month files it copies (``_manifest``).
MANIFEST_KEY = "endocal_history_manifest"
LOCK = ".lock"
_PROBE_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")
_MONTH_RE = re.compile(r"^\d{4}-(0[1-9]|1[0-2])$")


class HistoryError(RunFormatError):
    """A history folder that is not one (foreign files), or a row that cannot be read."""


def check_probe_id(probe_id: str) -> str:
    """Refuse a probe ID that cannot be a partition value (``/``, ``=``, spaces, a leading dot).

    Raises
    ------
    HistoryError
    """
    if not isinstance(probe_id, str) or not _PROBE_RE.match(probe_id):
        raise HistoryError(f"probe ID {probe_id!r}: use letters, digits, '.', '_' and '-' (up to 100, starting with "
                           "a letter or digit), e.g. TEE-0042")
    return probe_id


@dataclass
class HistoryRead:
    """What a history folder holds.

    Attributes
    ----------
    rows : pandas.DataFrame
        Every readable row, with ``probe`` and ``month`` from the paths, sorted by probe then time.
    corrupt : list of (Path, str)
        Month files that could not be read, with why (their rows are missing from ``rows``).
    files : list of Path
        The readable month files.
    """

    rows: object
    corrupt: list = field(default_factory=list)
    files: list = field(default_factory=list)

    def corrupt_line(self) -> str | None:
        """One line naming the unreadable month file(s), or None."""
        return corrupt_line(self.corrupt)


def corrupt_line(corrupt: list) -> str | None:
    """One line naming unreadable month files (``[(path, why)]``), or None when there are none."""
    if not corrupt:
        return None
    path, why = corrupt[0]
    more = f" (and {len(corrupt) - 1} more)" if len(corrupt) > 1 else ""
    return (f"{path} is not a readable Parquet file ({why}){more}: its checks are left out; restore it from a "
            "backup or move it out of the history folder")


class HistoryFolder:
    """A history folder (see the module docstring): validated, read and appended to."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)

    # ------------------------------------------------------------------ layout
    def partition(self, probe_id: str, month: str) -> Path:
        return self.root / f"probe={probe_id}" / f"month={month}"

    def validate(self) -> list[Path]:
        """The month files of the history, refusing anything that does not belong in it.

        A missing folder is an empty history. Hidden files (a lock, an interrupted write's
        temporary file) are allowed; run folders are not looked into.

        Raises
        ------
        HistoryError
            A foreign file or folder: named, with what to do.
        """
        if not self.root.exists():
            return []
        if not self.root.is_dir():
            raise HistoryError(f"history {self.root} is a file, not a folder: give the history folder of endocal check")
        files = []

        def foreign(p: Path, expected: str):
            raise HistoryError(f"history {self.root} holds {p}, which is not part of a check history (expected "
                               f"{expected}): give a folder only endocal check writes to, or move that out")

        def entries(folder):  # os.scandir: the entries' types come with the listing, no stat per entry
            with os.scandir(folder) as it:
                return sorted(it, key=lambda e: e.name)

        for p in entries(self.root):
            if p.name.startswith("."):
                continue
            name = p.name.removeprefix("probe=")
            if not (p.is_dir() and p.name.startswith("probe=") and _PROBE_RE.match(name)):
                foreign(Path(p.path), "probe=ID folders")
            for q in entries(p.path):
                if q.name.startswith(".") or (q.name == PROBE_FILE and q.is_file()):
                    continue
                if not (q.is_dir() and q.name.startswith("month=") and _MONTH_RE.match(q.name.removeprefix("month="))):
                    foreign(Path(q.path), f"month=YYYY-MM folders and {PROBE_FILE}")
                for r in entries(q.path):
                    if r.name.startswith("."):
                        continue
                    if r.name == ROWS_FILE and r.is_file():
                        files.append(Path(r.path))
                    elif r.name == RUNS and r.is_dir():
                        continue
                    else:
                        foreign(Path(r.path), f"{ROWS_FILE} and {RUNS}/")
        return files

    # ------------------------------------------------------------------ reading
    def read(self, probe_id: str | None = None) -> HistoryRead:
        """Every row (or one probe's), skipping unreadable month files (named in ``corrupt``).

        Raises
        ------
        HistoryError
            Foreign files (:meth:`validate`).
        """
        import pandas as pd
        import pyarrow.parquet as pq

        files = self.validate()
        if probe_id is not None:
            files = [f for f in files if f.parent.parent.name == f"probe={probe_id}"]
        frames, corrupt, good = [], [], []
        for probe_dir, (copy, months) in self.sources(files).items():
            if copy is not None:
                df = pq.read_table(copy).to_pandas()
                df.insert(0, "probe", probe_dir.name.removeprefix("probe="))
                frames.append(df)
                good.extend(months)
                continue
            for f in months:
                try:
                    df = pq.read_table(f).to_pandas()
                except Exception as exc:  # noqa: BLE001  any unreadable file is named, the rest still read
                    corrupt.append((f, _first_line(exc)))
                    continue
                df.insert(0, "month", f.parent.name.removeprefix("month="))
                df.insert(0, "probe", probe_dir.name.removeprefix("probe="))
                frames.append(df)
                good.append(f)
        rows = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=["probe", "month", "checked_utc"])
        if len(rows):
            rows = rows.sort_values(["probe", "checked_utc"], kind="stable", ignore_index=True)
        return HistoryRead(rows, corrupt, good)

    def sources(self, files: list[Path], manifests=None) -> dict[Path, tuple[Path | None, list[Path]]]:
        """Per probe folder: its one-file copy when it matches every month file (else None), and its month files.

        Parameters
        ----------
        files : list of Path
            Month files (:meth:`validate`).
        manifests : callable, optional
            ``manifests(copies) -> {copy: manifest JSON text or None}``; default: read with pyarrow.
        """
        by_probe: dict[Path, list[Path]] = {}
        for f in files:
            by_probe.setdefault(f.parent.parent, []).append(f)
        copies = [d / PROBE_FILE for d in by_probe if (d / PROBE_FILE).is_file()]
        recorded = (manifests or _manifests_pyarrow)(copies) if copies else {}
        out = {}
        for probe_dir, months in by_probe.items():
            copy = probe_dir / PROBE_FILE
            text = recorded.get(copy)
            try:
                fresh = text is not None and json.loads(text) == _manifest(months)
            except ValueError:
                fresh = False
            out[probe_dir] = (copy if fresh else None, months)
        return out

    def refresh_probe_file(self, probe_dir: Path) -> None:
        """Rewrite a probe's one-file copy from its month files (under the lock; best effort: a copy that
        cannot be written is removed, and readers use the month files)."""
        import pandas as pd
        import pyarrow as pa
        import pyarrow.parquet as pq

        from endocal.runs.format import atomic_write_bytes

        copy = probe_dir / PROBE_FILE
        try:
            months = sorted(probe_dir.glob(f"month=*/{ROWS_FILE}"))
            frames = []
            for f in months:
                df = pq.read_table(f).to_pandas()
                df.insert(0, "month", f.parent.name.removeprefix("month="))
                frames.append(df)
            table = pa.Table.from_pandas(pd.concat(frames, ignore_index=True), preserve_index=False)
            table = table.replace_schema_metadata({**(table.schema.metadata or {}),
                                                   MANIFEST_KEY.encode(): json.dumps(_manifest(months)).encode()})
            sink = pa.BufferOutputStream()
            pq.write_table(table, sink)
            atomic_write_bytes(copy, sink.getvalue().to_pybytes())
        except Exception:  # noqa: BLE001  a stale copy must not stay: readers fall back to the month files
            copy.unlink(missing_ok=True)

    # ------------------------------------------------------------------ writing
    @contextlib.contextmanager
    def locked(self):
        """Hold the history's lock (one writer at a time; readers never wait)."""
        import fcntl

        try:
            self.root.mkdir(parents=True, exist_ok=True)
            fh = open(self.root / LOCK, "a")
        except OSError as exc:
            raise OutputPathError(f"cannot write the history {self.root}: {exc.strerror}") from None
        with fh:
            fcntl.flock(fh, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(fh, fcntl.LOCK_UN)

    def append(self, row: dict, run_dir: Path | None = None, *, move_run: bool = True) -> Path:
        """Append one check's row, with its run folder kept beside it (call under :meth:`locked`).

        Parameters
        ----------
        row : dict
            ``probe`` (the probe ID), ``month`` (``YYYY-MM``), ``check_id`` and the stored columns.
        run_dir : Path, optional
            The check's run folder: moved (or copied, ``move_run=False``) to ``_runs/CHECK_ID``.

        Returns
        -------
        Path
            The month file written.

        Raises
        ------
        HistoryError
            The month's file exists and cannot be read (nothing is written: it would be lost).
        OutputPathError
        """
        import pandas as pd
        import pyarrow.parquet as pq

        from endocal.runs.format import parquet_bytes, atomic_write_bytes

        row = dict(row)
        part = self.partition(check_probe_id(row.pop("probe")), row.pop("month"))
        target = part / ROWS_FILE
        old = None
        if target.exists():
            try:
                old = pq.read_table(target).to_pandas()
            except Exception as exc:  # noqa: BLE001
                raise HistoryError(f"{target} is not a readable Parquet file ({_first_line(exc)}): no row appended; "
                                   "restore it from a backup or move it out of the history folder") from None
        new = pd.DataFrame([row])
        table = new if old is None else pd.concat([old, new], ignore_index=True)
        placed = None
        try:
            if run_dir is not None:
                placed = part / RUNS / row["check_id"]
                placed.parent.mkdir(parents=True, exist_ok=True)
                tmp = placed.parent / f".{row['check_id']}.tmp"
                if move_run:
                    shutil.move(str(run_dir), tmp)
                else:
                    shutil.copytree(run_dir, tmp)
                os.replace(tmp, placed)
            atomic_write_bytes(target, parquet_bytes(table))
        except BaseException as exc:
            if placed is not None and placed.exists():
                if move_run:
                    shutil.move(str(placed), run_dir)
                else:
                    shutil.rmtree(placed, ignore_errors=True)
            if isinstance(exc, OSError) and not isinstance(exc, OutputPathError):
                raise OutputPathError(f"cannot write the history {self.root}: {exc.strerror or exc}") from None
            raise
        self.refresh_probe_file(part.parent)
        return target


def _manifests_pyarrow(copies: list[Path]) -> dict:
    """``{copy: manifest text}`` read from each copy's Parquet footer (None where unreadable)."""
    import pyarrow.parquet as pq

    out = {}
    for c in copies:
        try:
            out[c] = ((pq.read_schema(c).metadata or {}).get(MANIFEST_KEY.encode()) or b"").decode() or None
        except Exception:  # noqa: BLE001  an unreadable copy is not used; the month files are
            out[c] = None
    return out


def _manifest(months: list[Path]) -> dict:
    """``{"month=YYYY-MM": [size, mtime_ns]}`` of a probe's month files: what its one-file copy was made from."""
    out = {}
    for f in months:
        st = f.stat()
        out[f.parent.name] = [st.st_size, st.st_mtime_ns]
    return dict(sorted(out.items()))


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def models_json(models: dict) -> str:
    """How a row records its models: ``{axis: {"path", "sha256"}}`` as JSON."""
    return json.dumps(models, sort_keys=True)
