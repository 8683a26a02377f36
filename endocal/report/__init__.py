"""Error reports: models compared on records with statistics done right for time series.

``build_report(models, datas, planes=None, out="report.html")`` scores every model on every
record of its axis with :func:`endocal.validation.metrics.error_metrics`, compares the models
on per-half-cycle errors (Wilcoxon signed-rank for two, Friedman + Holm-corrected pairwise
Wilcoxon for more; :mod:`endocal.report.stats`), draws the figures
(:mod:`endocal.report.figures`), cross-validates every model structure for the model ladder
(:mod:`endocal.report.ladder`), draws the measured bending-plane sweeps when a ``planes.json``
is given (:mod:`endocal.report.planes`) and returns a :class:`Report` that renders as terminal text,
``NAME.json``, ``NAME_metrics.csv`` and one self-contained HTML page ``NAME.html``.
"""

from endocal.report.build import build_report
from endocal.report.evaluate import DataEntry, Evaluation, Finding, Group, ModelEntry, NotEvaluated, evaluate, load_inputs
from endocal.report.ladder import HeldOut, cross_validate, model_ladder
from endocal.report.planes import PlanesView, SweepPoints, planes_view
from endocal.report.result import Report, ReportFigure, side_files
from endocal.report.stats import Comparison, PairTest, Units, compare_models, make_units

__all__ = [
    "Comparison", "DataEntry", "Evaluation", "Finding", "Group", "HeldOut", "ModelEntry",
    "NotEvaluated", "PairTest", "PlanesView", "Report", "ReportFigure", "SweepPoints", "Units", "build_report",
    "compare_models", "cross_validate", "evaluate", "load_inputs", "make_units", "model_ladder", "planes_view", "side_files",
]
