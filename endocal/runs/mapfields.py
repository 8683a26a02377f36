"""What the CSV import's checks read of a column map.

:mod:`endocal.runs.csvlog` reads a map into a :class:`~endocal.runs.csvlog.CsvMap` and
imports the log with it; :mod:`endocal.runs.csvchecks` checks what the map makes of the log.
The checks need only the map's fields, described here, so they do not import the importer
that calls them (the two modules imported each other).
"""

from __future__ import annotations

from typing import Any, Protocol

from endocal.probe import ProbeConfig


class ColumnMap(Protocol):
    """The fields of :class:`~endocal.runs.csvlog.CsvMap` the checks read (see its attributes)."""

    probe: ProbeConfig
    time_column: str | None
    time_factor: float | None
    sample_rate_hz: float | None
    knobs: dict[str, Any]
    tip: Any
    base: Any
    angles: dict[str, Any]
    source: str
