"""``endocal check``: is this probe still within its calibration? One line, an exit code for cron."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from endocal.cli._common import cli_errors, err, fail, out


@cli_errors
def check(
    model_files: list[Path] = typer.Option([], "--model", "-m", help="The probe's hysteresis model (endocal fit "
                                           "hysteresis), one per bending axis (repeatable). With --run RUN... of "
                                           "several probes: each probe's models on record in its history."),
    probe_id: Optional[str] = typer.Option(None, "--probe-id", help="The probe's own ID (its serial number, e.g. "
                                           "TEE-0042): its partition of the history. With several --run: from each "
                                           "run's run.json."),
    history: Path = typer.Option(..., "--history", help="The fleet's history folder (a Parquet dataset, "
                                 "probe=ID/month=YYYY-MM; created on the first check)."),
    runs: list[Path] = typer.Option([], "--run", help="Score a check recorded earlier or imported instead of running "
                                    "one (repeatable: one run per probe, scored as Dask tasks)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="With several --run: the address of a running "
                                            "Dask scheduler (tcp://host:8786); `synchronous` scores in this process. "
                                            "Default: a local cluster."),
    backend: str = typer.Option("sim", "--backend", "-b", help="`sim` (physics simulator) or `hardware` (the robot)."),
    probe: str = typer.Option("tee", "--probe", help="Probe preset (`tee`, `duodenoscope`) or a probe .toml."),
    sim_config: Optional[Path] = typer.Option(None, "--sim-config", help="Simulator TOML (see configs/sim-default.toml)."),
    hardware_config: Optional[Path] = typer.Option(None, "--hardware-config", help="Rig TOML for --backend hardware."),
    seed: int = typer.Option(0, "--seed", help="Seed of the simulator's noise."),
    realtime: bool = typer.Option(False, "--realtime", help="Pace the simulator to the wall clock (hardware always is)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object (a list with several --run)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
) -> None:
    """Check a probe's calibration in 90 seconds: play the built-in `check` protocol (both knobs, inside the
    model's fitted range), score it against the probe's models (validation RMSE, loop width, dead band, bend
    reached each way), append it to the probe's history and chart it.

    Prints one line: `in control`, `drifting` (an EWMA beyond its limit) or `out of control` (a point beyond 3
    sigma), with the checks since calibration (the first 10 set the limits: `baseline`), and the commands that
    recalibrate the probe when it is out. Exit code 0 in control (or baseline), 4 drifting or out of control, 2 bad
    input: nothing is appended then.
    """
    if runs:
        from endocal.check.batch import check_runs

        if len(runs) > 1 and scheduler is None and not as_json and err.is_terminal and not quiet:
            err.print(f"scoring {len(runs)} runs on a local Dask cluster", markup=False)
        results = check_runs(runs, history, probe_id=probe_id, models=model_files, scheduler=scheduler)
    else:
        if probe_id is None:
            fail("--probe-id is missing: give the probe's ID (e.g. --probe-id TEE-0042), its partition of the history")
        if scheduler is not None:
            fail("--scheduler applies to scoring recorded runs: use it with --run RUN...")
        results = [_run_check(model_files, probe_id, history, backend=backend, probe=probe, seed=seed,
                              sim_config=sim_config, hardware_config=hardware_config, realtime=realtime, quiet=quiet)]
    code = max(r.exit_code for r in results)
    if as_json:
        import json

        from endocal.cli._common import finite

        d = [r.to_dict() for r in results]
        out.print_json(json.dumps(finite(d[0] if len(d) == 1 and not len(runs) > 1 else d)))
    else:
        for r in results:
            out.print(r.line(), markup=False)
            if r.recalibrate:
                out.print(f"recalibrate {r.probe_id}:", markup=False)
                for c in r.recalibrate:
                    out.print(f"  {c}", markup=False)
    raise typer.Exit(code)


def _run_check(model_files, probe_id, history, *, quiet: bool, **kwargs):
    from rich.progress import BarColumn, Progress, TextColumn

    from endocal.check.run import check_probe

    with Progress(TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.completed:.0f}/{task.total:.0f} s"),
                  console=err.console, disable=quiet or not err.is_terminal, transient=True) as bar:
        task = bar.add_task(f"check {probe_id}", total=None)
        return check_probe(model_files, probe_id, history,
                           progress=lambda done, total: bar.update(task, completed=done, total=total), **kwargs)
