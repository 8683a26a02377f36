"""Write the CSV logs the README's `endocal import csv` examples read, from one simulated run.

    .venv/bin/python scripts/make_example_logs.py [DIR]      # DIR: default TMPDIR/endocal-examples

DIR defaults to a folder outside the repository (``endocal-examples`` in the system's temporary
folder, printed), so that neither the script nor the commands run on its logs write into a
checkout.

The run is the one tests/test_import_csv.py logs (a 20 s lissajous, seed 4, both knobs moving),
written out three ways, as labs log:

- lab_log.csv: a rig with servos and an EM tracker, the columns of configs/csv-map.example.toml
  (time in ms from a clock that does not start at 0, knob positions and goals in servo ticks,
  poses in metres with scalar-first quaternions, separate motor and tracker rows); one row is
  written twice, as a logger that repeats a message does;
- bench_log.csv: a bench that reads its bending angle itself, the columns of
  configs/csv-map.angles.example.toml (motor in rad, joint angle in deg read at every other
  motor sample, the sheath's configuration);
- rig_log.csv: the same bench with bare column names (Time, knob, TipAngle, sheath) and no map,
  for `--draft-map`.

The two example maps are copied to DIR/configs/, so the how-to's commands (`endocal import csv
lab_log.csv --map configs/csv-map.example.toml ...`), run in DIR, run as written and print what it
shows. The simulated run itself is left in DIR/example-run.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from endocal.runs.aligned import load_aligned, read_stream

TICKS_PER_DEG = 4096 / 360.0
REPO = Path(__file__).resolve().parents[1]
#: The example maps the how-to's commands name (configs/...), copied beside the logs.
MAPS = ("csv-map.example.toml", "csv-map.angles.example.toml")


def default_dir() -> Path:
    """Where the logs go without DIR: outside any checkout, in the system's temporary folder."""
    return Path(tempfile.gettempdir()) / "endocal-examples"


def lab_log(motor: pd.DataFrame, tracker: pd.DataFrame, whole_ticks: bool = True) -> pd.DataFrame:
    """A run's motor and tracker streams as configs/csv-map.example.toml's lab logs them: motor
    rows and tracker rows on one clock in ms (from 12.5 s), a tick and a frame of the same
    instant on one row; ticks as a servo reports them (whole), or exact for a round trip."""
    ticks = np.round if whole_ticks else (lambda v: v)
    rows = pd.DataFrame({"stamp_ms": 1000.0 * (motor["t_s"] + 12.5)})
    for axis in ("ap", "ml"):
        rows[f"{axis}_present_ticks"] = ticks(2048 + motor[f"{axis}_pos_deg"] * TICKS_PER_DEG)
        rows[f"{axis}_goal_ticks"] = ticks(2048 + motor[f"{axis}_goal_deg"] * TICKS_PER_DEG)
    rows["ap_current_ma"] = motor["ap_current_ma"]
    frames = []
    for sensor in ("tip", "base"):
        f = tracker[tracker["sensor"] == sensor].set_index("t_s")
        frames.append(pd.DataFrame({f"{sensor}_x_m": f["x_mm"] / 1000, f"{sensor}_y_m": f["y_mm"] / 1000,
                                    f"{sensor}_z_m": f["z_mm"] / 1000, f"{sensor}_qw": f["qw"],
                                    f"{sensor}_qx": f["qx"], f"{sensor}_qy": f["qy"], f"{sensor}_qz": f["qz"]}))
    poses = pd.concat(frames, axis=1).reset_index()
    poses.insert(0, "stamp_ms", 1000.0 * (poses.pop("t_s") + 12.5))
    log = pd.concat([rows, poses], ignore_index=True).sort_values("stamp_ms", kind="stable")
    return log.groupby("stamp_ms", as_index=False, sort=True).first()


#: The simulated run the logs are written from: `endocal excite` and these arguments.
EXCITE = ["excite", "lissajous", "--set", "duration_s=20", "--seed", "4", "--force", "--quiet"]


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    run = out / "example-run"
    subprocess.run([sys.executable, "-m", "endocal", *EXCITE, "--out", str(run)], check=True)
    write_logs(run, out)


def write_logs(run: Path, out: Path) -> None:
    """The three logs of the run folder ``run``, and the example maps, into ``out``."""
    log = lab_log(read_stream(run, "motor"), read_stream(run, "tracker"))
    repeat = 101  # the row of stamp 13340 ms (line 103), written again on line 104
    log = pd.concat([log.iloc[:repeat + 1], log.iloc[repeat:repeat + 1], log.iloc[repeat + 1:]], ignore_index=True)
    log.to_csv(out / "lab_log.csv", index=False)

    # bench_log.csv and rig_log.csv: knob command and measured angle of the aligned table
    a = load_aligned(run).table
    bench = pd.DataFrame({"time_ms": 1000.0 * a["t_s"], "motor_rad": np.deg2rad(a["ap_cmd_deg"]),
                          "joint_deg": a["ap_meas_deg"], "sheath_deg": 180.0})
    bench.loc[1::2, "joint_deg"] = np.nan  # the encoder read at half the motor rate
    bench.to_csv(out / "bench_log.csv", index=False)
    pd.DataFrame({"Time": a["t_s"], "knob": np.deg2rad(a["ap_cmd_deg"]), "TipAngle": a["ap_meas_deg"],
                  "sheath": 180.0}).to_csv(out / "rig_log.csv", index=False)
    (out / "configs").mkdir(exist_ok=True)
    for name in MAPS:
        shutil.copyfile(REPO / "configs" / name, out / "configs" / name)
    print(f"wrote lab_log.csv, bench_log.csv, rig_log.csv and configs/ (the example maps) in {out}, from the simulated "
          f"run {run} logged as three rigs would; run the how-to's commands there: cd {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else default_dir())
