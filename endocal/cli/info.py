"""``endocal info``: what a run folder or aligned table holds."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from endocal.cli._common import cli_errors, out


@cli_errors
def info(
    data: Path = typer.Argument(..., help="A run folder, or an aligned table (.parquet / .csv)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of a table."),
) -> None:
    """Show what a run or aligned table holds: axes, span, ranges, reversals, status.

    The table is checked as every later command checks it, so this is also the quickest
    way to see whether data recorded elsewhere follows the run format.
    """
    from rich.table import Table

    from endocal.runs.summary import summarize

    s = summarize(data)
    if as_json:
        out.print_json(json.dumps(s.to_dict()))
        return
    head = f"{s.source}: {s.rows} rows, {s.duration_s:.1f} s at {s.rate_hz:.1f} Hz"
    if s.status:
        head += f"; run {s.status}, protocol {s.protocol}, backend {s.backend}, seed {s.seed}"
    out.print(head)
    one = len({a.drive_unit for a in s.axes}) == 1  # a knob in deg, a linear drive in mm
    table = Table("axis", f"command ({s.axes[0].drive_unit})" if one else "command", "measured (deg)", "reversals")
    for a in s.axes:
        table.add_row(
            a.axis,
            f"{a.cmd_range_deg[0]:.1f} .. {a.cmd_range_deg[1]:.1f}" + ("" if one else f" {a.drive_unit}"),
            f"{a.meas_range_deg[0]:.1f} .. {a.meas_range_deg[1]:.1f}",
            str(a.reversals),
        )
    out.print(table)
    if s.extras:
        out.print("other columns: " + ", ".join(s.extras))
    if s.counts:
        out.print("counts: " + ", ".join(f"{k}={v}" for k, v in s.counts.items()))
