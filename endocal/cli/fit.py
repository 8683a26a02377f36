"""``endocal fit``: fit bending planes and hysteresis models to runs."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from endocal.cli._common import cli_errors, err, out
from endocal.errors import OutputExistsError

app = typer.Typer(help="Fit bending planes (`fit planes`) and hysteresis models (`fit hysteresis`).", no_args_is_help=True)


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
) -> None:
    """Fit the four half-planes (duodenoscope eqs. 1-2), the thesis's twist delta and the orthogonal compensator.

    Prints the deviation angles alpha_y+, alpha_y-, alpha_x+, alpha_x- and delta with 95 %
    bootstrap confidence intervals, the residual deviations after compensation, and which
    sweeps were used. Later commands take the file with `--planes planes.json`.
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
    by_half: dict[str, list[str]] = {}
    for sweep in cal.sweeps_used:
        by_half.setdefault(sweep["half_plane"], []).append(f"{sweep['run']}#{sweep['index']}")
    out.print("sweeps used: " + "; ".join(f"{h}: {', '.join(v)}" for h, v in sorted(by_half.items())), markup=False)
    err.print(f"wrote {out_path}")
