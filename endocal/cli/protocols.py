"""``endocal protocols``: list the excitation protocols, show one, plot one to PNG."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import typer

from endocal.cli._common import cli_errors, err, out
from endocal.probe import load_probe

app = typer.Typer(
    name="protocols",
    help="List the excitation protocols, show one's parameters, or plot its goals to PNG.\n\n"
    "Protocols are TOML files in ./protocols (first) and the shipped set; see protocols/README.md.",
    invoke_without_command=True,
    no_args_is_help=False,
    add_completion=False,
    pretty_exceptions_enable=False,
)

_SET_HELP = "Override a parameter, e.g. --set amplitude_deg=40 or --set axes=['ml'] (repeatable)."
_PROBE_HELP = "Probe preset (`tee`: ap/ml, `duodenoscope`: ud/lr) or a probe .toml; resolves axis1/axis2."


def _value(v: Any) -> str:
    """A parameter value as it would be written in a protocol file."""
    if v is None:
        return "(unset)"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return repr(v)


@app.callback(invoke_without_command=True)
@cli_errors
def _list(ctx: typer.Context) -> None:
    """List the protocols: name, duration, axes and what each is for."""
    if ctx.invoked_subcommand is not None:  # (before the import: `protocols show --help` stays instant)
        return
    from endocal.protocols import list_protocols, load_protocol, protocol_dirs

    rows = []
    for name, description, _path in list_protocols():
        proto = load_protocol(name)
        rows.append((name, f"{proto.duration_s:g} s", ", ".join(proto.params["axes"]), description))
    if not rows:
        out.print("no protocols found (looked in: " + ", ".join(map(str, protocol_dirs())) + ")", markup=False)
        return
    head = ("name", "duration", "axes", "description")
    widths = [max(len(r[i]) for r in [head, *rows]) for i in range(3)]
    for r in [head, *rows]:
        out.print("  ".join(c.ljust(w) for c, w in zip(r[:3], widths)) + "  " + r[3], markup=False)
    out.print("\nShow one: endocal protocols show NAME; plot one: endocal protocols plot NAME --out FILE.png", markup=False)


@app.command("show")
@cli_errors
def show(
    name: str = typer.Argument(..., help="Protocol name or a protocol .toml file."),
    sets: list[str] = typer.Option([], "--set", help=_SET_HELP),
    probe: str = typer.Option("tee", "--probe", help=_PROBE_HELP),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of text."),
) -> None:
    """Print a protocol's parameters (defaults, file values and overrides), its source and duration."""
    from endocal.protocols import load_protocol, parse_overrides

    overrides = parse_overrides(sets)
    proto = load_protocol(name, overrides=overrides or None)
    probe_cfg = load_probe(probe)
    traj = proto.trajectory(probe_cfg)
    axes = proto.resolved_axes(probe_cfg)
    if as_json:
        info = proto.to_dict()
        info.update(duration_s=traj.duration_s, n_samples=traj.n_samples, probe=probe_cfg.name, dofs=axes)
        out.print(json.dumps(info, indent=2), markup=False)
        return
    spec = proto.spec
    lines = [
        f"{proto.name}: {proto.description}",
        f"signal    {proto.signal}",
        f"source    {proto.source_path}",
        f"sha256    {proto.sha256}",
        f"duration  {traj.duration_s:g} s ({traj.n_samples} samples at {traj.sample_rate_hz:g} Hz)",
        f"axes      {', '.join(f'{a} -> {d}' if a != d else d for a, d in zip(proto.params['axes'], axes))} "
        f"(probe {probe_cfg.name})",
        "parameters",
    ]
    shown = {k: v for k, v in proto.params.items() if k != "segments"}
    width = max(len(f"{k} = {_value(v)}") for k, v in shown.items())
    for q in spec.params:
        mark = "  (override)" if q.name in proto.overrides else ""
        if q.name == "segments":  # a sequence: one line per segment, its parameters as the file sets them
            lines.append(f"  segments  # {q.doc}{mark}")
            for i, seg in enumerate(proto.params["segments"], 1):
                lines.append(f"    {i}. {seg['signal']}: " + ", ".join(f"{k} = {_value(v)}" for k, v in seg.items()
                                                                       if k != "signal"))
            continue
        text = f"{q.name} = {_value(proto.params[q.name])}"
        lines.append(f"  {text.ljust(width)}  # {q.doc}{mark}")
    for cname, cond in proto.conditions.items():
        value = proto.condition_values.get(cname)
        lines.append(f"condition {cname} = {'(give it: --set ' + cname + '=VALUE)' if value is None else f'{value:g}'}"
                     f"  # {cond['instruction']}")
    if proto.design.get("suspects"):
        lines.append(f"designed  to test {', '.join(map(str, proto.design['suspects']))}")
    out.print("\n".join(lines), markup=False)


@app.command("plot")
@cli_errors
def plot(
    name: str = typer.Argument(..., help="Protocol name or a protocol .toml file."),
    out_png: Path = typer.Option(..., "--out", "-o", help="PNG file to write."),
    probe: str = typer.Option("tee", "--probe", help=_PROBE_HELP),
    sets: list[str] = typer.Option([], "--set", help=_SET_HELP),
) -> None:
    """Draw goal against time for every moving degree of freedom, with the probe's limits dashed.

    A protocol beyond the probe's limits is still drawn (to show where), with a warning.
    """
    from endocal.errors import LimitError
    from endocal.protocols import load_protocol, parse_overrides
    from endocal.protocols.plot import plot_trajectory

    overrides = parse_overrides(sets)
    proto = load_protocol(name, overrides=overrides or None)
    probe_cfg = load_probe(probe)
    traj = proto.trajectory(probe_cfg)
    try:
        traj.check_limits(probe_cfg)
    except LimitError as exc:
        err.print(f"warning: {exc}", markup=False)
    path = plot_trajectory(traj, out_png, probe=probe_cfg)
    out.print(f"wrote {path} ({proto.name}, {traj.duration_s:g} s, moving: {', '.join(traj.moving_dofs) or 'nothing'})",
              markup=False)
