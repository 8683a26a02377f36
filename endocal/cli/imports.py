"""`endocal import csv|ros`: turn logs recorded elsewhere into run folders."""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from endocal.cli._common import cli_errors, err, out
from endocal.cli.ros import import_ros

app = typer.Typer(help="Turn logs recorded elsewhere (a lab's CSV, a ROS bag) into run folders.", no_args_is_help=True)
app.command("ros")(import_ros)


@app.command("csv")
@cli_errors
def import_csv_cmd(
    log: Path = typer.Argument(..., help="The CSV log (one header row; a row per sample)."),
    map_path: Path = typer.Option(..., "--map", help="TOML map naming its columns and units; see configs/csv-map.example.toml."),
    out_dir: Path = typer.Option(..., "--out", "-o", help="Run folder to create; a .parquet or .csv aligned table when the map gives measured [angles] instead of poses."),
    dedupe: bool = typer.Option(False, "--dedupe", help="Drop rows that repeat an earlier row exactly (ROS bridges write them) and merge rows of one time stamp that fill different columns (a motor tick and a tracker frame in the same millisecond); without it duplicated time stamps are refused."),
    force: bool = typer.Option(False, "--force", help="Replace --out if it is a run folder (or the table an angles map writes)."),
) -> None:
    """Convert a lab's CSV log into a run folder: knob positions (deg, rad or servo ticks),
    optional goals and currents, tip and base EM poses (mm or m, quaternions xyzw or wxyz).

    Bending angles come from the poses by thesis eq. 1, as for endocal's own runs; every later
    command reads the folder like a run of `endocal excite`. A rig that measures the angle
    itself (an encoder, a camera) maps [angles.AXIS] columns instead, and gets an aligned table.
    """
    from endocal.runs.csvlog import import_csv

    res = import_csv(log, map_path, out_dir, dedupe=dedupe, force=force, command="endocal " + " ".join(sys.argv[1:]))
    rate = f"{res.rate_hz:.1f} Hz" if res.rate_hz else "one sample"
    measured = "angle readings" if res.angles_measured else "tracker frames"
    out.print(f"imported {log} -> {res.run_dir}: {res.rows} rows, {res.motor_rows} motor samples over "
              f"{res.duration_s:.2f} s ({rate}), {res.tracker_frames} {measured}, {res.aligned_rows} aligned rows",
              markup=False)
    out.print("columns: " + ", ".join(f"{k} <- {v}" for k, v in res.columns.items()), markup=False)
    if res.duplicates_dropped:
        err.print(f"note: --dedupe dropped {res.duplicates_dropped} row(s) repeating an earlier row exactly")
    if res.rows_merged:
        err.print(f"note: --dedupe merged {res.rows_merged} row(s) into an earlier row of the same time stamp "
                  "(different columns filled)")
    if res.alignment_error:
        err.print(f"warning: no aligned table: {res.alignment_error}")
