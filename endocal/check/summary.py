"""A history read back: every probe's last check and state, and one probe's control charts."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from endocal.check.charts import ProbeCharts, probe_charts
from endocal.check.scoring import FIGURES
from endocal.check.store import HistoryError, HistoryFolder, corrupt_line

#: Columns of :meth:`FleetHistory.table`.
TABLE_COLUMNS = ("probe", "last_check_utc", "state", "checks_since_calibration", "checks", "calibration")


def since_calibration(rows, calibration: str | None = None):
    """One probe's rows of its current calibration, oldest first: the trailing rows scored against
    the same models (``calibration``; default: the last row's)."""
    if not len(rows):
        return rows
    keys = rows["calibration"].to_numpy()
    calibration = keys[-1] if calibration is None else calibration
    k = len(keys)
    while k > 0 and keys[k - 1] == calibration:
        k -= 1
    return rows.iloc[k:].reset_index(drop=True)


def figure_columns(rows) -> list[str]:
    """The figure columns present in ``rows`` (``ap_rmse_deg``...), axis by axis in :data:`FIGURES` order."""
    cols = [c for c in rows.columns if any(c.endswith("_" + f) for f in FIGURES) and rows[c].notna().any()]
    axes = list(dict.fromkeys(c.split("_")[0] for c in cols))
    return [f"{a}_{f}" for a in axes for f in FIGURES if f"{a}_{f}" in cols]


@dataclass
class FleetHistory:
    """What a history folder holds (``endocal history DIR``).

    Attributes
    ----------
    root : Path
    rows : pandas.DataFrame
        Every readable row (``probe`` and ``month`` from the partition paths), by probe then time.
    corrupt : list of (Path, str)
        Month files that could not be read (their rows are missing).
    """

    root: Path
    rows: object
    corrupt: list = field(default_factory=list)

    @property
    def probes(self) -> list[str]:
        return sorted(self.rows["probe"].unique()) if len(self.rows) else []

    def corrupt_line(self) -> str | None:
        return corrupt_line(self.corrupt)

    def probe_rows(self, probe_id: str):
        """One probe's rows, oldest first.

        Raises
        ------
        HistoryError
            No such probe in the history.
        """
        rows = self.rows[self.rows["probe"] == probe_id] if len(self.rows) else self.rows
        if not len(rows):
            known = ", ".join(self.probes) or "none"
            raise HistoryError(f"no checks of probe {probe_id} in {self.root} (probes: {known})")
        return rows.reset_index(drop=True)

    def table(self):
        """Every probe's last check and state (:data:`TABLE_COLUMNS`), one row per probe."""
        import pandas as pd

        out = []
        for pid in self.probes:
            rows = self.probe_rows(pid)
            last = rows.iloc[-1]
            out.append({"probe": pid, "last_check_utc": last["checked_utc"], "state": last["state"],
                        "checks_since_calibration": len(since_calibration(rows)), "checks": len(rows),
                        "calibration": last["calibration"]})
        return pd.DataFrame(out, columns=list(TABLE_COLUMNS))

    def charts(self, probe_id: str) -> ProbeCharts:
        """The control charts of a probe's checks since its last calibration."""
        rows = since_calibration(self.probe_rows(probe_id))
        return probe_charts(probe_id, rows, figure_columns(rows))


def read_history(root: str | Path) -> FleetHistory:
    """Read a history folder.

    Raises
    ------
    HistoryError
        Not a history folder (missing, or foreign files in it). An unreadable month file is not
        raised: it is named in ``corrupt`` and the rest is read.
    """
    root = Path(root)
    if not root.is_dir():
        raise HistoryError(f"no history folder {root}: give the --history folder of endocal check")
    read = HistoryFolder(root).read()
    return FleetHistory(root, read.rows, read.corrupt)


def probes_checked_against(fleet: FleetHistory, sha256s) -> list[str]:
    """The probes whose latest calibration's checks were scored against any of these model files (by SHA-256)."""
    import json

    wanted = {s for s in sha256s if s}
    found = []
    for pid in fleet.probes:
        rows = since_calibration(fleet.probe_rows(pid))
        used = {rec.get("sha256") for text in set(rows["models"]) for rec in json.loads(text).values()}
        if used & wanted:
            found.append(pid)
    return found


def report_pages(history: str | Path, sha256s, probe_id: str | None = None):
    """What ``endocal report --history DIR`` adds: each probe's control charts, ready to draw.

    Parameters
    ----------
    history : path
    sha256s : iterable of str
        The report's model files: the probes checked against them get a page.
    probe_id : str, optional
        The probe to show instead.

    Returns
    -------
    pages : list of (probe_id, ProbeCharts)
    notes : list of str
        An unreadable month file, named.

    Raises
    ------
    HistoryError
        No probe of the history was checked against these models (and none was named).
    """
    fleet = read_history(history)
    probes = [probe_id] if probe_id is not None else probes_checked_against(fleet, sha256s)
    if not probes:
        raise HistoryError(f"no probe in {history} was checked against these models ({', '.join(fleet.probes) or 'no probes'}"
                           " there): give the probe with --probe ID")
    notes = [line] if (line := fleet.corrupt_line()) else []
    return [(p, fleet.charts(p)) for p in probes], notes
