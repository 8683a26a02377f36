"""``endocal fit``: fit bending planes and hysteresis models to runs."""

from __future__ import annotations

import json
import shlex
from pathlib import Path
from typing import Optional

import typer

from endocal.cli._common import cli_errors, err, out, refuse_input_as_output, slow_clock_warning
from endocal.cli._effects_file import effects_file_option, use_effects_files
from endocal.cli.messages import EXPLAIN_HELP, keyed, keyed_lines
from endocal.errors import OutputExistsError

app = typer.Typer(help="Fit bending planes (`fit planes`), hysteresis models (`fit hysteresis`) and contact-force models (`fit force`).", no_args_is_help=True)


@app.command("planes")
@cli_errors
def planes(
    runs: list[Path] = typer.Argument(..., help="Run folders of the `planes` protocol (single-knob sweeps)."),
    out_path: Path = typer.Option(..., "--out", "-o", help="planes.json to write (versioned JSON)."),
    after: list[Path] = typer.Option([], "--after", help="Runs recorded with the compensator on: measured residual deviations."),
    bootstrap: int = typer.Option(200, "--bootstrap", help="Bootstrap replicates over sweeps for the 95 % CIs."),
    seed: int = typer.Option(0, "--seed", help="Seed of the bootstrap."),
    force: bool = typer.Option(False, "--force", help="Overwrite --out."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (deviation_deg, residual_deviation_deg, delta_deg, ...)."),
    explain: bool = typer.Option(False, "--explain", "-v", help=EXPLAIN_HELP + " Adds the sweeps used and the tracker frames dropped."),
) -> None:
    """Fit the four half-planes (duodenoscope eqs. 1-2), the thesis's twist delta and the orthogonal compensator.

    Prints the deviation angles alpha_y+, alpha_y-, alpha_x+, alpha_x- and delta with 95 %
    bootstrap confidence intervals and the residual deviations after compensation (with
    `--explain`, which sweeps were used). Later commands take the file with `--planes planes.json`.
    """
    from endocal.planes import save_planes
    from endocal.planes.from_runs import calibrate_planes

    if out_path.exists() and not force:
        raise OutputExistsError(f"{out_path} already exists: choose another --out or pass --force")
    cal, probe = calibrate_planes(runs, after=after or None, n_bootstrap=bootstrap, seed=seed)
    save_planes(cal, out_path, force=force)
    if as_json:
        out.print_json(json.dumps(cal.to_json()))
        return
    out.print(str(cal), markup=False)
    dropped = {k: v for k, v in cal.dropped_frames.items() if v}
    if explain:
        by_half: dict[str, list[str]] = {}
        for sweep in cal.sweeps_used:
            by_half.setdefault(sweep["half_plane"], []).append(f"{sweep['run']}#{sweep['index']}")
        out.print("sweeps used: " + "; ".join(f"{h}: {', '.join(v)}" for h, v in sorted(by_half.items())), markup=False)
        out.print("tracker frames dropped: " + (", ".join(f"{k}={v}" for k, v in dropped.items()) if dropped else "none"),
                  markup=False)
    elif dropped:
        out.print(keyed("tracker frames dropped: " + ", ".join(f"{k}={v}" for k, v in dropped.items()), "note",
                        "frames-dropped"), markup=False)
    err.print(f"wrote {out_path}")
    err.print(f"next: endocal fit hysteresis RUNS --axis AXIS --planes {shlex.quote(str(out_path))} --out MODEL.json "
              "(the hysteresis of each axis, in the planes the knobs drive)", markup=False)


@app.command("hysteresis")
@cli_errors
def hysteresis(
    data: list[Path] = typer.Argument(..., help="Run folders or aligned tables (.parquet / .csv); fitted together."),
    axis: str = typer.Option(..., "--axis", "-a", help="Bending axis to model, e.g. ap, ml, ud, lr."),
    model: str = typer.Option("pi", "--model", "-m", help="Base model: linear, bspline, pi (return-point memory), bouc-wen or dahl (smooth friction without it)."),
    effects: str = typer.Option("", "--effects", "-e", help="Comma-separated effects, e.g. envelope,delay (see `endocal effects`)."),
    planes_file: Optional[Path] = typer.Option(None, "--planes", help="planes.json: fit against the twisted planes the knob drives."),
    out_path: Path = typer.Option(..., "--out", "-o", help="Model file to write (versioned JSON)."),
    force: bool = typer.Option(False, "--force", help="Overwrite --out."),
    as_json: bool = typer.Option(False, "--json", help="Print the model file's content as JSON."),
    sets: list[str] = typer.Option([], "--set", help="A base-model setting, e.g. --set n_knots=3 (bspline: n_knots, degree; pi: n_operators, weights, offset); repeatable."),
    start_from: Optional[Path] = typer.Option(None, "--start-from", help="A fitted model (same axis) to start from: the effects it has start at its values, and its base's when it is this fit's; a fit from scratch replaces it where it ends more than 1 % lower. validate's refit commands use it."),
    start_values: list[str] = typer.Option([], "--start-value", help="A second start for an effect's parameter, e.g. --start-value deadzone_slack_deg=2.4 (full names as the fit prints them; repeatable; give each free parameter of the effect): the fit from it is kept where it ends lower on the data. validate's refit commands give the values its candidate reached."),
    explain: bool = typer.Option(False, "--explain", "-v", help=EXPLAIN_HELP),
    effects_files: list[Path] = effects_file_option(),
) -> None:
    """Fit a hysteresis model (knob command -> bending angle) of one axis.

    `--model pi --effects envelope` is the duodenoscope paper's modified Prandtl-Ishlinskii
    model (eqs. 5-8, analytic inverse eqs. 9-11); `bspline` is the thesis's direction-dependent
    B-splines; `linear` the piecewise-linear model in the spirit of Lee et al. The fitted
    model prints as its equation with standard errors, then its RMSE and a line per warning;
    `--explain` adds how the optimiser stopped and each warning in full.
    """
    import sys

    from endocal.fitting import fit_hysteresis, fit_provenance
    from endocal.models import model_to_dict, save_model

    use_effects_files(effects_files)
    refuse_input_as_output("--out", out_path, [*data, planes_file, start_from, *effects_files])
    if out_path.exists() and not force:
        raise OutputExistsError(f"{out_path} already exists: choose another --out or pass --force")
    planes = None
    if planes_file is not None:
        from endocal.planes import load_planes

        planes = load_planes(planes_file)
    start = None
    if start_from is not None:
        from endocal.models import load_model

        start = load_model(start_from)
    effect_list = [e.strip() for e in effects.split(",") if e.strip()]
    settings = _settings(model, sets)
    from endocal.protocols import parse_overrides

    result = fit_hysteresis(data, axis, model, effect_list, planes=planes, start_from=start,
                            start_values=parse_overrides(start_values, "--start-value"), **settings)
    provenance = fit_provenance(result, command="endocal " + " ".join(sys.argv[1:]), planes_path=planes_file,
                                start_from_path=start_from)
    save_model(result.model, out_path, provenance=provenance)
    if as_json:
        d = model_to_dict(result.model)
        d["provenance"] = provenance
        out.print_json(json.dumps(d))
        return
    if explain:
        _fit_explained(result)
    else:
        _fit_summary(result)
    err.print(f"wrote {out_path}")
    for line in _next_validate(out_path, result.sources):
        err.print(line, markup=False)


def _next_validate(model_path: Path, sources: list) -> list[str]:
    """What to run after a fit: validate on other records; after a fit on one record, also what to do
    when that record is all there is (rolling origin on it, or a held-out part with --cv split)."""
    m = shlex.quote(str(model_path))
    lines = [f"next: endocal validate {m} RECORDS (records it was not fitted on)"]
    if len(sources) == 1:
        rec = shlex.quote(str(sources[0]))
        lines.append(f"  only this one record? endocal validate {m} {rec} --cv rolling (rolling origin: each "
                     "candidate effect refitted on the record's start, scored on the stretch after it); or fit on "
                     "part of the log and validate on the rest with --cv split")
    return lines


def _fit_explained(result) -> None:
    """``fit hysteresis --explain``: the equation, how the fit went, every warning and note in full."""
    rep = result.model.fit_report_
    out.print(str(result.model), markup=False)
    out.print(
        f"fit: {result.samples} samples ({result.duration_s:.4g} s, {result.rate_hz:.1f} Hz) from "
        f"{len(result.sources)} source(s); RMSE {rep.rmse_deg:.3f} deg; {rep.nfev} evaluations; "
        + ("converged" if rep.status > 0 else f"stopped before converging ({rep.message}): the parameters may not be "
           "final; refit with --start-from this model"),
        markup=False,
    )
    slow = slow_clock_warning(result.samples, result.duration_s)
    if slow:
        out.print(slow, markup=False)
    for w in [*rep.warnings, *(n for n in (result.glitches,) if n)]:
        out.print(f"warning: {w}", markup=False)
    if result.cut_start:  # a start the fit estimated is said; one it could not is a warning
        out.print(f"{'note' if rep.estimated_starts else 'warning'}: {result.cut_start}", markup=False)


def _fit_summary(result) -> None:
    """``fit hysteresis``: the equation, the RMSE, one line per warning (the full text with --explain)."""
    rep = result.model.fit_report_
    out.print(str(result.model), markup=False)
    out.print(f"RMSE {rep.rmse_deg:.3f} deg on {result.samples} samples ({result.duration_s:.4g} s, "
              f"{result.rate_hz:.1f} Hz) from {len(result.sources)} source(s); "
              + ("converged" if rep.status > 0 else "not converged"), markup=False)
    lines = []
    if rep.status <= 0:
        lines.append(keyed(f"stopped before converging ({rep.message}), refit with --start-from the model just "
                           "written to go on from its values", key="not-converged"))
    slow = slow_clock_warning(result.samples, result.duration_s)
    lines += keyed_lines([slow, *rep.warnings, result.glitches])
    if result.cut_start:
        lines.append(keyed(result.cut_start, "note" if rep.estimated_starts else "warning"))
    for line in lines:
        out.print(line, markup=False)


from endocal.cli.force import fit_force_cmd  # noqa: E402  (registered here so `fit --help` lists it)

app.command("force")(fit_force_cmd)


def _settings(base: str, sets: list[str]) -> dict:
    """``--set key=value`` as base-model settings; a key the base does not have is an error naming those it has."""
    import inspect

    from endocal.errors import ModelError
    from endocal.models.registry import BASES
    from endocal.protocols import parse_overrides

    settings = parse_overrides(sets)
    if base in BASES:
        known = [k for k in inspect.signature(BASES[base].__init__).parameters
                 if k not in ("self", "effects", "fixed", "axis", "out_of_range")]
        unknown = [k for k in settings if k not in known]
        if unknown:
            raise ModelError(f"--set {unknown[0]}: model '{base}' has no such setting; it has {', '.join(known) or 'none'}")
    return settings
