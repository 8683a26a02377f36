"""CSV tables as labs write them: the delimiter, spaces and decimal mark read off the file.

Spreadsheets in much of Europe write ``;`` between columns and ``,`` as the decimal mark;
data loggers write tabs, or columns lined up with spaces; hand-edited files put a space after
each comma; loggers often write no header at all. Every CSV endocal reads (aligned tables,
lab logs, waypoint lists) goes through :func:`read_csv_table`, so a table that opens correctly
in a spreadsheet reads the same here, with its column names as written (stripped of spaces), or
numbered ``1``, ``2``, ... when its first line is all numbers. Lines starting with ``#`` before
the header (a logger's notes: the rig, the operator, the firmware) are skipped.
"""

from __future__ import annotations

import io
import re

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # imported when a CSV is read: a Parquet record is read without pandas (runs.aligned)
    import pandas as pd

#: delimiters recognised in the header line, most common first (ties go to the earlier one)
DELIMITERS = (",", ";", "\t", "|")
_DECIMAL_COMMA = re.compile(r"^\s*[-+]?\d+,\d+(?:[eE][-+]?\d+)?\s*$")


def comment_lines(raw: bytes) -> int:
    """How many lines before the header are comments (``#`` first) or blank: a logger's notes."""
    n = 0
    for line in raw.lstrip(b"\xef\xbb\xbf").split(b"\n"):
        text = line.strip()
        if text and not text.startswith(b"#"):
            break
        n += 1
    return n


def _first_line(raw: bytes) -> str:
    """The header line (or the first line of data): the first line that is not a comment."""
    lines = raw.lstrip(b"\xef\xbb\xbf").split(b"\n")
    k = comment_lines(raw)
    return lines[k].decode("utf-8", errors="replace").strip() if k < len(lines) else ""


def sniff_delimiter(raw: bytes) -> str:
    """The delimiter of a CSV file: the candidate that occurs most often in its header line.

    A header with none of them but spaces between names is whitespace-separated (``\\s+``).
    """
    header = _first_line(raw)
    for d in DELIMITERS[1:]:
        # a first line of numbers with decimal commas (no header): the commas are not the delimiter
        if d in header and "," in header and all(_DECIMAL_COMMA.match(f) or _is_number(f, ",")
                                                 for f in header.split(d)):
            return d
    counts = [header.count(d) for d in DELIMITERS]
    if max(counts) > 0:
        return DELIMITERS[counts.index(max(counts))]
    return r"\s+" if len(header.split()) > 1 else ","


def _is_number(field: str, sep: str) -> bool:
    text = field.strip().replace(",", ".") if sep != "," else field.strip()
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_csv_table(raw: bytes) -> pd.DataFrame:
    """Read a CSV file's bytes into a table.

    The delimiter is sniffed from the first line (:func:`sniff_delimiter`); column names are
    stripped of surrounding spaces; a first line of numbers only is data, not a header, and
    the columns are numbered ``"1"``, ``"2"``, ... (``df.attrs["headerless"]`` is then True);
    comment lines before it are skipped (:func:`comment_lines`, ``df.attrs["comment_lines"]``);
    with a delimiter other than ``,``, a file with a text column that reads ``12,5``
    throughout is re-read with ``,`` as the decimal mark; empty rows at the end are dropped.

    Raises
    ------
    pandas.errors.ParserError, pandas.errors.EmptyDataError, UnicodeDecodeError
        As :func:`pandas.read_csv`; callers turn them into one-line messages.
    """
    sep = sniff_delimiter(raw)
    first = _first_line(raw)
    fields = first.split() if sep == r"\s+" else first.split(sep)
    headerless = bool(first) and all(_is_number(f, sep) for f in fields)
    header = None if headerless else "infer"
    skip = comment_lines(raw)
    import pandas as pd

    df = pd.read_csv(io.BytesIO(raw), sep=sep, skipinitialspace=sep != r"\s+", header=header, skiprows=skip)
    if sep not in (",", r"\s+"):
        text = [c for c in df.columns if df[c].dtype == object or pd.api.types.is_string_dtype(df[c])]
        if any(len(df[c].dropna()) and df[c].dropna().astype(str).str.match(_DECIMAL_COMMA).all() for c in text):
            df = pd.read_csv(io.BytesIO(raw), sep=sep, skipinitialspace=True, decimal=",", header=header,
                             skiprows=skip)
    if headerless:
        df.columns = [str(i + 1) for i in range(df.shape[1])]
    df.columns = [c.strip() if isinstance(c, str) else c for c in df.columns]
    # rows left empty at the end (a spreadsheet's export of its formatted range, ",,,"): no data;
    # those inside the table stay, so that line numbers in messages remain the file's
    filled = np.flatnonzero(df.notna().any(axis=1).to_numpy())
    df = df.iloc[: filled[-1] + 1 if filled.size else 0]
    df.attrs["headerless"] = headerless
    df.attrs["comment_lines"] = skip
    return df


def line_numbers(raw: bytes, n: int, headerless: bool) -> np.ndarray:
    """The lines (1 the first, as an editor numbers them) of a table's first ``n`` rows.

    pandas skips blank lines (spaces only; tabs too, unless they separate the cells), so the
    rows after one are not at their count; a quoted cell that spans lines is not followed (a
    logger writes none).
    """
    blank = b" \r" if sniff_delimiter(raw) == "\t" else b" \t\r"
    skip = comment_lines(raw)  # a logger's notes before the header
    filled = np.array([i + 1 for i, text in enumerate(raw.split(b"\n")) if i >= skip and text.strip(blank)], dtype=int)
    rows = filled if headerless else filled[1:]
    # lines ended by a lone \r (old Mac files) are one line here: count the rows instead
    return rows[:n] if rows.size >= n else np.arange(n) + (1 if headerless else 2)


__all__ = ["DELIMITERS", "comment_lines", "line_numbers", "read_csv_table", "sniff_delimiter"]
