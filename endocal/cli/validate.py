"""``endocal validate``: hold a model against measurements (or play it on a backend) and say what is missing."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer

from endocal.cli._common import (
    OUT_OF_RANGE_HELP,
    apply_out_of_range,
    cli_errors,
    emit_json,
    err,
    guard_factory,
    out,
    refuse_input_as_output,
    warnings_as_lines,
)
from endocal.cli._effects_file import effects_file_option, use_effects_files
from endocal.cli.messages import EXPLAIN_HELP
from endocal.errors import ModelError
from endocal.views import SUMMARY_MAX_LINES  # noqa: F401  (the summary's budget, as tests and docs quote it)

if TYPE_CHECKING:
    from rich.table import Table

_UNITS = {"rmse_deg": "deg", "mae_deg": "deg", "max_deg": "deg", "median_deg": "deg", "median_pct": "%"}


def _metrics_table(title: str, metrics) -> Table:
    from rich.table import Table

    from endocal.validation.metrics import METRIC_KEYS

    t = Table(title=title, title_justify="left", show_edge=False)
    t.add_column("metric")
    t.add_column("value", justify="right")
    t.add_column("95 % CI", justify="right")
    for k in METRIC_KEYS:
        lo_hi = metrics.ci.get(k)
        ci = f"{lo_hi[0]:.3g} .. {lo_hi[1]:.3g}" if lo_hi else "-"
        t.add_row(k, f"{getattr(metrics, k):.3g} {_UNITS[k]}", ci)
    return t


_SCHEME_WORDS = {
    "estimation/validation": "candidates fitted on the estimation data, scored on the validation data",
    "rolling-origin": "rolling-origin cross-validation on the validation data",
    "none": "no effect scan",
}


def heldout_label(scan, in_sample: bool = False) -> str:
    """What the scan's held-out RMSE is, in words."""
    if scan.scheme == "estimation/validation":
        if in_sample:
            return "in-sample RMSE (structure fitted on estimation data that includes this record)"
        return "validation RMSE (structure fitted on the estimation data)"
    return f"held-out RMSE (model refitted on earlier data, rolling origin, {scan.folds} blocks)"


