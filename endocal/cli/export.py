"""``endocal export c|mcap``: a model's compensator as C99 source; a run as an MCAP file."""

from __future__ import annotations

import json
import shlex
from pathlib import Path
from typing import Optional

import typer

from endocal.cli._common import cli_errors, err, fail, out, refuse_input_as_output
from endocal.cli._effects_file import effects_file_option, use_effects_files
from endocal.cli.messages import keyed

app = typer.Typer(help="Take endocal's results where robotics people use them: a model's compensator as C99 "
                       "source (`export c`), a run as an MCAP file for Foxglove and PlotJuggler (`export mcap`).",
                  no_args_is_help=True)


@app.command("c")
@cli_errors
def export_c_cmd(
    model_path: Path = typer.Argument(..., help="Model file (endocal fit hysteresis --out)."),
    out_dir: Path = typer.Option(..., "--out", "-o", help="Folder for NAME.h and NAME.c (created if missing)."),
    use_float: bool = typer.Option(False, "--float", help="Generate float arithmetic (default double): for a "
                                   "microcontroller with a single-precision FPU; agrees with Python to ~1e-4 deg."),
    loop_hz: Optional[float] = typer.Option(None, "--loop-hz", help="The control loop's rate (Hz), e.g. 1000. "
                                            "Required for a model with a time-based effect (rate, creep), which is "
                                            "discretised for it."),
    name: Optional[str] = typer.Option(None, "--name", help="C identifier prefix and file stem (default "
                                       "endocal_<axis>): NAME_state, NAME_init, NAME_step."),
    force: bool = typer.Option(False, "--force", help="Overwrite NAME.h and NAME.c."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (name, real, chain, dt_s, cmd_range, "
                                 "warnings, files)."),
    effects_files: list[Path] = effects_file_option(),
) -> None:
    """Write the model's streaming compensator as C99: a header and a source with a state struct,
    NAME_init and NAME_step(desired_deg) -> knob command, one call per control tick.

    No allocation, no dependency but <math.h>. It implements the inverse of the fitted model
    with its effects, as the Python compensator does (the same commands to 1e-9 deg in double).
    An effect that cannot be compensated one sample at a time (delay, load, coupling, drift)
    is refused, and nothing is written.
    """
    from endocal.export.c import export_c

    use_effects_files(effects_files)
    comp = export_c(model_path, out_dir, real="float" if use_float else "double", loop_hz=loop_hz, name=name,
                    force=force)
    h_path, c_path = comp.files
    if as_json:
        out.print_json(json.dumps(comp.to_dict()))
        return
    for key, text in comp.warnings:
        err.print(keyed(text, "warning", key), markup=False)
    period = f", loop period {comp.dt_s:g} s" if comp.dt_s else ""
    out.print(f"wrote {h_path} and {c_path}: {comp.name}_step in {comp.real}, {' -> '.join(comp.chain)}{period}; "
              f"commands clamped to [{comp.cmd_range[0]:g}, {comp.cmd_range[1]:g}] {comp.drive_unit}", markup=False)
    err.print(f"next: cc -std=c99 -O2 -c {shlex.quote(str(c_path))} and call {comp.name}_init once, "
              f"{comp.name}_step every tick (docs: how-to, export the compensator to C)", markup=False)


@app.command("mcap")
@cli_errors
def export_mcap_cmd(
    run: Path = typer.Argument(..., help="Run folder (endocal excite, import csv, import ros)."),
    out_path: Path = typer.Option(..., "--out", "-o", help="The .mcap file to write."),
    models: list[Path] = typer.Option([], "--model", help="Model file; adds its prediction on the run and the error "
                                      "as /model/<axis>. Repeat for each bending axis."),
    force: bool = typer.Option(False, "--force", help="Replace --out."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (path, channels, t_range_s, start_ns, "
                                 "incomplete, notes)."),
    effects_files: list[Path] = effects_file_option(),
) -> None:
    """Write a run as one MCAP file that Foxglove and PlotJuggler open without ROS (JSON Schema
    channels): motor streams per degree of freedom, tracker poses as foxglove.PoseInFrame and
    FrameTransform (the 3-D panel shows the tip moving), the aligned table, run.json as metadata.

    A run that did not complete (interrupted, failed, killed) is exported as far as it is
    readable, and said so: one line and exit code 2, with the file written.
    Needs the mcap extra: pip install 'endocal-toolkit[mcap]'.
    """
    from endocal.export.mcap import export_mcap

    use_effects_files(effects_files)
    refuse_input_as_output("--out", out_path, [run, *models, run / "run.json", run / "aligned.parquet"])
    res = export_mcap(run, out_path, models=models, force=force)
    span = f"t_s {res.t_range_s[0]:.2f}..{res.t_range_s[1]:.2f}"
    if as_json:
        out.print_json(json.dumps(res.to_dict()))
    else:
        _print_mcap(res, span)
    if res.incomplete:
        fail(f"{res.incomplete}; {res.path} holds the run as far as it is readable ({span}), and its metadata "
             "(endocal.export) says so")


def _print_mcap(res, span: str) -> None:
    out.print(f"wrote {res.path}: {res.messages} messages on {len(res.channels)} channels ({span}): "
              + ", ".join(f"{topic} {n}" for topic, n in res.channels.items()), markup=False)
    for note in res.notes:
        out.print(f"note: {note}", markup=False)
