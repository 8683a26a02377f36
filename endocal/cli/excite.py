"""``endocal excite``: play an excitation protocol on the simulator or the robot and log a run."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional

import typer

from endocal.cli._common import (
    OUT_OF_RANGE_HELP,
    apply_out_of_range,
    cli_errors,
    err,
    fail,
    guard_factory,
    out,
    warnings_as_lines,
)
from endocal.cli._effects_file import effects_file_option, use_effects_files


@cli_errors
def excite(
    protocol: str = typer.Argument(..., help="Protocol name (see `endocal protocols`) or a protocol .toml file."),
    out_dir: Path = typer.Option(..., "--out", "-o", help="Run folder to create."),
    backend: str = typer.Option("sim", "--backend", "-b", help="`sim` (physics simulator) or `hardware` (the robot)."),
    probe: str = typer.Option("tee", "--probe", help="Probe preset (`tee`: ap/ml, `duodenoscope`: ud/lr) or a probe .toml."),
    sim_config: Optional[Path] = typer.Option(None, "--sim-config", help="Simulator TOML (effects and physics); see configs/sim-default.toml."),
    hardware_config: Optional[Path] = typer.Option(None, "--hardware-config", help="Rig TOML for --backend hardware; see configs/hardware-example.toml."),
    seed: int = typer.Option(0, "--seed", help="Seed of every random draw (simulator noise, random protocols)."),
    realtime: bool = typer.Option(False, "--realtime", help="Pace the simulator to the wall clock (hardware always is)."),
    force: bool = typer.Option(False, "--force", help="Replace --out if it exists."),
    sets: list[str] = typer.Option([], "--set", help="Override a protocol parameter, e.g. --set frequency_hz=0.1 (repeatable)."),
    amplitude: Optional[float] = typer.Option(None, "--amplitude", help="Shortcut for --set amplitude_deg=VALUE."),
    offset: Optional[float] = typer.Option(None, "--offset", help="Shortcut for --set offset_deg=VALUE."),
    duration: Optional[float] = typer.Option(None, "--duration", help="Shortcut for --set duration_s=VALUE (protocols with a free duration; periodic ones take --set cycles=N)."),
    sample_rate: Optional[float] = typer.Option(None, "--sample-rate", help="Shortcut for --set sample_rate_hz=VALUE (motor clock)."),
    axes: Optional[str] = typer.Option(None, "--axes", help="Comma-separated axes to drive, e.g. `ml` or `ap,ml`."),
    planes_file: Optional[Path] = typer.Option(None, "--planes", help="planes.json from `endocal fit planes`: pass the knob goals through the orthogonal compensator."),
    model_files: list[Path] = typer.Option([], "--model", help="Hysteresis model (endocal fit hysteresis) of one axis, repeatable: the protocol's goals become desired bending angles played through the inverse models (task-space control)."),
    out_of_range: Optional[str] = typer.Option(None, "--out-of-range", help="With --model: " + OUT_OF_RANGE_HELP),
    force_model: Optional[Path] = typer.Option(None, "--force-model", help="force.json (endocal fit force): guard the run, checking the predicted tip force every tick."),
    max_force_n: Optional[float] = typer.Option(None, "--max-force-n", help="With --force-model: stop bending further into the load when the predicted tip force reaches this (N)."),
    tip_load_n: Optional[float] = typer.Option(None, "--tip-load-n", help="Known load hung at the tip (N), opposing positive bending of the protocol's first axis: recorded for `fit force`; the simulator hangs it."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
    effects_files: list[Path] = effects_file_option(),
) -> None:
    """Run an excitation protocol and log motor and tracker streams to a run folder.

    The simulator (the default backend) runs as fast as it can; `--realtime` paces it.
    Ctrl-C stops cleanly and leaves a valid run (status `interrupted` in run.json).
    """
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    from endocal.backends.registry import make_backend
    from endocal.errors import StopSignal
    from endocal.excite import prepare_backend, run_excitation
    from endocal.probe import load_probe
    from endocal.protocols import load_protocol, parse_overrides

    use_effects_files(effects_files)  # before the models that use them and the sim config that hides them
    overrides = parse_overrides(sets)
    known = {q.name for q in load_protocol(protocol).spec.params}
    for flag, key, value in (("--amplitude", "amplitude_deg", amplitude), ("--offset", "offset_deg", offset),
                             ("--duration", "duration_s", duration), ("--sample-rate", "sample_rate_hz", sample_rate)):
        if value is not None:
            if key not in known:
                from endocal.errors import ProtocolError

                raise ProtocolError(f"{flag} sets {key}, which protocol '{protocol}' does not have (it has "
                                    f"{', '.join(sorted(known))}): use --set NAME=VALUE with one of those")
            overrides[key] = value
    if axes is not None:
        overrides["axes"] = [a.strip() for a in axes.split(",") if a.strip()]

    probe_cfg = load_probe(probe)
    proto = load_protocol(protocol, overrides=overrides or None)
    proto.check_conditions()  # a condition only the user can set is asked for before anything moves
    trajectory = proto.trajectory(probe_cfg, seed=seed)
    protocol_info = proto.to_dict()
    planes = None
    if planes_file is not None:
        from endocal.planes import load_planes

        planes = load_planes(planes_file)
        protocol_info["orthogonal_compensation"] = str(planes_file)
    if model_files:
        from endocal.errors import ModelError
        from endocal.models import load_model
        from endocal.validation.playback import PREROLL_S, task_space_trajectory

        models = {}
        for path in model_files:
            model = load_model(path)
            apply_out_of_range(model, out_of_range)
            if model.axis in models:
                raise ModelError(f"two --model files for axis '{model.axis}' ({path}): give one per axis")
            models[model.axis] = model
        with warnings_as_lines():
            trajectory = task_space_trajectory(trajectory, probe_cfg, models, planes)
        protocol_info["hysteresis_compensation"] = {axis: str(p) for axis, p in zip(models, model_files)}
        protocol_info["out_of_range"] = {axis: m.out_of_range for axis, m in models.items()}
        protocol_info["preroll_s"] = PREROLL_S  # the protocol starts this much after t_s = 0
    elif out_of_range is not None:
        fail("--out-of-range applies to the inverse hysteresis models: use it with --model")
    elif planes is not None:
        from endocal.planes.from_runs import compensate_trajectory

        trajectory = compensate_trajectory(trajectory, probe_cfg, planes)
    trajectory.check_limits(probe_cfg)  # before any backend is built or anything moves
    make_guard = guard_factory(force_model, max_force_n, probe_cfg)
    guard = make_guard() if make_guard is not None else None
    if guard is not None:
        protocol_info["force_model"] = str(force_model)
    be = make_backend(backend, probe_cfg, seed=seed, sim_config=sim_config, hardware_config=hardware_config)
    be, record = prepare_backend(be, proto, probe_cfg, tip_load_n=tip_load_n)
    protocol_info.update(record)
    command = "endocal " + " ".join(sys.argv[1:])

    show = not quiet and err.is_terminal
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:.0f}/{task.total:.0f} s"),
        TimeRemainingColumn(),
        console=err.console,
        disable=not show,
        transient=True,
    ) as bar:
        task = bar.add_task(f"{proto.name} on {be.name}", total=trajectory.duration_s)
        try:
            result = run_excitation(
                trajectory,
                be,
                probe_cfg,
                out_dir,
                protocol_info=protocol_info,
                seed=seed,
                realtime=realtime,
                force=force,
                command=command,
                progress=lambda done, total: bar.update(task, completed=done),
                guard=guard,
            )
        except StopSignal as exc:  # torque is off; the run so far is on disk
            kept = (f"the run in {out_dir} is kept (status interrupted in run.json)" if (out_dir / "run.json").is_file()
                    else "nothing was logged")
            fail(f"stopped by {exc.signame}: torque is off; {kept}", code=exc.code)
    speed = f", {result.speed_x_realtime:,.0f}x real time" if result.wall_s > 0 else ""
    out.print(
        f"run {result.status}: {result.run_dir} ({result.logged_s:.1f} of {result.planned_s:.1f} s logged, "
        f"{result.motor_rows} motor ticks, {result.tracker_rows} tracker frames, {result.aligned_rows} aligned rows{speed})"
    )
    if guard is not None:
        stops = [e for e in result.events if e["kind"] == "stop"]
        out.print(f"force guard ({guard.axis}, {guard.max_force_n:g} N): {len(stops)} stop(s)")
        for e in result.events:
            pred = "predicted -" if e["force_pred_n"] is None else f"predicted {e['force_pred_n']:.3f} N"
            out.print(f"  t = {e['t_s']:.2f} s  {e['kind']:<7}  {pred}  "
                      f"{e['axis']} = {e['knob_deg'][e['axis']]:.2f} deg", markup=False)
    if result.alignment_error:
        err.print(f"warning: no aligned table: {result.alignment_error}")
    if result.status == "interrupted":
        fail(f"interrupted: the run in {result.run_dir} is valid up to t = {result.logged_s:.1f} s", code=130)
