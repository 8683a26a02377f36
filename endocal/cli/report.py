"""``endocal report``: one self-contained HTML report comparing models on records, with JSON and CSV beside it."""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path
from typing import Optional

import typer

from endocal.cli._common import cli_errors, err, out, refuse_input_as_output
from endocal.cli._effects_file import effects_file_option, use_effects_files
from endocal.cli.messages import EXPLAIN_HELP, capped, keyed_lines


def split_paths(paths: list[Path], data: list[Path]) -> tuple[list[Path], list[Path]]:
    """Model files and records from the command line.

    Click gives ``--data`` one value per flag, so in ``report m1.json m2.json --data r1 r2``
    ``r2`` arrives as a positional argument: positional run folders and tables (``.parquet``,
    ``.csv``) are records, everything else is a model file.
    """
    from endocal.runs.aligned import CSV_SUFFIXES

    models, records = [], list(data)
    for p in paths:
        (records if p.is_dir() or p.suffix.lower() in (".parquet", *CSV_SUFFIXES) else models).append(p)
    return models, records


@cli_errors
def report(
    paths: list[Path] = typer.Argument(..., help="Model files (MODEL.json from `endocal fit hysteresis`)."),
    data: list[Path] = typer.Option(..., "--data", "-d", help="Run folders or aligned tables (.parquet/.csv) to "
                                    "evaluate on: `--data A B` or `--data A --data B`."),
    out_path: Path = typer.Option(..., "--out", "-o", help="HTML file to write; NAME.json and NAME_metrics.csv "
                                  "are written beside it (report.json, report_metrics.csv for report.html)."),
    planes: Optional[Path] = typer.Option(None, "--planes", help="planes.json from `endocal fit planes`: adds the "
                                          "bending-plane figure before/after orthogonal compensation, and stands in "
                                          "for a model's planes file that was moved (same SHA-256)."),
    bootstrap: int = typer.Option(400, "--bootstrap", help="Block-bootstrap replicates for the 95 % intervals "
                                  "(the default matches `endocal validate`)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the bootstrap."),
    force: bool = typer.Option(False, "--force", help="Overwrite the report files."),
    history: Optional[Path] = typer.Option(None, "--history", help="A probe-check history (endocal check --history "
                                           "DIR): adds the control charts of the probe checked against these models."),
    history_probe: Optional[str] = typer.Option(None, "--probe", help="With --history: the probe to chart (default: "
                                                "the one whose checks used these model files)."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary and metrics as one JSON object."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
    explain: bool = typer.Option(False, "--explain", "-v", help=EXPLAIN_HELP + " Adds each finding's test, the ladder "
                                 "of models and every note in full."),
    effects_files: list[Path] = effects_file_option(),
) -> None:
    """Compare hysteresis models on records: metrics with 95 % CIs, statistical tests, figures, provenance.

    Every model is scored on every record of its axis (error = predicted - measured bending
    angle). Models are compared on per-half-cycle errors, because samples are autocorrelated:
    Wilcoxon signed-rank for two models, Friedman with Holm-corrected pairwise Wilcoxon tests
    for more. The summary says which model is best on which record, by how much, and whether
    that is significant (`--explain`: with the test, and the ladder of models). A model that cannot be evaluated on a record is listed with the reason.
    """
    from endocal.report import build_report
    from endocal.report.result import side_files

    use_effects_files(effects_files)
    models, records = split_paths(paths, data)
    if history_probe is not None and history is None:
        from endocal.errors import ModelError

        raise ModelError("--probe names a probe of a check history: give --history DIR with it")
    for kind, written in side_files(out_path).items():
        refuse_input_as_output("--out" if kind == "html" else f"--out (its {kind} file)", written,
                               [*paths, *data, planes])
    show = not quiet and not as_json and err.is_terminal
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=err.console, disable=not show, transient=True) as bar:
        task = bar.add_task("report", total=None)

        def progress(step: str, done: int, total: int) -> None:
            bar.update(task, description=step[:60], completed=done, total=total)

        rep = build_report(models, records, planes=planes, out=out_path, force=force, n_boot=bootstrap, seed=seed,
                           progress=progress, command="endocal " + " ".join(sys.argv[1:]), history=history,
                           history_probe=history_probe)
    if as_json:
        d = json.loads(rep.to_json())
        out.print_json(json.dumps({k: d[k] for k in ("summary", "not_evaluated", "metrics", "ladder", "notes")} |
                                  {"files": {k: str(v) for k, v in side_files(out_path).items()}}))
        return
    if explain:
        for line in rep.summary_lines():
            out.print(line, markup=False)
        for note in rep.notes:
            err.print(note, markup=False)
    else:
        _summary(rep)
    files = side_files(out_path)
    err.print(f"wrote {out_path} (+ {files['json'].name}, {files['csv'].name})", markup=False)
    err.print(f"next: open {shlex.quote(str(out_path))} in a browser (figures, every metric with its interval, the "
              "tests)", markup=False)


def _summary(rep) -> None:
    """``report``: the best model on each record and whether that is significant, one line per
    note (``--explain``: the full findings, the ladder of models, every note in full)."""
    for g in rep.groups:
        f = g.finding
        where = f"{f.data} ({f.signal}), {f.axis}"
        fitted_on = [e.model for e in g.evaluations if e.in_sample]
        if fitted_on:
            where += f" [in-sample for {', '.join(fitted_on)}]"
        line = f"{where}: {f.best} best, RMSE {f.best_rmse_deg:.3g} deg"
        if f.runner_up is not None:
            line += f", {f.margin_pct:.0f} % below {f.runner_up}: "
            line += ("not tested" if f.p_value is None else
                     f"{'significant' if f.significant else 'not significant'} (p = {f.p_value:.2g})")
            if "record more cycles to decide" in f.sentence:  # no p-value could fall below alpha
                line += ": too few cycles to decide, record more"
        out.print(line, markup=False)
    notes = [f"note[not-evaluated]: {n.model} on {n.data} ({n.axis})" for n in rep.not_evaluated]  # why: --explain
    notes += keyed_lines([note for g in rep.groups for e in g.evaluations for note in e.notes], "note")
    for line in capped(notes, 6, "notes"):
        out.print(line, markup=False)
    for line in capped(keyed_lines(rep.notes, "note"), 4, "notes"):
        err.print(line, markup=False)
