"""`endocal import csv|ros`: turn logs recorded elsewhere into run folders."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Optional

import typer

from endocal.cli._common import cli_errors, err, out, refuse_input_as_output
from endocal.cli.messages import EXPLAIN_HELP, keyed_lines
from endocal.cli.ros import import_ros

app = typer.Typer(help="Turn logs recorded elsewhere (a lab's CSV, a ROS bag) into run folders.", no_args_is_help=True)
app.command("ros")(import_ros)


@app.command("csv")
@cli_errors
def import_csv_cmd(
    log: Path = typer.Argument(..., help="The CSV log (one header row; a row per sample)."),
    map_path: Optional[Path] = typer.Option(None, "--map", help="TOML map naming its columns and units; see configs/csv-map.example.toml (or draft one with --draft-map)."),
    out_dir: Optional[Path] = typer.Option(None, "--out", "-o", help="Run folder to create; a .parquet or .csv aligned table when the map gives measured [angles] instead of poses."),
    draft: Optional[Path] = typer.Option(None, "--draft-map", help="Instead of importing, write a first map for this log, guessed from its column names and numbers; every guess is marked CHECK."),
    dedupe: bool = typer.Option(False, "--dedupe", help="Drop rows that repeat an earlier row in every column the map uses (ROS bridges write them) and merge rows of one time stamp that fill different columns (a motor tick and a tracker frame in the same millisecond); columns the map does not use (a ROS header's arrival time, seq, frame_id) are not compared. Without it duplicated time stamps are refused."),
    force: bool = typer.Option(False, "--force", help="Replace --out if it is a run folder (or the table an angles map writes), or an existing --draft-map."),
    explain: bool = typer.Option(False, "--explain", "-v", help=EXPLAIN_HELP + " Adds which column became which."),
) -> None:
    """Convert a lab's CSV log into a run folder: knob positions (deg, rad or servo ticks) or a
    linear stage's tendon displacement (mm, m or um, kept in mm), optional goals and currents, tip and
    base EM poses (mm or m, quaternions xyzw or wxyz).

    Bending angles come from the poses by thesis eq. 1, as for endocal's own runs; every later
    command reads the folder like a run of `endocal excite`. A rig that measures the angle
    itself (an encoder, a camera) maps [angles.AXIS] columns instead, and gets an aligned table.

    No map yet? `--draft-map MAP.toml` writes one from the log's header and numbers (units
    told by the names, or by the values and marked CHECK), to read over before the import.
    """
    from endocal.errors import ConfigError
    from endocal.runs.csvlog import import_csv

    refuse_input_as_output("--out", out_dir, [log, map_path])
    refuse_input_as_output("--draft-map", draft, [log])
    if draft is not None:
        if map_path is not None or out_dir is not None:
            raise ConfigError("--draft-map writes a map and imports nothing: run it without --map and --out, then "
                              "import with the map it wrote")
        _draft(log, draft, force)
        return
    if map_path is None or out_dir is None:
        raise ConfigError(f"give --map MAP.toml and --out RUN (or --draft-map MAP.toml to have a first map guessed "
                          f"from {log.name})")

    res = import_csv(log, map_path, out_dir, dedupe=dedupe, force=force, command="endocal " + " ".join(sys.argv[1:]))
    rate = f"{res.rate_hz:.1f} Hz" if res.rate_hz else "one sample"
    measured = "angle readings" if res.angles_measured else "tracker frames"
    invalid = f" ({res.tracker_invalid} invalid, left out)" if res.tracker_invalid else ""
    out.print(f"imported {log} -> {res.run_dir}: {res.rows} rows, {res.motor_rows} motor samples over "
              f"{res.duration_s:.2f} s ({rate}), {res.tracker_frames} {measured}{invalid}, "
              f"{res.aligned_rows} aligned rows", markup=False)
    notes = [
        ("dedupe-dropped", f"--dedupe dropped {res.duplicates_dropped} row(s) repeating an earlier row in every column "
         "the map uses" if res.duplicates_dropped else ""),
        ("dedupe-merged", f"--dedupe merged {res.rows_merged} row(s) into an earlier row of the same time stamp "
         "(different columns filled)" if res.rows_merged else ""),
        ("incomplete-rows", f"{res.motor_rows_incomplete} row(s) with knob cells but not every knob position were left "
         f"out of the motor samples; the first at line {res.motor_rows_incomplete_line}"
         if res.motor_rows_incomplete else ""),
        ("invalid-frames", f"{res.tracker_invalid} tracker frame(s) were invalid (a sensor's cell empty, its quaternion "
         f"no rotation, or flagged by the map's valid column) and left out of the aligned table; the first at line "
         f"{res.tracker_invalid_line}" if res.tracker_invalid else ""),
        ("unused-rows", f"{res.rows_unused} row(s) held neither a motor sample nor a "
         f"{'reading' if res.angles_measured else 'pose'} in the mapped columns; the first at line "
         f"{res.rows_unused_line}" if res.rows_unused else ""),
    ]
    warns = [("gap", res.gap_warning or ""), *(("unit", w) for w in res.unit_warnings),
             ("no-aligned-table", f"no aligned table: {res.alignment_error}" if res.alignment_error else "")]
    if explain:
        out.print("columns: " + ", ".join(f"{k} <- {v}" for k, v in res.columns.items()), markup=False)
        for kind, messages in (("note", notes), ("warning", warns)):
            for _, text in messages:
                if text:
                    err.print(f"{kind}: {text}", markup=False)
    else:
        # a unit warning begins with the log's path, which the line above names
        warns = [(k, t.removeprefix(f"{log}: ")) for k, t in warns]
        for line in keyed_lines(notes, "note") + keyed_lines(warns):
            err.print(line, markup=False)
    if not res.alignment_error:
        err.print(_next_fit(res.run_dir, res.axes), markup=False)


def _next_fit(data: Path, axes: tuple[str, ...] = ()) -> str:
    """The next command after an import: fit the hysteresis of the records just written, on the
    axis the import found commanded and measured (the first, naming the others, when several)."""
    q = shlex.quote(str(data))
    if not axes:
        return f"next: endocal fit hysteresis {q} --axis AXIS --out MODEL.json (`endocal info {q}` names its axes)"
    others = f" (and --axis {' / '.join(axes[1:])}: one model per axis)" if len(axes) > 1 else ""
    return f"next: endocal fit hysteresis {q} --axis {axes[0]} --out MODEL.json{others}"


def _draft(log: Path, path: Path, force: bool) -> None:
    from endocal.runs.mapdraft import import_out, write_draft

    d = write_draft(log, path, force=force)
    out.print(f"drafted {path} for {log}:", markup=False)
    for role, cols in d.roles.items():
        out.print(f"  {role} <- {cols}", markup=False)
    for c in d.checks:
        out.print(f"  CHECK {c}", markup=False)
    for u in d.unmatched:
        out.print(f"  FILL IN {u}: no column looked like it", markup=False)
    # an [angles] map imports to an aligned table (a .parquet or .csv file), a map of EM poses to a run folder
    target = shlex.quote(str(import_out(log, d.angles)))
    dedupe = ""
    if d.repeated_stamps:
        out.print(f"  note: {d.repeated_stamps} row(s) repeat an earlier row's time stamp (ROS bridges write them, and "
                  "a motor tick and a frame may share a millisecond): the import needs --dedupe", markup=False)
        dedupe = " --dedupe"
    out.print(f"then: endocal import csv {shlex.quote(str(log))} --map {shlex.quote(str(path))} --out {target}{dedupe}",
              markup=False)