def render(result) -> None:
    """``--explain``: print every detail of a :class:`~endocal.validation.offline.ValidationResult` (the result
    the summary renders too): the metrics table, the worst regimes, the residual tests, every candidate with
    its physics and promise, the untested suspects with why and how to test them, every warning and note in
    full."""
    from rich.markup import escape

    from endocal.shell import refit_command
    from endocal.views import promise, scheme_word

    folded = result.request is not None and result.request.folded
    m = result.model
    scan = result.scan
    out.print(f"[bold]{m['label']}[/] on axis {result.axis}: {sum(d['n_samples'] for d in result.data)} samples "
              f"from {len(result.data)} table(s)")
    out.print(m["equation"], markup=False)
    for w in m.get("fit_warnings", []):  # what its fit said (a parameter at a bound, no better than a line)
        out.print(f"fit warning: {w}", markup=False)
    if scan.scheme != "none":
        out.print(f"scheme: {_SCHEME_WORDS[scan.scheme]} ({scan.scheme_reason})", markup=False)
    if result.estimation:
        out.print(f"  estimation data: {', '.join(str(d['source']) for d in result.estimation)} "
                  f"({sum(d['n_samples'] for d in result.estimation)} samples)", markup=False)
    if result.in_sample:
        out.print("[bold]warning:[/] the estimation data includes the record validated here: every score below is "
                  "in-sample and flatters the model; validate on a record it was not fitted on")
    out.print(_metrics_table("How far off (measured vs predicted)", result.metrics))
    n = sum(d["n_samples"] for d in result.data)
    if result.beyond_samples > 0.1 * n:
        # said before any diagnosis: no effect term fixes a model asked where it was never fitted
        out.print(f"[bold]warning:[/] {result.beyond_samples} of {n} samples command beyond the range the model was "
                  "fitted on: there it is extrapolated, and most of this error may be that; refit on data that "
                  "covers this record's commands first")
    if scan.scheme != "none":
        out.print(f"{heldout_label(scan, result.in_sample)}: {scan.baseline_rmse_heldout_deg:.3g} deg", markup=False)
    c = result.compare
    if c is not None:
        arrow = "fell" if c.change_pct < 0 else "rose"
        what = scheme_word(result)
        out.print(f"[bold]Watch the error fall:[/] {what} RMSE {c.old_label} {c.old_heldout_rmse_deg:.3g} deg -> "
                  f"{c.new_label} {c.new_heldout_rmse_deg:.3g} deg ({arrow} {abs(c.change_pct):.0f} %); "
                  f"on all data {c.old_rmse_deg:.3g} -> {c.new_rmse_deg:.3g} deg")
    out.print("[bold]Where it fails[/] (worst regimes, RMSE relative to the whole record):")
    for r in result.regimes.worst(3):
        out.print(f"  {r.group}: {r.name}: RMSE {r.metrics.rmse_deg:.3g} deg ({r.ratio:.2f}x), "
                  f"{100 * r.fraction:.0f} % of samples", markup=False)
    w = result.residuals.whiteness
    out.print(f"residual: {'white' if w.white else 'not white'} (Ljung-Box p = {w.p_value:.2g}, correlation time "
              f"{w.correlation_time_s:.3g} s)", markup=False)
    for x in result.residuals.significant():
        out.print(f"  correlates with {x.signal} (|r| = {x.max_abs_corr:.2f} at lag {x.lag_s:+.3g} s): {x.hint}",
                  markup=False)
    what = scheme_word(result)
    if result.suspects:
        thin = not any(s.significant for s in result.suspects)
        few = all(s.evidence.startswith("not enough") for s in result.suspects)
        head = (f"{what} gain, Holm-corrected p" if not thin else
                f"candidates by {what} gain (not enough evidence for significance)" if few else
                f"candidates by {what} gain: none significant, the gain is not consistent across the record")
        out.print(f"[bold]Which effect is missing[/] ({head}):")
        for i, s in enumerate(result.suspects, 1):
            stat = s.evidence if thin else f"p = {s.p_value:.2g}"
            out.print(f"  {i}. {s.effect}: {promise(s, what)}, {stat}", markup=False)
            out.print(f"     {s.cause}; signature: {s.signature}", markup=False)
            if s.caution:
                out.print(f"     caution: {s.caution}", markup=False)
        if result.beyond_samples > 0.5 * n:  # no effect term fixes a model asked where it was never fitted
            out.print("[bold]Next:[/] refit on data that covers this record's commands (most of it lies beyond the "
                      "model's range, where the candidates above are scored on an extrapolation), then validate again")
        else:
            then = ("then validate the new model on a third record (this one is in its fit now)" if folded else
                    "then validate the new model")
            out.print("[bold]Next:[/] refit with the first " + ("candidate" if thin else "suspect") + f", {then}:")
            out.print("  " + refit_command(result.suspects[0].refit), markup=False)
    elif scan.scheme == "none":
        out.print("[bold]Which effect is missing:[/] not tested: " + escape(scan.scheme_reason))
    elif result.pointers:
        out.print("[bold]Which effect is missing:[/] no catalog effect confirmed by the scan, but the data "
                  "point at effects it could not settle (below).")
    elif result.unexplained:
        out.print(f"[bold]Which effect is missing:[/] no catalog effect lowers the {what} RMSE by {scan.min_gain_pct:g} % "
                  f"or more, but {escape(result.unexplained)}.")
    elif scan.tested and scan.tested[0].gain_pct >= scan.min_gain_pct:
        best = scan.tested[0]
        out.print(f"[bold]Which effect is missing:[/] nothing significant: the best candidate, {escape(best.effect)}, "
                  f"lowers the {what} RMSE by {best.gain_pct:.0f} % but not consistently (Holm-corrected p = "
                  f"{best.p_value:.2g}); the residual points at nothing the scan could not test.")
    else:
        rests = (f" But {scan.still_blocks} of its {scan.folds} held-out blocks hold no motion of this axis: "
                 "this says little (see the notes)." if scan.still_blocks else "")
        out.print(f"[bold]Which effect is missing:[/] nothing: no catalog effect lowers the {what} RMSE by "
                  f"{scan.min_gain_pct:g} % or more, and the residual points at nothing the scan could not test.{rests}")
    if scan.bases:
        out.print(f"[bold]Which base[/] (the other bases with this model's effects, or with an effect beside them "
                  f"where the minor loops point at the base, {what} gain, Holm-corrected p):")
        for b in scan.bases:
            out.print(f"  {b.line(what)}: {b.evidence}"
                      + ("" if b.return_point_memory else "; no return-point memory"), markup=False)
        for b in scan.base_suggestions[:1]:
            out.print("  " + refit_command(b.refit), markup=False)
    if result.pointers:
        out.print("[bold]Untested suspects[/] (the data point at them; the scan did not confirm them):")
        for p in result.pointers:
            out.print(f"  {p.effect} ({p.status}): {p.evidence}", markup=False)
            out.print(f"     why not confirmed: {p.why}", markup=False)
            out.print(f"     to test it: {p.experiment}", markup=False)
    for note in result.notes:
        out.print(f"note: {note}", markup=False)


