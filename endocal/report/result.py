"""The report as one object: the terminal summary, ``report.json``, ``report_metrics.csv`` and
the HTML page all render from a :class:`Report`; nothing is computed twice.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from endocal.errors import OutputExistsError, OutputPathError
from endocal.files import atomic_write_bytes
from endocal.planes import PlanesCalibration
from endocal.report.evaluate import DataEntry, Group, ModelEntry, NotEvaluated
from endocal.report.planes import PlanesView
from endocal.validation.metrics import METRIC_KEYS

FORMAT = "endocal-report"
VERSION = 1


def side_files(out_html: str | Path) -> dict[str, Path]:
    """The report's files: the HTML page and, beside it, ``<name>.json`` and ``<name>_metrics.csv``
    (``report.json`` and ``report_metrics.csv`` for ``report.html``), so that several reports
    can share a folder."""
    out = Path(out_html)
    return {"html": out, "json": out.with_suffix(".json"), "csv": out.with_name(f"{out.stem}_metrics.csv")}


@dataclass
class ReportFigure:
    """One figure of the report.

    Attributes
    ----------
    id : str
        Stable identifier (``loops-ds-ap``), the HTML anchor.
    section : str
        ``records``, ``ladder``, ``models``, ``planes``, ``task-space`` or ``checks`` (``report --history``).
    title, caption : str
    png : bytes
    group : str or None
        ``data/axis`` of the record group it belongs to.
    figure : matplotlib Figure or None
        The drawn figure itself, kept when the report was built with ``keep_figures``
        (:func:`~endocal.report.build.build_report`; the Python API does); not serialised.
    """

    id: str
    section: str
    title: str
    caption: str
    png: bytes
    group: str | None = None
    figure: object = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict:
        return {"id": self.id, "section": self.section, "title": self.title, "caption": self.caption,
                "group": self.group, "png_bytes": len(self.png)}


@dataclass
class Report:
    """Everything ``endocal report`` found.

    Attributes
    ----------
    models, datas : lists of ModelEntry, DataEntry
    groups : list of Group
        One per record and axis: evaluations, units, comparison, finding.
    not_evaluated : list of NotEvaluated
        Every model x record that could not be scored, with the reason.
    ladder : list of dict
        Steps of the model ladder in ladder order: each model structure cross-validated on each
        record (held-out and in-sample RMSE, the step's gain and its test), see
        :func:`endocal.report.ladder.model_ladder`.
    figures : list of ReportFigure
    planes : PlanesCalibration or None
    provenance : dict
    notes : list of str
        What the report could not draw and why (e.g. no tracker stream for tip paths).
    planes_view : PlanesView or None
        The measured sweeps behind ``planes`` that the bending-plane figure draws.
    """

    models: list[ModelEntry]
    datas: list[DataEntry]
    groups: list[Group]
    not_evaluated: list[NotEvaluated]
    ladder: list[dict]
    figures: list[ReportFigure] = field(default_factory=list)
    planes: PlanesCalibration | None = None
    provenance: dict = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    planes_view: PlanesView | None = None

    # ------------------------------------------------------------------ views
    @property
    def findings(self):
        return [g.finding for g in self.groups]

    def group(self, data: str, axis: str) -> Group:
        for g in self.groups:
            if g.data == data and g.axis == axis:
                return g
        raise KeyError((data, axis))

    def summary_lines(self) -> list[str]:
        """The summary as plain sentences (terminal and HTML)."""
        lines = [f.sentence for f in self.findings]
        lines += self.ladder_lines()
        lines += [f"not evaluated: {n.model} on {n.data} ({n.axis}): {n.reason}" for n in self.not_evaluated]
        lines += [f"note: {note}" for g in self.groups for e in g.evaluations for note in e.notes]
        return lines

    def ladder_lines(self) -> list[str]:
        """One sentence per record with two or more rungs: the held-out RMSE step by step."""
        out = []
        for key in dict.fromkeys((s["axis"], s["data"]) for s in self.ladder):
            steps = [s for s in self.ladder if (s["axis"], s["data"]) == key]
            if len(steps) < 2:
                continue
            parts = []
            for s in steps:
                if s["heldout_rmse_deg"] is None:
                    parts.append(f"{s['step']} not cross-validated ({s['heldout_error']})")
                    continue
                txt = f"{s['step']} {s['heldout_rmse_deg']:.3g}"
                if s["change_pct"] is not None:
                    txt += f" ({s['change_pct']:+.0f} %, p = {s['p_adjusted']:.2g})"
                parts.append(txt)
            schemes = {s["scheme"] for s in steps if s["scheme"]}
            how = (f"{steps[0]['folds']}-fold rolling origin" if schemes == {"rolling-origin"} else
                   "fitted on the estimation data" if schemes == {"estimation/validation"} else
                   "no rung cross-validated" if not schemes else "mixed schemes: " + ", ".join(sorted(schemes)))
            out.append(f"ladder {key[1]}, {key[0]} (held-out RMSE deg, {how}): " + " -> ".join(parts))
        return out

    def __str__(self) -> str:
        return "\n".join(self.summary_lines())

    def metrics_rows(self) -> list[dict]:
        """One row per model x record x axis: the five metrics with their 95 % intervals."""
        sig = {m.label: m for m in self.models}
        rows = []
        for g in self.groups:
            best = g.finding.best
            for e in g.evaluations:
                row = {"data": g.data, "signal": next(d.signal for d in self.datas if d.label == g.data),
                       "axis": g.axis, "model": e.model, "model_name": sig[e.model].name,
                       "in_sample": e.in_sample, "n": e.metrics.n, "best": e.model == best}
                for k in METRIC_KEYS:
                    lo, hi = e.metrics.ci.get(k, (math.nan, math.nan))
                    row[k] = getattr(e.metrics, k)
                    row[k + "_ci_low"] = lo
                    row[k + "_ci_high"] = hi
                rows.append(row)
        return rows

    def to_dict(self) -> dict:
        """The JSON view (``report.json``)."""
        return {
            "format": FORMAT, "version": VERSION,
            "summary": [f.to_dict() for f in self.findings],
            "not_evaluated": [n.to_dict() for n in self.not_evaluated],
            "metrics": self.metrics_rows(),
            "groups": [g.to_dict() for g in self.groups],
            "ladder": list(self.ladder),
            "models": [m.to_dict() for m in self.models],
            "data": [d.to_dict() for d in self.datas],
            "planes": None if self.planes is None else self.planes.to_json(),
            "planes_sweeps": None if self.planes_view is None else self.planes_view.to_dict(),
            "figures": [f.to_dict() for f in self.figures],
            "notes": list(self.notes),
            "provenance": self.provenance,
        }

    def to_json(self) -> str:
        return json.dumps(_clean(self.to_dict()), indent=2, allow_nan=False)

    def to_csv(self) -> str:
        rows = self.metrics_rows()
        buf = io.StringIO()
        if rows:
            w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
            w.writeheader()
            for r in rows:
                w.writerow({k: ("" if isinstance(v, float) and not math.isfinite(v) else v) for k, v in r.items()})
        return buf.getvalue()

    def to_html(self) -> str:
        from endocal.report.html import render_html

        return render_html(self)

    # ------------------------------------------------------------------ files
    def write(self, out_html: str | Path, *, force: bool = False) -> dict[str, Path]:
        """Write the HTML page and, beside it, its JSON and metrics CSV (:func:`side_files`).

        Parameters
        ----------
        out_html : path
            The HTML file; its folder is created if needed.
        force : bool
            Overwrite existing files.

        Returns
        -------
        dict with keys ``html``, ``json``, ``csv``

        Raises
        ------
        OutputExistsError
            A file exists and ``force`` is False (nothing is written).
        OutputPathError
            The folder cannot be created or written.
        """
        out = Path(out_html)
        paths = check_output(out, force=force)
        try:
            contents = {"json": self.to_json().encode(), "csv": self.to_csv().encode(), "html": self.to_html().encode()}
            for k in ("json", "csv", "html"):
                atomic_write_bytes(paths[k], contents[k])
        except (PermissionError, NotADirectoryError, FileExistsError, IsADirectoryError) as exc:
            raise OutputPathError(f"cannot write the report to {out.parent}: {exc.strerror or exc}") from None
        return paths


def check_output(out_html: str | Path, *, force: bool = False) -> dict[str, Path]:
    """The three report paths for ``out_html``, refused before any work if they exist (unless ``force``).

    Raises
    ------
    OutputPathError
        ``out_html`` does not end in ``.html``.
    OutputExistsError
        One of the files exists and ``force`` is False.
    """
    out = Path(out_html)
    paths = side_files(out)
    if out.suffix.lower() not in (".html", ".htm"):
        raise OutputPathError(f"{out}: the report is an HTML file; give --out a name ending in .html")
    if not force:
        exists = [str(p) for p in paths.values() if p.exists()]
        if exists:
            raise OutputExistsError(f"{', '.join(exists)} already exist(s): choose another --out or pass --force")
    return paths


def _clean(x):
    """NaN/inf -> None so the JSON is strict."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if hasattr(x, "item") and callable(x.item):
        return _clean(x.item())
    return x
