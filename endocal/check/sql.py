"""SQL over a fleet's history with DuckDB (embedded, no server), read-only.

The whole dataset is the view ``checks`` (every stored column, plus ``probe`` and ``month``
from the partition paths), so a fleet's questions are one query::

    SELECT probe, max(ap_dead_band_deg) / min(ap_dead_band_deg) - 1 AS growth
    FROM checks WHERE checked_utc >= '2026-10-29' GROUP BY probe HAVING growth > 0.2

Only a single ``SELECT`` (or ``WITH ... SELECT``) statement runs; anything that could write
(``COPY``, ``INSERT``, ``CREATE``, ``ATTACH``, ``EXPORT``, ``SET`` ...) is refused before DuckDB
executes it, so the history is never changed by a query.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from endocal.check.extras import require
from endocal.check.store import MANIFEST_KEY, HistoryError, HistoryFolder, corrupt_line


class QueryError(HistoryError):
    """A ``--sql`` query that would write, or that DuckDB cannot run."""


@dataclass
class QueryResult:
    """A query's rows, and the month files left out because they could not be read.

    Attributes
    ----------
    rows : pandas.DataFrame, or list of tuples with ``as_frame=False``
    columns : list of str
    corrupt : list of (Path, str)
    """

    rows: object
    columns: list = field(default_factory=list)
    corrupt: list = field(default_factory=list)

    def corrupt_line(self) -> str | None:
        """One line naming the unreadable month file(s), or None."""
        return corrupt_line(self.corrupt)


def _refuse_writes(duckdb, query: str) -> None:
    try:
        statements = duckdb.extract_statements(query)
    except duckdb.Error as exc:
        raise QueryError(f"--sql: {_one_line(exc)}") from None
    if len(statements) != 1:
        raise QueryError(f"--sql: {len(statements)} statements; give one SELECT over the view checks")
    kind = statements[0].type
    if kind != duckdb.StatementType.SELECT:
        raise QueryError(f"--sql: a {kind.name} statement; the history is read-only: give one SELECT over the view checks")


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def _listing(files) -> str:
    return "[" + ", ".join("'" + str(f).replace("'", "''") + "'" for f in files) + "]"


def _view(con, copies: list[Path], months: list[Path]) -> None:
    """The view ``checks``: each probe's one-file copy where it is current, its month files elsewhere."""
    parts = []
    if copies:
        parts.append(f"SELECT * FROM read_parquet({_listing(copies)}, hive_partitioning = true, "
                     "hive_types = {'probe': VARCHAR}, union_by_name = true)")
    if months:
        parts.append(f"SELECT * FROM read_parquet({_listing(months)}, hive_partitioning = true, "
                     "hive_types = {'probe': VARCHAR, 'month': VARCHAR}, union_by_name = true)")
    if not parts:
        parts.append("SELECT NULL::VARCHAR AS probe, NULL::VARCHAR AS month, NULL::VARCHAR AS check_id, "
                     "NULL::VARCHAR AS checked_utc, NULL::VARCHAR AS state WHERE false")
    con.execute("CREATE VIEW checks AS " + " UNION ALL BY NAME ".join(parts))


def query(history: str | Path, sql: str, *, as_frame: bool = True) -> QueryResult:
    """Run one read-only SELECT over the view ``checks`` of a history folder.

    Parameters
    ----------
    history : path
        The history folder.
    sql : str
        One ``SELECT`` statement.
    as_frame : bool
        Rows as a pandas DataFrame; False: a list of tuples, and no pandas or pyarrow imported
        (the command line's start stays short).

    Returns
    -------
    QueryResult
        An unreadable month file is left out and named in ``corrupt`` (the rest is still read).

    Raises
    ------
    QueryError
        A statement that is not one SELECT, or one DuckDB cannot run (its message, one line).
    HistoryError
        Foreign files in the history.
    ExtraMissingError
        DuckDB is not installed.
    """
    duckdb = require("duckdb", "endocal history --sql")
    _refuse_writes(duckdb, sql)
    folder = HistoryFolder(history)

    def manifests(copies):  # read by DuckDB from the copies' footers, in one query
        con = duckdb.connect(":memory:")
        try:
            found = con.execute("SELECT file_name, decode(value) FROM parquet_kv_metadata($1) WHERE decode(key) = $2",
                                [[str(c) for c in copies], MANIFEST_KEY]).fetchall()
        except duckdb.Error:
            found = []  # a copy DuckDB cannot read: every probe's month files are read instead
        finally:
            con.close()
        return {Path(f): text for f, text in found}

    sources = folder.sources(folder.validate(), manifests)
    copies = [c for c, _ in sources.values() if c is not None]
    months = [f for c, ms in sources.values() if c is None for f in ms]
    corrupt = []
    for attempt in range(2):
        con = duckdb.connect(":memory:")
        try:
            _view(con, copies, months)
            cur = con.execute(sql)
            if as_frame:
                df = cur.fetchdf()
                return QueryResult(df, list(df.columns), corrupt)
            rows = cur.fetchall()
            return QueryResult(rows, [d[0] for d in cur.description], corrupt)
        except duckdb.Error as exc:
            if attempt == 0 and isinstance(exc, (duckdb.IOException, duckdb.InvalidInputException)):
                # only on a failure: find what cannot be read; a bad copy gives way to its month files
                bad_copies = {c for c, _ in _unreadable(copies)}
                copies = [c for c in copies if c not in bad_copies]
                months += [f for c, ms in sources.values() if c in bad_copies for f in ms]
                corrupt = _unreadable(months)
                if corrupt or bad_copies:
                    months = [f for f in months if f not in {b for b, _ in corrupt}]
                    continue
            raise QueryError(f"--sql: {_one_line(exc)}") from None
        finally:
            con.close()
    raise AssertionError("unreachable")


def _unreadable(files: list[Path]) -> list[tuple[Path, str]]:
    """The files DuckDB cannot read whole, with why (only after a query failed: one file at a time)."""
    import duckdb

    bad = []
    con = duckdb.connect(":memory:")
    try:
        for f in files:
            try:
                con.execute("SELECT count(*) FROM read_parquet($1)", [str(f)]).fetchall()
                con.execute("SELECT * FROM read_parquet($1)", [str(f)]).fetchall()
            except duckdb.Error as exc:
                bad.append((f, _one_line(exc)))
    finally:
        con.close()
    return bad
