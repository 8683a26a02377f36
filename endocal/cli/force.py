"""``endocal fit force``: contact-force model from unloaded and loaded calibration runs."""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path
from typing import Optional

import typer

from endocal.cli._common import cli_errors, err, out, refuse_input_as_output
from endocal.cli.messages import EXPLAIN_HELP
from endocal.errors import OutputExistsError


@cli_errors
def fit_force_cmd(
    runs: list[Path] = typer.Argument(..., help="force-calibration run folders: unloaded ones and ones with --tip-load-n."),
    out_path: Path = typer.Option(..., "--out", "-o", help="force.json to write (versioned JSON)."),
    axis: Optional[str] = typer.Option(None, "--axis", "-a", help="Bending axis (default: the one the runs' loads name)."),
    torque_constant: Optional[float] = typer.Option(None, "--torque-constant", help="Motor torque per current (N*m/A); default: the simulator's, from run.json."),
    force: bool = typer.Option(False, "--force", help="Overwrite --out."),
    as_json: bool = typer.Option(False, "--json", help="Print the model file's content as JSON."),
    explain: bool = typer.Option(False, "--explain", "-v", help=EXPLAIN_HELP + " Adds the held-out prediction of each loaded run."),
) -> None:
    """Fit the contact-force model M_knob = G * M_contact + M_r(theta) (duodenoscope paper, eqs. 12-15).

    M_r(theta) per direction of motion from the unloaded runs; G from the loaded ones, with the
    lever arm from constant curvature. Prints G with its standard error and the worst error of
    the force predicted on a loaded run by a model fitted without it (held out; each run's with
    `--explain`). `excite` and `validate --protocol`
    take the file with `--force-model force.json --max-force-n F`.
    """
    from endocal.force import fit_force, save_force_model
    from endocal.force.io import force_model_to_dict, force_provenance

    refuse_input_as_output("--out", out_path, runs)
    if out_path.exists() and not force:
        raise OutputExistsError(f"{out_path} already exists: choose another --out or pass --force")
    model = fit_force(runs, axis=axis, torque_constant_nm_per_a=torque_constant)
    provenance = force_provenance(runs, "endocal " + " ".join(sys.argv[1:]))
    save_force_model(model, out_path, provenance=provenance, force=force)
    if as_json:
        out.print_json(json.dumps(force_model_to_dict(model, provenance)))
        return
    out.print(str(model), markup=False)
    out.print(f"G = {model.g_:.3f} +- {model.g_se_:.3f} (standard error over passes) at knob {model.g_theta_ref_deg * model.side:+.0f} deg; "
              f"loads {', '.join(f'{v:g}' for v in model.loads_n)} N", markup=False)
    if explain:
        out.print("held-out prediction (each loaded run predicted by a model fitted without it):", markup=False)
        for h in model.heldout_:
            out.print(f"  {h.source}: load {h.load_n:.3f} N -> predicted {h.pred_mean_n:.3f} N "
                      f"(error {h.error_n:+.3f} N, {h.error_pct:+.1f} %; per tick rms {h.rms_error_n:.3f} N)",
                      markup=False)
    if model.heldout_:
        worst_n = max(model.heldout_, key=lambda h: abs(h.error_n))
        worst_pct = max(model.heldout_, key=lambda h: abs(h.error_pct))
        out.print(f"worst held-out error {abs(worst_n.error_n):.3f} N ({worst_n.source}), "
                  f"{abs(worst_pct.error_pct):.1f} % ({worst_pct.source})", markup=False)
    err.print(f"wrote {out_path}")
    err.print(f"next: endocal validate MODEL.json --protocol PROTOCOL --force-model {shlex.quote(str(out_path))} "
              "--max-force-n F (a playback guarded by the predicted tip force)", markup=False)