@cli_errors
def validate(
    model_path: Path = typer.Argument(..., help="Fitted model file (endocal fit hysteresis --out)."),
    data: Optional[list[Path]] = typer.Argument(None, help="Run folders or aligned tables (.parquet/.csv) to validate on."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (metrics, regimes, residuals, suspects, notes)."),
    json_out: Optional[Path] = typer.Option(None, "--json-out", help="Also write that JSON object to this file (the terminal view still prints)."),
    folds: int = typer.Option(5, "--folds", help="Held-out blocks of the blocked cross-validation (2 or more)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the bootstrap intervals (and of the backend with --protocol)."),
    compare: list[Path] = typer.Option([], "--compare", help="A previous model: show its error beside this one's. With --trajectory: other models to walk the path with, one per axis per set (repeatable), compared with paired tests."),
    train: list[Path] = typer.Option([], "--train", help="Estimation data (repeatable): candidate effects are fitted on it and scored on DATA. Default: the records the model file names, when found and unchanged."),
    cv: str = typer.Option("auto", "--cv", help="How effects are tested: `auto` (estimation/validation split when there is estimation data, else rolling origin), `rolling` (rolling-origin cross-validation on DATA alone), `split` (require estimation data)."),
    refit_on: str = typer.Option("estimation", "--refit-on", help="What the printed refit commands fit on: `estimation` (the estimation data only, as the candidates were scored; default) or `all` (the estimation and the validation data: a final model, whose error must then be measured on a third record)."),
    out_of_range: Optional[str] = typer.Option(None, "--out-of-range", help="With --protocol: " + OUT_OF_RANGE_HELP),
    load_column: list[str] = typer.Option([], "--load-column", help="Try load:COLUMN on this column (repeatable; default: every varying extra column)."),
    protocol: Optional[str] = typer.Option(None, "--protocol", help="Play this desired-angle protocol through the inverse model on a backend instead."),
    trajectory: Optional[str] = typer.Option(None, "--trajectory", help="Walk this tip path (circle-1, circle-2, line, raster, a path .toml or an x_mm,y_mm,z_mm .csv) with task-space control: MODEL and DATA are then the model files, one per axis."),
    backend: str = typer.Option("sim", "--backend", "-b", help="Backend for --protocol: `sim` or `hardware`."),
    probe: str = typer.Option("tee", "--probe", help="Probe preset or .toml for --protocol."),
    sim_config: Optional[Path] = typer.Option(None, "--sim-config", help="Simulator TOML for --backend sim."),
    hardware_config: Optional[Path] = typer.Option(None, "--hardware-config", help="Rig TOML for --backend hardware."),
    planes: Optional[Path] = typer.Option(None, "--planes", help="planes.json (endocal fit planes): for --protocol; offline, overrides the planes the model was fitted through."),
    sets: list[str] = typer.Option([], "--set", help="Override a parameter of --protocol, e.g. --set amplitude_deg=40 (repeatable)."),
    runs_out: Optional[Path] = typer.Option(None, "--runs-out", help="With --protocol: keep the played runs here (compensated/, uncompensated/); without it they are removed once scored on the simulator, and kept in a temporary folder (named) on a rig."),
    force_model: Optional[Path] = typer.Option(None, "--force-model", help="With --protocol: force.json (endocal fit force); guard both playbacks every tick."),
    max_force_n: Optional[float] = typer.Option(None, "--max-force-n", help="With --force-model: stop bending into the load at this predicted tip force (N)."),
    explain: bool = typer.Option(False, "--explain", "-v", help=EXPLAIN_HELP + " Offline: the metrics table, the worst regimes, the residual tests, every candidate with its physics, the untested suspects with why and how to test them."),
    next_path: Optional[Path] = typer.Option(None, "--next", help="Offline: write the protocol that would settle what this validation could not (suspects it could not confirm, effects the data cannot test) to this .toml, sized from the effects seen, for the probe the records were made on (else --probe); prints the excite commands that record it (with --json or --json-out: the object's `next`: the file, the suspects, each one's half-cycles needed at the gain seen, the excite commands)."),
    effects_files: list[Path] = effects_file_option(),
) -> None:
    """Compare a model with measurements: how far off, where it fails, which physical effect is missing.

    Offline (DATA given): error metrics with 95 % block-bootstrap intervals, the error by regime,
    residual whiteness and cross-correlations, and every catalog effect the model lacks tested:
    fitted on the estimation data (--train, or the records the model was fitted on) and scored
    on DATA, unit by unit, Holm-corrected; rolling-origin cross-validation on DATA when there is
    no estimation data. Prints the command that refits with the most likely missing effect, and
    names effects the residual points at that the scan could not confirm. With --protocol: plays
    the protocol through the inverse model on a backend and measures desired vs reached angles.
    """
    from endocal.models import load_model

    use_effects_files(effects_files)  # before the model that may need them
    if folds < 2:
        raise ModelError(f"--folds must be 2 or more (held-out blocks of the rolling-origin scan), got {folds}")
    refuse_input_as_output("--json-out", json_out, [model_path, *(data or []), *train, *compare, planes, force_model,
                                                    sim_config, hardware_config])
    for path in (json_out, next_path):
        if path is not None:
            from endocal.runs.format import check_parent

            check_parent(path)  # before any work: a long validation must not end in an output it cannot write
    if next_path is not None:
        if protocol is not None or trajectory is not None:
            raise ModelError("--next designs the next recording from an offline validation: give DATA, not "
                             "--protocol or --trajectory")
        refuse_input_as_output("--next", next_path, [model_path, *(data or []), *train, *compare, planes])
    if trajectory is not None:
        if protocol is not None:
            raise ModelError("give either --trajectory (a tip path) or --protocol (desired angles of one axis), not both")
        from endocal.cli.tip_path import run_trajectory

        run_trajectory([model_path, *(data or [])], compare, trajectory, backend=backend, probe=probe, sim_config=sim_config,
                       hardware_config=hardware_config, planes=planes, seed=seed, sets=sets, out_of_range=out_of_range,
                       runs_out=runs_out, as_json=as_json, json_out=json_out,
                       force_model=force_model, max_force_n=max_force_n)
        return
    if len(compare) > 1:
        raise ModelError("--compare takes one previous model offline (several only with --trajectory)")
    compare_path = compare[0] if compare else None
    model = load_model(model_path)
    if protocol is not None:
        if data:
            raise ModelError("give either DATA (offline validation) or --protocol (playback on a backend), not both")
        apply_out_of_range(model, out_of_range)
        _playback(model, model_path, protocol, backend, probe, sim_config, hardware_config, planes, seed, as_json, sets,
                  runs_out, json_out, force_model, max_force_n, explain)
        return
    if force_model is not None or max_force_n is not None:
        raise ModelError("--force-model and --max-force-n guard a playback: use them with --protocol")
    if out_of_range is not None:
        raise ModelError("--out-of-range applies to a playback (--protocol): offline validation predicts the recorded commands as they are")
    if not data:
        raise ModelError("nothing to validate on: give run folders or aligned tables, or --protocol P")
    if refit_on not in ("estimation", "all"):
        raise ModelError(f"--refit-on must be one of estimation, all, got {refit_on!r}")
    from endocal.runs.aligned import load_aligned
    from endocal.validation.offline import validate_records
    from endocal.views import validation_dict, validation_summary

    old = load_model(compare_path) if compare_path is not None else None
    v = validate_records(model, [load_aligned(p) for p in data], model_path=model_path, train_paths=train, cv=cv,
                         planes_path=planes, compare=old, compare_path=compare_path, refit_on=refit_on, folds=folds,
                         seed=seed, load_columns=load_column or None, next_path=next_path, probe=probe)
    refuse_input_as_output("--json-out", json_out, [*(d["source"] for d in v.estimation), *v.request.train,
                                                    v.request.planes])
    if not emit_json(validation_dict(v), as_json, json_out):
        if explain:
            render(v)
            if v.compare_found:
                err.print(f"compared with {v.compare.old_path} (the model this one was refitted from)")
        else:
            for line in validation_summary(v):
                out.print(line, markup=False)
    if v.next is not None:
        from endocal.cli.next_protocol import render_next
        from endocal.validation.next_experiment import NothingSuspectedError

        render_next(v.next, as_json)
        if not v.next.written:  # said in the JSON too; on the command line one line, exit code 2
            raise NothingSuspectedError(v.next.reason)


def _rmse_ci(metrics) -> str:
    """``RMSE 0.405 deg (95 % CI 0.39 .. 0.419)``."""
    lo, hi = metrics.ci.get("rmse_deg", (float("nan"), float("nan")))
    return f"RMSE {metrics.rmse_deg:.3g} deg (95 % CI {lo:.3g} .. {hi:.3g})"


def _playback(model, model_path, protocol, backend, probe, sim_config, hardware_config, planes, seed, as_json, sets,
              runs_out, json_out, force_model=None, max_force_n=None, explain=False) -> None:
    from endocal.backends.registry import make_backend
    from endocal.probe import load_probe
    from endocal.protocols import load_protocol, parse_overrides
    from endocal.validation.estimation import recorded_planes
    from endocal.validation.playback import validate_on_backend

    probe_cfg = load_probe(probe)
    proto = load_protocol(protocol, overrides=parse_overrides(sets) or None)
    make_backend(backend, probe_cfg, seed=seed, sim_config=sim_config, hardware_config=hardware_config)  # check configs first
    # the planes the model was fitted through (as offline): its commands bend those planes
    cal = recorded_planes(model, model_path, planes)[0]
    make_guard = guard_factory(force_model, max_force_n, probe_cfg)
    if runs_out is None and backend != "sim":  # what a rig recorded is kept: say where
        runs_out = Path(tempfile.mkdtemp(prefix="endocal-validate-"))
        err.print(f"the played runs are kept in {runs_out} (--runs-out names a folder)", markup=False)
    with warnings_as_lines():
        result = validate_on_backend(
            model,
            proto,
            lambda: make_backend(backend, probe_cfg, seed=seed, sim_config=sim_config, hardware_config=hardware_config),
            probe_cfg,
            planes=cal,
            seed=seed,
            out_dir=runs_out,
            guard_factory=make_guard,
        )
    if emit_json(result.to_dict(), as_json, json_out):
        return
    if explain:
        out.print(_metrics_table(f"compensated: {protocol} on {backend}", result.metrics))
        out.print(_metrics_table("uncompensated", result.uncompensated))
    else:
        comp, unc = result.metrics, result.uncompensated
        lines = [f"compensated ({protocol} on {backend}): {_rmse_ci(comp)}, max {comp.max_deg:.3g} deg",
                 f"uncompensated: {_rmse_ci(unc)}, max {unc.max_deg:.3g} deg"]
        if unc.rmse_deg > 0:
            change = 100.0 * (1.0 - comp.rmse_deg / unc.rmse_deg)
            lines[-1] += f": the model {'lowers' if change >= 0 else 'raises'} the RMSE {abs(change):.0f} %"
        for line in lines:
            out.print(line, markup=False)
    if make_guard is not None:
        for name, events in result.events.items():
            stops = [e for e in events if e["kind"] == "stop"]
            out.print(f"force guard, {name}: {len(stops)} stop(s)" + "".join(
                f"; t = {e['t_s']:.2f} s at {e['force_pred_n']:.3f} N" for e in stops), markup=False)
    if not explain:
        out.print("details: --explain (every metric with its interval)", markup=False)
