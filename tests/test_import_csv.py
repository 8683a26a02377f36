"""`endocal import csv` (endocal/runs/csvlog.py, its checks in csvchecks.py): a lab's CSV log into a run folder.

Round trip: a simulated run is written out as a lab would log it, through the documented
example map (time in ms, knob positions and goals in servo ticks, poses in metres with
scalar-first quaternions, separate motor and tracker rows), imported back, and must give the
same aligned table: the bending angles computed again by thesis eq. 1 from the poses.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from endocal.runs.aligned import load_aligned, read_stream
from scripts.make_example_logs import TICKS_PER_DEG, lab_log
from tests._cli import endocal, one_line_exit_2

ROOT = Path(__file__).resolve().parents[1]
MAP = ROOT / "configs" / "csv-map.example.toml"


@pytest.fixture(scope="module")
def sim_log(tmp_path_factory):
    """A simulated run and the CSV log a lab would have written of it (the example map's columns)."""
    tmp = tmp_path_factory.mktemp("csv")
    proc = endocal("excite", "lissajous", "--set", "duration_s=20", "--out", tmp / "run", "--seed", "4", "-q")
    assert proc.returncode == 0, proc.stderr
    # the README's lab log (scripts/make_example_logs.py) with exact ticks, for a round trip
    log = lab_log(read_stream(tmp / "run", "motor"), read_stream(tmp / "run", "tracker"), whole_ticks=False)
    log.to_csv(tmp / "log.csv", index=False)
    return tmp


def test_round_trip_gives_the_same_aligned_table(sim_log):
    tmp = sim_log
    proc = endocal("import", "csv", tmp / "log.csv", "--map", MAP, "--out", tmp / "imported", "--explain")
    assert proc.returncode == 0, proc.stderr
    assert "motor samples" in proc.stdout and "ap <- ap_present_ticks" in proc.stdout
    a, b = load_aligned(tmp / "run").table, load_aligned(tmp / "imported").table
    assert len(a) == len(b)
    np.testing.assert_allclose(b["t_s"], a["t_s"], atol=1e-9)  # ms through float text: sub-nanosecond
    for axis in ("ap", "ml"):
        # ticks back to degrees: exact up to the CSV's 17 significant digits
        np.testing.assert_allclose(b[f"{axis}_cmd_deg"], a[f"{axis}_cmd_deg"], atol=1e-9)
        # eq. 1 again from poses written in metres: the same angles to 1e-9 deg
        np.testing.assert_allclose(b[f"{axis}_meas_deg"], a[f"{axis}_meas_deg"], atol=1e-9)
    np.testing.assert_allclose(b["ap_current_ma"], a["ap_current_ma"], atol=1e-9)
    meta = load_aligned(tmp / "imported").meta
    assert meta["backend"]["name"] == "csv-import" and meta["protocol"]["sha256"]
    assert meta["backend"]["command_source"] == "goal columns"


def test_a_log_saved_by_a_european_spreadsheet_imports_the_same(sim_log, tmp_path):
    # ';' between columns, ',' as the decimal mark, a space after each delimiter in the header
    tmp = sim_log
    log = pd.read_csv(tmp / "log.csv")
    text = log.to_csv(index=False, sep=";", decimal=",")
    header, body = text.split("\n", 1)
    (tmp_path / "eu.csv").write_text(header.replace(";", "; ") + "\n" + body)
    proc = endocal("import", "csv", tmp_path / "eu.csv", "--map", MAP, "--out", tmp_path / "eu")
    assert proc.returncode == 0, proc.stderr
    a, b = load_aligned(tmp / "run").table, load_aligned(tmp_path / "eu").table
    assert len(a) == len(b)
    for axis in ("ap", "ml"):
        np.testing.assert_allclose(b[f"{axis}_meas_deg"], a[f"{axis}_meas_deg"], atol=1e-9)


def test_duplicated_stamps_are_refused_or_dropped(sim_log, tmp_path):
    log = pd.read_csv(sim_log / "log.csv")
    # a bridge writing one row three times: data row 100 is on line 102, its repeats on 103 and 104
    rep = pd.concat([log.iloc[:101], log.iloc[100:101], log.iloc[100:101], log.iloc[101:]], ignore_index=True)
    rep.to_csv(tmp_path / "rep.csv", index=False)
    one_line_exit_2(endocal("import", "csv", tmp_path / "rep.csv", "--map", MAP, "--out", tmp_path / "r1"),
                    "2 row(s) repeat a time stamp", "line 103", "--dedupe")
    assert not (tmp_path / "r1").exists()
    ok = endocal("import", "csv", tmp_path / "rep.csv", "--map", MAP, "--out", tmp_path / "r2", "--dedupe")
    assert ok.returncode == 0 and "dropped 2 row(s)" in ok.stderr, ok.stderr
    np.testing.assert_allclose(load_aligned(tmp_path / "r2").table["ap_meas_deg"],
                               load_aligned(sim_log / "run").table["ap_meas_deg"], atol=1e-9)
    clash = log.copy()
    clash.loc[101, "stamp_ms"] = clash.loc[100, "stamp_ms"]  # the same stamp on rows that differ
    clash.to_csv(tmp_path / "clash.csv", index=False)
    one_line_exit_2(endocal("import", "csv", tmp_path / "clash.csv", "--map", MAP, "--out", tmp_path / "r3",
                            "--dedupe"), "lines 102 and 103 share a time stamp", "differ in column 'ap_present_ticks'")


def _one_row_per_message(log: pd.DataFrame, **per_device) -> tuple[pd.DataFrame, int]:
    """A logger writing one row per message: where a tick and a frame share a stamp, the motor
    cells and the pose cells come on two rows, the other's cells empty. ``per_device``: a column
    with a value for the motor rows and one for the tracker rows (``frame_id=("knobs", "aurora")``).
    Returns the log and the number of shared stamps."""
    pose = [c for c in log.columns if c.startswith(("tip_", "base_"))]
    both = log[pose].notna().all(axis=1) & log["ap_present_ticks"].notna()
    motor_part, pose_part = log[both].copy(), log[both].copy()
    motor_part[pose] = np.nan
    pose_part[[c for c in log.columns if c not in pose and c != "stamp_ms"]] = np.nan
    rest = log[~both].copy()
    for col, (motor_value, tracker_value) in per_device.items():
        rest[col], motor_part[col], pose_part[col] = motor_value, motor_value, tracker_value
    return pd.concat([rest, motor_part, pose_part]).sort_values("stamp_ms", kind="stable"), int(both.sum())


def test_a_motor_tick_and_a_frame_logged_in_one_millisecond_on_two_rows_are_merged(sim_log, tmp_path):
    split, n = _one_row_per_message(pd.read_csv(sim_log / "log.csv"))
    split.to_csv(tmp_path / "split.csv", index=False)
    assert n > 100  # every frame of the 40 Hz tracker shares its instant with a 100 Hz motor tick
    one_line_exit_2(endocal("import", "csv", tmp_path / "split.csv", "--map", MAP, "--out", tmp_path / "r1"),
                    f"{n} row(s) repeat a time stamp", "--dedupe")
    ok = endocal("import", "csv", tmp_path / "split.csv", "--map", MAP, "--out", tmp_path / "r2", "--dedupe")
    assert ok.returncode == 0 and f"merged {n} row(s)" in ok.stderr, ok.stderr
    a, b = load_aligned(sim_log / "run").table, load_aligned(tmp_path / "r2").table
    assert len(a) == len(b)
    for axis in ("ap", "ml"):
        np.testing.assert_allclose(b[f"{axis}_meas_deg"], a[f"{axis}_meas_deg"], atol=1e-9)


def _map(tmp_path: Path, old: str, new: str) -> Path:
    text = MAP.read_text()
    assert old in text
    p = tmp_path / "map.toml"
    p.write_text(text.replace(old, new))
    return p


@pytest.mark.parametrize("old, new, fragments", [
    ('position = "ap_present_ticks"', 'position = "ap_pos"', ("names column 'ap_pos'", "its columns: stamp_ms")),
    ('unit = "m"                                          # ...in mm or m', 'unit = "inch"', ("unknown length unit 'inch'",)),
    ('unit = "ms"', 'unit = "minutes"', ("unknown time unit 'minutes'",)),
    ('order = "wxyz"                                      # wxyz', 'order = "zyxw"                                      #',
     ("unknown quaternion order 'zyxw'",)),
    ('zero_ticks = 2048             # ticks', '# ticks', ("unit 'ticks' needs zero_ticks and ticks_per_rev",)),
    ("[knobs.ml]", "[knobs.lr]", ("probe 'tee' has no axis 'lr'",)),
    ('position = "ml_present_ticks"', 'position = "stamp_ms"', ("column 'stamp_ms' is named for two roles",)),
])
def test_bad_maps_are_one_line(sim_log, tmp_path, old, new, fragments):
    one_line_exit_2(endocal("import", "csv", sim_log / "log.csv", "--map", _map(tmp_path, old, new), "--out",
                            tmp_path / "run"), *fragments)
    assert not (tmp_path / "run").exists()


def test_a_map_without_poses_or_angles_names_both_ways(tmp_path):
    (tmp_path / "log.csv").write_text("t,ap,ml\n0,0,0\n0.01,1,0\n")
    (tmp_path / "map.toml").write_text('[time]\ncolumn = "t"\nunit = "s"\n[knobs.ap]\nposition = "ap"\nunit = "deg"\n'
                                       '[knobs.ml]\nposition = "ml"\nunit = "deg"\n')
    one_line_exit_2(endocal("import", "csv", tmp_path / "log.csv", "--map", tmp_path / "map.toml", "--out",
                            tmp_path / "run"), "a [tip] table is required", "[angles.AXIS] tables instead")


def test_not_a_table_and_existing_output(sim_log, tmp_path):
    (tmp_path / "prose.csv").write_text("just one line of prose\n")
    one_line_exit_2(endocal("import", "csv", tmp_path / "prose.csv", "--map", MAP, "--out", tmp_path / "r"),
                    "not a CSV table")
    shutil.copytree(sim_log / "run", tmp_path / "exists")
    one_line_exit_2(endocal("import", "csv", sim_log / "log.csv", "--map", MAP, "--out", tmp_path / "exists"),
                    "already exists", "--force")


ANGLES_MAP = ROOT / "configs" / "csv-map.angles.example.toml"


@pytest.fixture(scope="module")
def bench_log(sim_log):
    """The simulated run as a bench that reads its joint angle itself would log it (the angles
    example map's columns): motor in rad, the angle in deg from an encoder zeroed at 5 deg, a
    sheath configuration column, angle readings at every other motor sample."""
    a = load_aligned(sim_log / "run").table
    log = pd.DataFrame({"time_ms": 1000.0 * a["t_s"] + 250.0, "motor_rad": np.deg2rad(a["ap_cmd_deg"]),
                        "joint_deg": a["ap_meas_deg"] + 5.0, "sheath_deg": 180.0})
    log.loc[1::2, "joint_deg"] = np.nan  # the encoder is read at half the motor rate
    log.to_csv(sim_log / "bench.csv", index=False)
    return sim_log / "bench.csv", a


def test_a_bench_measuring_its_angle_imports_as_an_aligned_table(bench_log, tmp_path):
    log, a = bench_log
    text = ANGLES_MAP.read_text().replace("zero = 0.0 ", "zero = 5.0 ")
    (tmp_path / "map.toml").write_text(text)
    proc = endocal("import", "csv", log, "--map", tmp_path / "map.toml", "--out", tmp_path / "bench.parquet", "-v")
    assert proc.returncode == 0, proc.stderr
    assert "angle readings" in proc.stdout and "ap_meas_deg <- joint_deg" in proc.stdout
    b = load_aligned(tmp_path / "bench.parquet").table
    # every motor sample from the first reading to the last, the encoder's zero taken off, the
    # motor's radians back in degrees; between readings the angle is interpolated linearly
    n = len(b)
    assert n == len(a) - (len(a) + 1) % 2
    t = a["t_s"].to_numpy()[:n]
    np.testing.assert_allclose(b["t_s"], t, atol=1e-9)
    np.testing.assert_allclose(b["ap_cmd_deg"], a["ap_cmd_deg"][:n], atol=1e-9)
    np.testing.assert_allclose(b["ap_meas_deg"], np.interp(t, t[::2], a["ap_meas_deg"].to_numpy()[:n:2]), atol=1e-9)
    assert (b["sheath_deg"] == 180.0).all() and "ml_meas_deg" not in b
    # the table is a model's input like any run
    fit = endocal("fit", "hysteresis", tmp_path / "bench.parquet", "--axis", "ap", "--model", "linear",
                  "--out", tmp_path / "m.json")
    assert fit.returncode == 0, fit.stderr


@pytest.mark.parametrize("edit, out, fragments", [
    (lambda t: t + '\n[tip]\nposition = ["x", "y", "z"]\n', "t.parquet", ("either [tip] and [base]", "not both")),
    (lambda t: t.replace('column = "joint_deg"', 'column = "joint"'), "t.parquet", ("names column 'joint'",)),
    (lambda t: t.replace('unit = "deg"                  # ...in deg or rad', 'unit = "grad"'), "t.parquet",
     ("unknown angle unit 'grad'",)),
    (lambda t: t.replace("[angles.ap]", "[angles.lr]"), "t.parquet", ("no bending axis 'lr'",)),
    (lambda t: t.replace('"sheath_deg"]', '"sheath_deg", "x_meas_deg"]'), "t.parquet", ("'x_meas_deg'", "rename")),
    (lambda t: t, "folder", ("give --out a .parquet or .csv file name",)),
])
def test_bad_angle_maps_and_outputs_are_one_line(bench_log, tmp_path, edit, out, fragments):
    (tmp_path / "map.toml").write_text(edit(ANGLES_MAP.read_text()))
    one_line_exit_2(endocal("import", "csv", bench_log[0], "--map", tmp_path / "map.toml", "--out", tmp_path / out),
                    *fragments)
    assert not (tmp_path / out).exists()


@pytest.mark.parametrize("edit, fragments", [
    # the motor's radians read as degrees: a 35-fold gain
    (lambda t: t.replace('unit = "rad"  ', 'unit = "deg"  '),
     ("read as deg, column 'motor_rad'", "35 deg of bend per knob degree", "[knobs.ap] unit", "[angles.ap] unit")),
    # the joint's degrees read as radians: a bend over 3 000 deg
    (lambda t: t.replace('unit = "deg"                  # ...in deg or rad', 'unit = "rad"'),
     ("read as rad, column 'joint_deg'", "more than a bending section or joint turns", "[angles.ap] unit right?")),
])
def test_a_measured_angle_map_with_a_unit_mistake_warns_naming_the_key(bench_log, tmp_path, edit, fragments):
    """Warned, not refused: an angles map also carries what is no angle (the real piezo's volts and
    displacement, imported by test_a_headerless_logger_file_imports_by_column_number)."""
    (tmp_path / "map.toml").write_text(edit(ANGLES_MAP.read_text()))
    proc = endocal("import", "csv", bench_log[0], "--map", tmp_path / "map.toml", "--out", tmp_path / "t.parquet",
                   "--explain")
    assert proc.returncode == 0, proc.stderr
    warned = [ln for ln in proc.stderr.splitlines() if ln.startswith("warning:") and "unit" in ln]
    assert len(warned) == 1 and all(f in warned[0] for f in fragments), proc.stderr
    # the summary: one line, keyed, naming the column and the key to check
    proc = endocal("import", "csv", bench_log[0], "--map", tmp_path / "map.toml", "--out", tmp_path / "t.parquet",
                   "--force")
    warned = [ln for ln in proc.stderr.splitlines() if ln.startswith("warning")]
    assert len(warned) == 1 and warned[0].startswith("warning[unit]: ") and fragments[0] in warned[0], proc.stderr
    assert f"[angles.ap] unit" in warned[0] and proc.stderr.splitlines()[-1].startswith("next: endocal fit")


def test_a_geared_bench_whose_motor_turns_far_more_than_its_joint_imports_without_a_word(bench_log, tmp_path):
    """Only a bend many times the knob's travel looks like a unit mistake: a motor geared 20:1 down
    to the joint turns 20 times as far (0.05 deg of bend per motor degree)."""
    log = pd.read_csv(bench_log[0])
    log["motor_rad"] *= 20.0
    log.to_csv(tmp_path / "geared.csv", index=False)
    proc = endocal("import", "csv", tmp_path / "geared.csv", "--map", ANGLES_MAP, "--out", tmp_path / "g.parquet")
    assert proc.returncode == 0 and "warning" not in proc.stderr, proc.stderr


def test_a_clock_written_as_date_and_time_text(sim_log, tmp_path):
    # LabVIEW and spreadsheet exports stamp rows with date-time text, here to the microsecond
    log = pd.read_csv(sim_log / "log.csv")
    start = pd.Timestamp("2026-11-24 15:09:47")
    log.insert(0, "stamp", (start + pd.to_timedelta(log.pop("stamp_ms"), unit="ms")).dt.strftime("%Y-%m-%d %H:%M:%S.%f"))
    log.to_csv(tmp_path / "dated.csv", index=False)
    text = MAP.read_text().replace('column = "stamp_ms"', 'column = "stamp"').replace('unit = "ms"', 'unit = "datetime"')
    (tmp_path / "map.toml").write_text(text)
    ok = endocal("import", "csv", tmp_path / "dated.csv", "--map", tmp_path / "map.toml", "--out", tmp_path / "r")
    assert ok.returncode == 0, ok.stderr
    a, b = load_aligned(sim_log / "run").table, load_aligned(tmp_path / "r").table
    assert len(a) == len(b)
    np.testing.assert_allclose(b["t_s"], a["t_s"], atol=1.5e-6)  # stamps rounded to the microsecond
    # a microsecond of shift moves the interpolated angle by < 1e-4 deg (bends < 100 deg/s)
    np.testing.assert_allclose(b["ap_meas_deg"], a["ap_meas_deg"], atol=1e-3)
    log.loc[5, "stamp"] = "24/11/2026 quarter past three"
    log.to_csv(tmp_path / "bad.csv", index=False)
    one_line_exit_2(endocal("import", "csv", tmp_path / "bad.csv", "--map", tmp_path / "map.toml", "--out",
                            tmp_path / "r2"), "time column 'stamp' is not a date and time at line 7", "quarter past")


def test_a_clamped_base_given_as_one_fixed_pose(sim_log, tmp_path):
    # the simulated probe's base does not move in this run: its pose, written once into the map,
    # gives the same angles as the same pose logged on every row
    log = pd.read_csv(sim_log / "log.csv")
    cols = ["base_x_m", "base_y_m", "base_z_m", "base_qw", "base_qx", "base_qy", "base_qz"]
    pose = log[cols].mean().to_numpy().copy()
    pose[3:] /= np.linalg.norm(pose[3:])
    frames = log["tip_x_m"].notna()
    log.loc[frames, cols] = pose
    log.to_csv(tmp_path / "logged.csv", index=False)
    fixed = MAP.read_text().replace('# fixed_position = [0.012, -0.034, 0.151]', f"fixed_position = {pose[:3].tolist()}")
    fixed = fixed.replace("# fixed_quaternion = [1.0, 0.0, 0.0, 0.0]", f"fixed_quaternion = {pose[3:].tolist()}")
    fixed = fixed.replace('position = ["base_x_m", "base_y_m", "base_z_m"]\n', "").replace(
        'quaternion = ["base_qw", "base_qx", "base_qy", "base_qz"]\n', "")
    (tmp_path / "fixed.toml").write_text(fixed)
    log.drop(columns=cols).to_csv(tmp_path / "tip_only.csv", index=False)
    for name, m, out in (("logged.csv", MAP, "a"), ("tip_only.csv", tmp_path / "fixed.toml", "b")):
        proc = endocal("import", "csv", tmp_path / name, "--map", m, "--out", tmp_path / out)
        assert proc.returncode == 0, proc.stderr
    a, b = load_aligned(tmp_path / "a").table, load_aligned(tmp_path / "b").table
    assert len(a) == len(b)
    for axis in ("ap", "ml"):
        np.testing.assert_allclose(b[f"{axis}_meas_deg"], a[f"{axis}_meas_deg"], atol=1e-9)
    (tmp_path / "bad.toml").write_text(fixed.replace(f"fixed_quaternion = {pose[3:].tolist()}",
                                                     "fixed_quaternion = [1.0, 0.0, 0.0, 0.5]"))
    one_line_exit_2(endocal("import", "csv", tmp_path / "tip_only.csv", "--map", tmp_path / "bad.toml", "--out",
                            tmp_path / "c"), "fixed_quaternion a unit quaternion")


def test_a_headerless_logger_file_imports_by_column_number(tmp_path):
    # the real piezo recording's own format (data_samples/piezo/README.md): tab-separated, no
    # header, no clock (200 Hz), drive in column 1 and sensor in column 5, the rest constant
    real = pd.read_csv(ROOT / "data_samples" / "piezo" / "piezo_aligned.csv")
    n = len(real)
    cols = [real["piezo_cmd_deg"], *([np.zeros(n)] * 3), real["piezo_meas_deg"], *([np.full(n, -317.205767)] * 2)]
    (tmp_path / "piezo.dat").write_text("\n".join("\t".join(f"{v:.6f}" for v in row) for row in zip(*cols)) + "\n")
    (tmp_path / "map.toml").write_text('[time]\nsample_rate_hz = 200.0\n\n[knobs.ap]\nposition = "1"\n\n'
                                       '[angles.ap]\ncolumn = "5"\n')
    proc = endocal("import", "csv", tmp_path / "piezo.dat", "--map", tmp_path / "map.toml", "--out",
                   tmp_path / "piezo.parquet")
    assert proc.returncode == 0, proc.stderr
    b = load_aligned(tmp_path / "piezo.parquet").table
    np.testing.assert_allclose(b["t_s"], real["t_s"], atol=1e-9)
    np.testing.assert_allclose(b["ap_cmd_deg"], real["piezo_cmd_deg"], atol=1e-6)  # 6 decimals, as the file
    np.testing.assert_allclose(b["ap_meas_deg"], real["piezo_meas_deg"], atol=1e-6)
    # read as an aligned table it has no names: one line saying how to map it
    one_line_exit_2(endocal("info", tmp_path / "piezo.dat"), "no header line", "endocal import csv --map")
    bad = (tmp_path / "piezo.dat").read_text().splitlines()
    fields = bad[9].split("\t")
    for cell, expect in (("n/a", "3999 angle readings, 4000 aligned rows"), ("ERR", None)):
        bad[9] = "\t".join(fields[:4] + [cell] + fields[5:])  # the sensor's reading on line 10
        (tmp_path / "bad.dat").write_text("\n".join(bad) + "\n")
        proc = endocal("import", "csv", tmp_path / "bad.dat", "--map", tmp_path / "map.toml", "--out",
                       tmp_path / "bad.parquet", "--force")
        if expect:  # a reading the logger marked missing is left out and interpolated across
            assert proc.returncode == 0 and expect in proc.stdout, proc.stderr
        else:
            one_line_exit_2(proc, "column '5' is not numeric (line 10: 'ERR')")


def test_help_shows_the_map_tables_as_written():
    # help text is Markdown: Rich markup would swallow "[angles.AXIS]" as a style tag
    proc = endocal("import", "csv", "--help")
    assert proc.returncode == 0 and "[angles.AXIS]" in proc.stdout and "[angles]" in proc.stdout


def _draft(log: Path, tmp_path: Path, name: str = "draft.toml"):
    proc = endocal("import", "csv", log, "--draft-map", tmp_path / name)
    assert proc.returncode == 0, proc.stderr
    return tmp_path / name, proc.stdout


def test_a_drafted_map_imports_a_log_named_as_labs_name_columns(sim_log, tmp_path):
    """--draft-map on the example map's log: every role and unit read off the names and numbers.

    The clock says ms, the ticks and metres say so in their names; only the ticks' zero (a
    servo's mid-turn, 2048) is a guess, marked CHECK. Imported through the draft, the log gives
    the run's aligned table, as through the hand-written example map.
    """
    draft, stdout = _draft(sim_log / "log.csv", tmp_path)
    assert "knob ap <- ap_present_ticks (goal ap_goal_ticks)" in stdout and "tip <- tip_x_m" in stdout
    assert "CHECK [knobs.ap] zero_ticks" in stdout and "FILL IN" not in stdout
    assert "time <- stamp_ms\n" in stdout  # the name says ms: not repeated
    assert _then(stdout)[-2:] == ["--out", str(sim_log / "log")]  # poses: a run folder
    proc = endocal("import", "csv", sim_log / "log.csv", "--map", draft, "--out", tmp_path / "imported")
    assert proc.returncode == 0, proc.stderr
    a, b = load_aligned(sim_log / "run").table, load_aligned(tmp_path / "imported").table
    for col in ("t_s", "ap_cmd_deg", "ml_cmd_deg", "ap_meas_deg", "ml_meas_deg", "ap_current_ma"):
        np.testing.assert_allclose(b[col], a[col], atol=1e-9)


def test_a_drafted_map_reads_units_off_the_numbers_when_names_do_not_say(bench_log, tmp_path):
    """A bench log written by a European spreadsheet with bare names: Time, knob, TipAngle.

    Its units come from the numbers (a 100 Hz step in seconds; the knob within +-2 pi is
    radians, the angle beyond +-pi degrees), each marked CHECK; the extra numeric column is
    carried as a covariate. Imported through the draft it is the bench's table.
    """
    log, a = bench_log
    src = pd.read_csv(log)
    bare = pd.DataFrame({"Time": (src["time_ms"] - 250.0) / 1000, "knob": src["motor_rad"],
                         "TipAngle": src["joint_deg"] - 5.0, "sheath": src["sheath_deg"]})
    bare.to_csv(tmp_path / "bench eu.csv", sep=";", decimal=",", index=False)
    draft, stdout = _draft(tmp_path / "bench eu.csv", tmp_path)
    for check in ("[time] unit: median step 0.01 s = 100 Hz", "[knobs.ap] unit: values within +-6.28",
                  "[angles.ap] unit: values "):
        assert f"CHECK {check}" in stdout, stdout
    assert "extras <- sheath" in stdout
    proc = endocal("import", "csv", tmp_path / "bench eu.csv", "--map", draft, "--out", tmp_path / "b.parquet")
    assert proc.returncode == 0, proc.stderr
    b = load_aligned(tmp_path / "b.parquet").table
    n = len(b)
    np.testing.assert_allclose(b["ap_cmd_deg"], a["ap_cmd_deg"][:n], atol=1e-9)
    assert (b["sheath"] == 180.0).all()


def _then(stdout: str) -> list[str]:
    """The import command a draft prints on its `then:` line, split as a shell would (without `endocal`)."""
    import shlex

    line = next(ln for ln in stdout.splitlines() if ln.startswith("then: "))
    argv = shlex.split(line[len("then: "):])
    assert argv[0] == "endocal", line
    return argv[1:]


def test_the_command_a_draft_prints_for_an_angles_log_runs_as_printed(bench_log, tmp_path):
    """A bench log whose clock names its unit in brackets, `Time (s)`: the roles line says the
    unit once, and the `then:` command imports through the draft to an aligned table, as an
    [angles] map needs (`--out RUN`, a folder, is refused for one)."""
    log, a = bench_log
    src = pd.read_csv(log)
    pd.DataFrame({"Time (s)": (src["time_ms"] - 250.0) / 1000, "knob": src["motor_rad"],
                  "TipAngle": src["joint_deg"] - 5.0, "sheath": src["sheath_deg"]}).to_csv(tmp_path / "rig log.csv",
                                                                                          index=False)
    draft, stdout = _draft(tmp_path / "rig log.csv", tmp_path, "rig map.toml")
    assert "  time <- Time (s)\n" in stdout, stdout
    argv = _then(stdout)
    assert argv[-2:] == ["--out", str(tmp_path / "rig log.parquet")], argv
    assert "--out 'rig log.parquet'" in draft.read_text()  # the map's own header says the same
    proc = endocal(*argv)
    assert proc.returncode == 0, proc.stderr
    b = load_aligned(tmp_path / "rig log.parquet").table
    np.testing.assert_allclose(b["ap_cmd_deg"], a["ap_cmd_deg"][:len(b)], atol=1e-9)


def test_a_draft_of_a_log_with_a_repeated_stamp_prints_a_command_with_dedupe(bench_log, tmp_path):
    """A ROS bridge's row written twice: the draft says so and its `then:` command imports (without
    --dedupe the import would stop at the repeated stamp)."""
    log = pd.read_csv(bench_log[0])
    pd.concat([log.iloc[:11], log.iloc[10:]]).to_csv(tmp_path / "twice.csv", index=False)
    _, stdout = _draft(tmp_path / "twice.csv", tmp_path, "twice.toml")
    assert "1 row(s) repeat an earlier row's time stamp" in stdout, stdout
    argv = _then(stdout)
    assert argv[-1] == "--dedupe", argv
    proc = endocal(*argv)
    assert proc.returncode == 0 and "--dedupe dropped 1 row(s)" in proc.stderr, proc.stderr


def test_a_draft_that_could_not_place_a_role_says_so_and_the_import_refuses_it(tmp_path):
    t = np.arange(200) * 0.01
    pd.DataFrame({"a": t, "b": np.sin(t), "c": np.cos(t)}).to_csv(tmp_path / "opaque.csv", index=False)
    draft, stdout = _draft(tmp_path / "opaque.csv", tmp_path)
    assert "FILL IN [knobs.ap] position" in stdout and "FILL IN [angles.ap] column" in stdout
    one_line_exit_2(endocal("import", "csv", tmp_path / "opaque.csv", "--map", draft, "--out", tmp_path / "r.csv"),
                    "is still 'FILL IN' (a drafted map)")
    # with the columns named the units are still to give: no unit is guessed for a column no name placed
    # (the draft listed b and c among its extras: named as the knob and the angle, they are no longer extras)
    text = draft.read_text().replace('position = "FILL IN"', 'position = "b"').replace('column = "FILL IN"',
                                                                                       'column = "c"')
    assert '"b",' in text and '"c",' in text
    draft.write_text(text)
    one_line_exit_2(endocal("import", "csv", tmp_path / "opaque.csv", "--map", draft, "--out", tmp_path / "r.csv"),
                    "[knobs.ap]: the unit is still 'FILL IN' (a drafted map)", "deg, rad, ticks")
    assert not (tmp_path / "r.csv").exists()
    draft.write_text(text.replace('unit = "FILL IN"', 'unit = "deg"'))
    proc = endocal("import", "csv", tmp_path / "opaque.csv", "--map", draft, "--out", tmp_path / "r.csv")
    assert proc.returncode == 0, proc.stderr
    table = pd.read_csv(tmp_path / "r.csv")
    assert {"ap_cmd_deg", "ap_meas_deg"} <= set(table.columns) and not {"b", "c"} & set(table.columns), table.columns
    np.testing.assert_allclose(table["ap_meas_deg"], np.cos(t), atol=1e-6)
    # the options: a draft imports nothing, an import needs a map and an output, a draft is not overwritten
    one_line_exit_2(endocal("import", "csv", tmp_path / "opaque.csv", "--draft-map", tmp_path / "x.toml", "--map",
                            draft), "--draft-map writes a map and imports nothing")
    one_line_exit_2(endocal("import", "csv", tmp_path / "opaque.csv"), "give --map MAP.toml and --out RUN")
    one_line_exit_2(endocal("import", "csv", tmp_path / "opaque.csv", "--draft-map", draft), "already exists")
    assert not (tmp_path / "x.toml").exists()


def _run_json(run: Path) -> dict:
    import json

    return json.loads((run / "run.json").read_text())


def test_invalid_tracker_frames_and_incomplete_motor_rows_are_left_out_and_counted(sim_log, tmp_path):
    # a tracker writes zeros for a sensor out of the field, a ROS bridge empty cells; a servo
    # read can fail: such frames and motor rows are dropped, and every one is counted
    log = pd.read_csv(sim_log / "log.csv")
    frame_only = np.flatnonzero((log["tip_x_m"].notna() & log["ap_present_ticks"].isna()).to_numpy())
    motor_only = np.flatnonzero((log["tip_x_m"].isna() & log["ap_present_ticks"].notna()).to_numpy())
    zero_q, empty, no_knob = frame_only[100:105], frame_only[200:203], motor_only[300:304]
    log.loc[zero_q, ["base_qw", "base_qx", "base_qy", "base_qz"]] = 0.0  # scipy: "zero norm quaternions"
    log.loc[empty, "tip_qx"] = np.nan
    log.loc[no_knob, "ap_present_ticks"] = np.nan
    log.to_csv(tmp_path / "gaps.csv", index=False)
    proc = endocal("import", "csv", tmp_path / "gaps.csv", "--map", MAP, "--out", tmp_path / "r", "--explain")
    assert proc.returncode == 0, proc.stderr
    n_frames = int(log["tip_x_m"].notna().sum())
    assert f"{n_frames} tracker frames (8 invalid, left out)" in proc.stdout, proc.stdout
    first = int(min(zero_q[0], empty[0])) + 2  # data row k is on line k + 2
    assert f"8 tracker frame(s) were invalid" in proc.stderr and f"the first at line {first}" in proc.stderr
    assert "4 row(s) with knob cells but not every knob position" in proc.stderr, proc.stderr
    # the summary: a keyed line each (where they are, with --explain)
    short = endocal("import", "csv", tmp_path / "gaps.csv", "--map", MAP, "--out", tmp_path / "r", "--force")
    assert short.stderr.splitlines()[:2] == [
        "note[incomplete-rows]: 4 row(s) with knob cells but not every knob position were left out of the motor samples",
        "note[invalid-frames]: 8 tracker frame(s) were invalid (a sensor's cell empty, its quaternion no rotation, or "
        "flagged by the map's valid column) and left out of the aligned table"], short.stderr
    meta = _run_json(tmp_path / "r")
    assert meta["status"] == "complete"
    assert meta["counts"]["tracker_invalid_dropped"] == 8  # one sensor reading in each of the 8 frames
    assert meta["backend"]["tracker_frames_invalid"] == 8 and meta["backend"]["motor_rows_incomplete"] == 4
    table = load_aligned(tmp_path / "r").table
    assert np.isfinite(table[["ap_meas_deg", "ml_meas_deg"]].to_numpy()).all()
    # the stored stream carries the dropped readings as endocal's own dropouts: NaN, valid false
    tracker = read_stream(tmp_path / "r", "tracker")
    bad = tracker[~tracker["valid"]]
    assert len(bad) == 8 and bad[["qw", "qx", "qy", "qz"]].isna().all().all()


def test_a_failed_import_leaves_nothing_at_out(sim_log, tmp_path, monkeypatch):
    # whatever fails while the run is written (here: after every file, as a full disk would),
    # no half-written run folder with run.json "running" is left, and --force keeps the old run
    # (the staging is import ros's too: both write through runs.imported.write_imported_run)
    import endocal.runs.csvlog as csvlog
    import endocal.runs.imported as imported

    real = imported._write_run

    def fails(out, *args, **kwargs):
        real(out, *args, **kwargs)
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(imported, "_write_run", fails)
    with pytest.raises(OSError, match="No space left"):
        csvlog.import_csv(sim_log / "log.csv", MAP, tmp_path / "new")
    assert not (tmp_path / "new").exists()
    shutil.copytree(sim_log / "run", tmp_path / "old")
    with pytest.raises(OSError, match="No space left"):
        csvlog.import_csv(sim_log / "log.csv", MAP, tmp_path / "old", force=True)
    assert _run_json(tmp_path / "old")["backend"]["name"] != "csv-import"  # the old run, untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old"]  # no staging folder left beside it
    monkeypatch.setattr(imported, "_write_run", real)
    csvlog.import_csv(sim_log / "log.csv", MAP, tmp_path / "old", force=True)
    assert _run_json(tmp_path / "old")["backend"]["name"] == "csv-import"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old"]


def test_dedupe_merges_rows_that_differ_only_in_columns_the_map_does_not_use(sim_log, tmp_path):
    # a ROS bridge's rows of one stamp: a motor message and a tracker message, each with its own
    # arrival time, sequence number and frame name, none of which the map reads
    split, n = _one_row_per_message(pd.read_csv(sim_log / "log.csv"), frame_id=("knobs", "aurora"))
    split.insert(0, "%time", np.arange(len(split)) * 1000 + 1_732_460_987_000_000)  # arrival, us
    split.insert(1, "seq", np.arange(len(split)))
    split.to_csv(tmp_path / "ros.csv", index=False)
    ok = endocal("import", "csv", tmp_path / "ros.csv", "--map", MAP, "--out", tmp_path / "r", "--dedupe")
    assert ok.returncode == 0 and f"merged {n} row(s)" in ok.stderr, ok.stderr
    a, b = load_aligned(sim_log / "run").table, load_aligned(tmp_path / "r").table
    assert len(a) == len(b)
    np.testing.assert_allclose(b["ap_meas_deg"], a["ap_meas_deg"], atol=1e-9)
    # a column the map uses still has to agree
    k = int(np.flatnonzero((split["frame_id"] == "aurora").to_numpy())[0])
    split.iloc[k, split.columns.get_loc("ap_goal_ticks")] = 1234.0
    split.to_csv(tmp_path / "clash.csv", index=False)
    one_line_exit_2(endocal("import", "csv", tmp_path / "clash.csv", "--map", MAP, "--out", tmp_path / "r2",
                            "--dedupe"), "differ in column 'ap_goal_ticks' ([knobs.ap] goal)")


def _no_tick_keys(text: str) -> str:
    """The example map with the ap knob's tick keys removed (for a unit other than ticks)."""
    return text.replace("zero_ticks = 2048             # ticks when the knob is at 0 deg (probe straight)\n", "").replace(
        "ticks_per_rev = 4096          # XM430: 4096\n", "")


@pytest.mark.parametrize("edit, fragments", [
    # the clock in ms declared as s: 100 Hz becomes 0.1 Hz (one aligned row)
    (lambda t: t.replace('unit = "ms"', 'unit = "s"'), ('[time] unit = "s"', "0.1 Hz", "in ms they would be 100 Hz")),
    # ... as us: 100 kHz, knob speeds a thousand times the servo's
    (lambda t: t.replace('unit = "ms"', 'unit = "us"'), ('[time] unit = "us"', "1e+05 Hz", "in ms they would be 100 Hz")),
    # servo ticks read as degrees (2048 at the knob's zero) or radians
    (lambda t: _no_tick_keys(t).replace('unit = "ticks"                # deg', 'unit = "deg" # deg'),
     ("'ap_present_ticks' read as deg", "far beyond the limits of probe 'tee' (-90..90 deg)", "[knobs.ap] unit",
      'unit = "ticks"')),
    (lambda t: _no_tick_keys(t).replace('unit = "ticks"                # deg', 'unit = "rad" # deg'),
     ("'ap_present_ticks' read as rad", "[knobs.ap] unit")),
    # ... or with the tick keys left in place: they would be ignored, so the map is refused
    (lambda t: t.replace('unit = "ticks"                # deg', 'unit = "deg" # deg'),
     ("[knobs.ap]", 'zero_ticks and ticks_per_rev apply to unit = "ticks" only')),
    # poses in metres declared as millimetres: sensors 0.06 mm apart on a 60 mm section
    (lambda t: t.replace('unit = "m"                                          # ...in mm or m', 'unit = "mm"')
     .replace('position = ["base_x_m", "base_y_m", "base_z_m"]\nunit = "m"',
              'position = ["base_x_m", "base_y_m", "base_z_m"]\nunit = "mm"'),
     ('[tip] unit = "mm"', "bends over 60 mm", "metres need unit")),
    # NDI's scalar-first quaternions declared scalar-last (ROS): the base frame is another
    # rotation and the tip, straight ahead at neutral, never comes near its axis
    (lambda t: t.replace('order = "wxyz"', 'order = "xyzw"'),
     ('[base] order = "xyzw"', "deg or more off the base sensor's z axis in 95 % of the frames",
      'with order = "wxyz" 5 % come within', "scalar-first",
      'set [base] order = "wxyz" (and [tip] order')),
    # a zero_ticks a quarter turn off: the knob reads 90 deg where the probe is straight (within
    # a limit span of the limits, so only the bend gives it away: bent -58 deg at "knob 0")
    (lambda t: t.replace("zero_ticks = 2048             #", "zero_ticks = 1024             #"),
     ("at ap knob 0 as the map reads it the tip is bent -", "column 'ap_present_ticks' reads 20",
      "is [knobs.ap] zero_ticks right?")),
])
def test_numbers_no_rig_logs_are_refused_as_a_unit_mistake(sim_log, tmp_path, edit, fragments):
    (tmp_path / "map.toml").write_text(edit(MAP.read_text()))
    one_line_exit_2(endocal("import", "csv", sim_log / "log.csv", "--map", tmp_path / "map.toml", "--out",
                            tmp_path / "run"), *fragments)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.toml"]


def test_a_knob_in_radians_read_as_degrees_is_refused_by_its_gain(sim_log, tmp_path):
    # within the probe's limits (+-1.6 "deg"), so only the bend it drives gives it away: 57 deg
    # of bend per knob degree; the ml knob, logged right, passes
    log = pd.read_csv(sim_log / "log.csv")
    log["ap_present_rad"] = np.radians((log["ap_present_ticks"] - 2048) / TICKS_PER_DEG)
    log.to_csv(tmp_path / "log.csv", index=False)
    text = _no_tick_keys(MAP.read_text()).replace('position = "ap_present_ticks"', 'position = "ap_present_rad"')
    text = text.replace('unit = "ticks"                # deg', 'unit = "deg" # deg').replace('goal = "ap_goal_ticks"', "")
    (tmp_path / "map.toml").write_text(text)
    one_line_exit_2(endocal("import", "csv", tmp_path / "log.csv", "--map", tmp_path / "map.toml", "--out",
                            tmp_path / "run"), "read as deg, column 'ap_present_rad'", "deg of bend per knob degree",
                    '[knobs.ap] unit right? (radians need unit = "rad")')
    assert not (tmp_path / "run").exists()
    (tmp_path / "map.toml").write_text(text.replace('unit = "deg" # deg', 'unit = "rad" # deg'))
    proc = endocal("import", "csv", tmp_path / "log.csv", "--map", tmp_path / "map.toml", "--out", tmp_path / "run")
    assert proc.returncode == 0, proc.stderr


def test_a_knob_logged_in_degrees_from_another_zero_takes_zero(tmp_path, sim_log):
    # a servo's absolute angle: 180 deg where the probe is straight
    log = pd.read_csv(sim_log / "log.csv")
    log["ap_abs_deg"] = 180.0 + (log["ap_present_ticks"] - 2048) / TICKS_PER_DEG
    log.to_csv(tmp_path / "log.csv", index=False)
    text = _no_tick_keys(MAP.read_text()).replace('position = "ap_present_ticks"', 'position = "ap_abs_deg"')
    text = text.replace('unit = "ticks"                # deg', 'unit = "deg" # deg').replace('goal = "ap_goal_ticks"', "")
    (tmp_path / "map.toml").write_text(text)
    one_line_exit_2(endocal("import", "csv", tmp_path / "log.csv", "--map", tmp_path / "map.toml", "--out",
                            tmp_path / "run"), "is [knobs.ap] zero right?", "column 'ap_abs_deg' reads 1")
    (tmp_path / "map.toml").write_text(text.replace('unit = "deg" # deg', 'zero = 180.0\nunit = "deg" # deg'))
    proc = endocal("import", "csv", tmp_path / "log.csv", "--map", tmp_path / "map.toml", "--out", tmp_path / "run")
    assert proc.returncode == 0, proc.stderr
    np.testing.assert_allclose(read_stream(tmp_path / "run", "motor")["ap_pos_deg"],
                               read_stream(sim_log / "run", "motor")["ap_pos_deg"], atol=1e-9)


def test_too_few_aligned_rows_for_any_fit_are_refused(sim_log, tmp_path):
    # the tracker logged its first 0.3 s only (12 frames at 40 Hz): about 30 motor samples
    # lie in its span, 22 is the least a fit can use (2 samples per parameter + 20)
    log = pd.read_csv(sim_log / "log.csv")
    late = log["stamp_ms"] > log["stamp_ms"].iloc[0] + 300
    pose = [c for c in log.columns if c.startswith(("tip_", "base_"))]
    log.loc[late, pose] = np.nan
    log.to_csv(tmp_path / "ok.csv", index=False)
    proc = endocal("import", "csv", tmp_path / "ok.csv", "--map", MAP, "--out", tmp_path / "ok")
    assert proc.returncode == 0, proc.stderr
    log.loc[log["stamp_ms"] > log["stamp_ms"].iloc[0] + 100, pose] = np.nan  # 0.1 s: about 10 motor samples
    log.to_csv(tmp_path / "short.csv", index=False)
    one_line_exit_2(endocal("import", "csv", tmp_path / "short.csv", "--map", MAP, "--out", tmp_path / "r"),
                    "only 11 motor sample(s)", "fewer than any fit can use (22)", "the tracker frames 0.000..0.100 s",
                    "[time] column 'stamp_ms'")
    assert not (tmp_path / "r").exists()


def test_epoch_time_stamps_in_errors_are_printed_so_the_row_can_be_found(sim_log, tmp_path):
    # a clock in seconds since 1970: "t = 1.73246e+09" would point at no row
    log = pd.read_csv(sim_log / "log.csv")
    log.insert(0, "stamp_s", 1_732_460_987.0 + log.pop("stamp_ms") / 1000.0)
    rep = pd.concat([log.iloc[:101], log.iloc[100:101], log.iloc[101:]], ignore_index=True)
    rep.to_csv(tmp_path / "rep.csv", index=False)
    text = MAP.read_text().replace('column = "stamp_ms"', 'column = "stamp_s"').replace('unit = "ms"', 'unit = "s"')
    (tmp_path / "map.toml").write_text(text)
    written = (tmp_path / "rep.csv").read_text().splitlines()[102].split(",")[0]  # the stamp as the file has it
    since = log["stamp_s"].iloc[100] - log["stamp_s"].iloc[0]
    proc = endocal("import", "csv", tmp_path / "rep.csv", "--map", tmp_path / "map.toml", "--out", tmp_path / "r")
    one_line_exit_2(proc, "line 103", f"stamp_s = {written}, {since:.3f} s after the first row")
    assert "e+09" not in proc.stderr
    back = log.copy()
    back.iloc[[200, 201]] = back.iloc[[201, 200]].to_numpy()
    back.to_csv(tmp_path / "back.csv", index=False)
    later = back["stamp_s"].iloc[201] - back["stamp_s"].iloc[0]
    one_line_exit_2(endocal("import", "csv", tmp_path / "back.csv", "--map", tmp_path / "map.toml", "--out",
                            tmp_path / "r"), "time goes back", "at line 203", f"{later:.3f} s after the first row",
                    "split the log there into two records")


@pytest.mark.parametrize("old, new, fragments", [
    ("ticks_per_rev = 4096          # XM430: 4096", "ticks_per_rev = 0",
     ("[knobs.ap]", "ticks_per_rev must be a positive number", "got 0")),
    ("ticks_per_rev = 4096          # XM430: 4096", "ticks_per_rev = -4096", ("ticks_per_rev must be a positive number",)),
    ("ticks_per_rev = 4096          # XM430: 4096", 'ticks_per_rev = "4096"', ("ticks_per_rev must be a positive number",)),
    ("zero_ticks = 2048 ", "zero_ticks = nan ", ("[knobs.ap]", "zero_ticks must be a number", "got nan")),
    ('goal = "ap_goal_ticks"', "goal = 5", ("[knobs.ap]", "goal must name a column", "got 5")),
    ('column = "stamp_ms"', "column = 1", ("[time]", "column must name a column",)),
])
def test_numbers_of_a_map_are_checked_in_one_line(sim_log, tmp_path, old, new, fragments):
    proc = endocal("import", "csv", sim_log / "log.csv", "--map", _map(tmp_path, old, new), "--out", tmp_path / "run")
    one_line_exit_2(proc, *fragments)
    assert "RuntimeWarning" not in proc.stderr and not (tmp_path / "run").exists()


def test_a_pose_map_writes_a_run_folder_not_a_table(sim_log, tmp_path):
    one_line_exit_2(endocal("import", "csv", sim_log / "log.csv", "--map", MAP, "--out", tmp_path / "run.parquet"),
                    "maps EM poses, so the import is a run folder", "give --out a folder name")
    assert not (tmp_path / "run.parquet").exists()


@pytest.fixture
def ros_log(sim_log):
    """The simulated run as `rostopic echo -p` of a merged topic writes it: numbered JointState
    arrays of servo ticks (field.position0, field.goal1), poses in metres, a ROS header."""
    log = pd.read_csv(sim_log / "log.csv")
    ns = (1_732_460_987_000_000_000 + np.round(log["stamp_ms"] * 1e6)).astype("int64")
    ros = pd.DataFrame({"%time": ns + 150_000, "field.header.seq": np.arange(len(log)), "field.header.stamp": ns,
                        "field.header.frame_id": "rig"})
    for i, axis in enumerate(("ap", "ml")):
        ros[f"field.position{i}"] = np.round(log[f"{axis}_present_ticks"])  # a servo reports whole ticks
        ros[f"field.goal{i}"] = np.round(log[f"{axis}_goal_ticks"])
    ros["field.effort0"] = log["ap_current_ma"]  # dynamixel_workbench publishes the present current (mA) as effort
    for sensor in ("tip", "base"):
        for a in "xyz":
            ros[f"field.{sensor}.pose.position.{a}"] = log[f"{sensor}_{a}_m"]
        for a in "wxyz":
            ros[f"field.{sensor}.pose.orientation.{a}"] = log[f"{sensor}_q{a}"]
    return ros


def test_a_drafted_map_of_a_ros_log_maps_its_numbered_motors_and_never_a_pose_as_a_knob(ros_log, sim_log, tmp_path):
    ros_log.to_csv(tmp_path / "ros.csv", index=False)
    draft, stdout = _draft(tmp_path / "ros.csv", tmp_path)
    assert "knob ap <- field.position0 (goal field.goal0)" in stdout, stdout
    assert "knob ml <- field.position1 (goal field.goal1)" in stdout, stdout
    assert "CHECK [knobs.ap] position: motor 0 read as the ap knob" in stdout
    assert "CHECK [knobs.ap] unit: whole numbers" in stdout and "FILL IN" not in stdout
    assert "CHECK [knobs.ap] current: a JointState's effort read as the servo's current" in stdout, stdout
    assert "extras <-" not in stdout  # a ROS header's stamp and seq are no covariates
    # the clock is when the devices measured (the header stamp), not when the bridge got the message
    assert "time <- field.header.stamp (ns)" in stdout, stdout
    proc = endocal("import", "csv", tmp_path / "ros.csv", "--map", draft, "--out", tmp_path / "r")
    assert proc.returncode == 0, proc.stderr
    a, b = load_aligned(sim_log / "run").table, load_aligned(tmp_path / "r").table
    assert len(a) == len(b)
    # ticks rounded by the servo: the command within half a tick (0.044 deg); angles from the
    # same poses, on a clock read from ns stamps to 2.4e-7 s (< 1e-4 deg at < 100 deg/s)
    np.testing.assert_allclose(b["ap_cmd_deg"], a["ap_cmd_deg"], atol=0.5 * 360 / 4096 + 1e-9)
    np.testing.assert_allclose(b["ml_meas_deg"], a["ml_meas_deg"], atol=1e-3)
    np.testing.assert_allclose(read_stream(tmp_path / "r", "motor")["ap_current_ma"],
                               read_stream(sim_log / "run", "motor")["ap_current_ma"], rtol=1e-6)


def test_a_draft_that_found_one_numbered_motor_leaves_the_other_knob_to_fill_in(ros_log, tmp_path):
    ros_log.drop(columns=["field.position1", "field.goal1"]).to_csv(tmp_path / "one.csv", index=False)
    draft, stdout = _draft(tmp_path / "one.csv", tmp_path)
    assert "knob ap <- field.position0" in stdout and "FILL IN [knobs.ml] position" in stdout, stdout
    assert "base.pose" not in "".join(ln for ln in stdout.splitlines() if ln.startswith("  knob"))
    one_line_exit_2(endocal("import", "csv", tmp_path / "one.csv", "--map", draft, "--out", tmp_path / "r"),
                    "[knobs.ml] position: a column is still 'FILL IN'")


def test_a_log_holding_the_latest_pose_on_every_row_reads_each_frame_at_its_own_time(sim_log, tmp_path):
    """A logger writing one row per motor tick with the latest pose repeated (the example map's
    note): each reading is a frame where it first appears, not at every row it was held, which
    placed readings up to 25 ms late (0.3 deg RMS, 2.1 deg at worst on the red team's log)."""
    log = pd.read_csv(sim_log / "log.csv")
    pose = [c for c in log.columns if c.startswith(("tip_", "base_"))]
    log[pose] = log[pose].ffill()
    log.dropna(subset=pose).to_csv(tmp_path / "held.csv", index=False)
    ok = endocal("import", "csv", tmp_path / "held.csv", "--map", MAP, "--out", tmp_path / "r")
    assert ok.returncode == 0, ok.stderr
    frames = int(pd.read_csv(sim_log / "log.csv")[pose].notna().all(axis=1).sum())
    assert f"{frames} tracker frames" in ok.stdout, (frames, ok.stdout)
    a, b = load_aligned(sim_log / "run").table, load_aligned(tmp_path / "r").table
    assert len(a) == len(b)
    np.testing.assert_allclose(b["ap_meas_deg"], a["ap_meas_deg"], atol=1e-9)


def test_a_tracker_that_starts_a_moment_after_the_motors_is_no_gap(sim_log, tmp_path):
    # devices start one after the other: motor rows before the first frame are trimmed, as every
    # aligned table is, and said only when that edge is longer than a gap (0.2 s); a warning on
    # every clean log (the first motor row 0.4 ms before the first frame) taught users to skip it
    import endocal.runs.csvlog as csvlog

    log = pd.read_csv(sim_log / "log.csv")
    pose = [c for c in log.columns if c.startswith(("tip_", "base_"))]
    stamp = log["stamp_ms"].to_numpy()
    for name, late_ms, warned in (("late", 100, False), ("later", 500, True)):
        cut = log.copy()
        cut.loc[stamp < stamp[0] + late_ms, pose] = np.nan
        cut.to_csv(tmp_path / f"{name}.csv", index=False)
        res = csvlog.import_csv(tmp_path / f"{name}.csv", MAP, tmp_path / name)
        assert (res.gap_warning is not None) == warned, (name, res.gap_warning)
        assert (res.motor_rows_unaligned > 0) == warned


def test_a_gap_in_the_poses_is_warned_with_its_rows_first_line_and_length(sim_log, tmp_path):
    # the tracker lost both sensors for a second (a bridge writes empty cells): the motor samples
    # in that gap have no bend to interpolate and are left out of the aligned table, which the
    # import counts, with the first one's line and the gap's length, for a warning
    import endocal.runs.csvlog as csvlog

    clean = csvlog.import_csv(sim_log / "log.csv", MAP, tmp_path / "clean")
    assert clean.motor_rows_unaligned == 0 and clean.gap_warning is None
    log = pd.read_csv(sim_log / "log.csv")
    pose = [c for c in log.columns if c.startswith(("tip_", "base_"))]
    stamp = log["stamp_ms"].to_numpy()
    lost = (stamp >= stamp[0] + 5000) & (stamp < stamp[0] + 6000)
    log.loc[lost, pose] = np.nan
    log.to_csv(tmp_path / "gap.csv", index=False)
    frames = stamp[log["tip_x_m"].notna().to_numpy()]
    before, after = frames[frames < stamp[0] + 5000].max(), frames[frames >= stamp[0] + 6000].min()
    # align()'s rule: a gap over 0.2 s leaves out the motor samples from the frame before it up to
    # the one after it
    left = log["ap_present_ticks"].notna().to_numpy() & (stamp >= before) & (stamp < after)
    line = int(np.flatnonzero(left)[0]) + 2  # data row k is on line k + 2
    res = csvlog.import_csv(tmp_path / "gap.csv", MAP, tmp_path / "r")
    assert res.motor_rows_unaligned == left.sum() >= 100  # a gap of a second or more at 100 Hz
    assert res.motor_rows_unaligned_line == line
    assert res.longest_gap_s == pytest.approx((after - before) / 1000.0, abs=1e-9)
    assert res.aligned_rows == clean.aligned_rows - left.sum()
    assert res.gap_warning == (f"{left.sum()} motor sample(s) were left out of the aligned table, with no tracker "
                               "frame to interpolate (a gap over 0.2 s, or outside the tracker frames' span; the "
                               f"longest gap {(after - before) / 1000.0:.2f} s); the first at line {line}")
    meta = _run_json(tmp_path / "r")
    assert meta["backend"]["motor_rows_unaligned"] == left.sum() == meta["counts"]["motor_ticks_without_tracking"]
    assert meta["backend"]["motor_rows_unaligned_line"] == line
    assert meta["backend"]["longest_gap_s"] == pytest.approx((after - before) / 1000.0, abs=1e-9)


def test_a_gap_in_the_angle_readings_is_counted_in_the_table_metadata(bench_log, tmp_path):
    # the encoder, read at every other motor sample, stops for half a second: the motor samples from
    # the reading before it up to the one after are left out (the every-other-row gaps are interpolated)
    import json

    import pyarrow.parquet as pq

    import endocal.runs.csvlog as csvlog

    log = pd.read_csv(bench_log[0])
    lost = (log["time_ms"] >= 5250.0) & (log["time_ms"] < 5750.0)  # 5.0 to 5.5 s after the first row
    log.loc[lost, "joint_deg"] = np.nan
    log.to_csv(tmp_path / "gap.csv", index=False)
    read = np.flatnonzero(log["joint_deg"].notna().to_numpy())
    k0, k1 = read[read < np.flatnonzero(lost)[0]].max(), read[read > np.flatnonzero(lost)[-1]].min()
    (tmp_path / "map.toml").write_text(ANGLES_MAP.read_text().replace("zero = 0.0 ", "zero = 5.0 "))
    res = csvlog.import_csv(tmp_path / "gap.csv", tmp_path / "map.toml", tmp_path / "gap.parquet")
    assert (res.motor_rows_unaligned, res.motor_rows_unaligned_line) == (k1 - k0, k0 + 2)  # every row a motor sample
    assert res.longest_gap_s == pytest.approx((log["time_ms"][k1] - log["time_ms"][k0]) / 1000.0, abs=1e-9)
    assert "with no angle reading to interpolate" in res.gap_warning and res.aligned_rows == len(log) - (k1 - k0)
    backend = json.loads(pq.read_schema(tmp_path / "gap.parquet").metadata[b"endocal"])["backend"]
    assert (backend["motor_rows_unaligned"], backend["motor_rows_unaligned_line"]) == (k1 - k0, k0 + 2)


@pytest.mark.parametrize("spoil, fragment", [
    (lambda cells, cols: cells.__setitem__(cols.index("ap_present_ticks"), "ERR"),
     "column 'ap_present_ticks' is not numeric (line {line}: 'ERR')"),
    (lambda cells, cols: cells.__setitem__(cols.index("stamp_ms"), ""),
     "time column 'stamp_ms' is empty or not a number at line {line}"),
    (lambda cells, cols: cells.__setitem__(cols.index("ap_goal_ticks"), ""),
     "goal column 'ap_goal_ticks' is empty on a motor row (line {line})"),
])
def test_a_bad_cell_is_named_by_its_line_in_the_file_past_blank_lines(sim_log, tmp_path, spoil, fragment):
    # an editor counts the blank lines a logger left (a restart, a hand edit), which pandas skips
    text = (sim_log / "log.csv").read_text().splitlines()
    cols = text[0].split(",")
    k = next(i for i in range(100, len(text)) if text[i + 1].split(",")[cols.index("ap_present_ticks")])  # a motor row
    cells = text[k + 1].split(",")  # data row k is on line k + 2, index k + 1
    spoil(cells, cols)
    text[k + 1] = ",".join(cells)
    text[60:60] = [""]  # empty, and spaces only: two lines no row is read from
    text[30:30] = ["   "]
    (tmp_path / "blank.csv").write_text("\n".join(text) + "\n")
    one_line_exit_2(endocal("import", "csv", tmp_path / "blank.csv", "--map", MAP, "--out", tmp_path / "r"),
                    fragment.format(line=k + 4))


@pytest.mark.parametrize("time, fragments", [
    # a log without a clock: its rows per second are the map's, and no lab logs 0.5 or 20 000
    ("sample_rate_hz = 0.5", ("[time] sample_rate_hz = 0.5", "2 s apart (0.5 Hz), slower than any lab log",
                              "set sample_rate_hz to the rows the logger wrote per second")),
    ("sample_rate_hz = 20000.0", ("[time] sample_rate_hz = 20000", "faster than any lab log (1 Hz to 10000 Hz)")),
    # the clock's unit left beside a rate would be ignored
    ('sample_rate_hz = 100.0\nunit = "ms"', ("[time]: unit applies to a time column, not to sample_rate_hz",
                                             "delete unit = 'ms'")),
])
def test_a_fixed_sample_rate_is_checked_as_a_clock_is(bench_log, tmp_path, time, fragments):
    text = ANGLES_MAP.read_text()
    clock = text[text.index('column = "time_ms"'):text.index("[knobs.ap]")]
    (tmp_path / "map.toml").write_text(text.replace(clock, time + "\n\n"))
    one_line_exit_2(endocal("import", "csv", bench_log[0], "--map", tmp_path / "map.toml", "--out",
                            tmp_path / "t.parquet"), *fragments)
    assert not (tmp_path / "t.parquet").exists()
    (tmp_path / "map.toml").write_text(text.replace(clock, "sample_rate_hz = 100.0\n\n"))
    ok = endocal("import", "csv", bench_log[0], "--map", tmp_path / "map.toml", "--out", tmp_path / "t.parquet")
    assert ok.returncode == 0 and "(100.0 Hz)" in ok.stdout, ok.stderr


def test_a_drafted_import_is_pointed_beside_the_log_or_here_when_its_folder_is_read_only(tmp_path, monkeypatch):
    # a shared data folder is often read-only: the drafted `--out` then lands in the working folder
    import endocal.runs.mapdraft as mapdraft

    log = tmp_path / "sweep.csv"
    assert mapdraft.import_out(log, angles=True) == tmp_path / "sweep.parquet"
    monkeypatch.setattr(mapdraft.os, "access", lambda path, mode: False)  # root may write anywhere
    assert mapdraft.import_out(log, angles=True) == Path("sweep.parquet")
    assert mapdraft.import_out(log, angles=False) == Path("sweep")


def test_a_probe_pulled_by_linear_stages_imports_as_a_run_in_mm(sim_log, tmp_path):
    """The knobs replaced by linear stages pulling the tendons, 25 knob degrees a mm (a tendon
    2.3 mm off the axis): the run keeps the drives in mm (motor stream, aligned table and
    run.json's drive_units), the probe's knob limits (deg) no longer apply, and the bending
    angles are those of the knobs' import. Read as degrees, the stages bend the tip some 17 deg
    per "knob degree", refused naming the unit."""
    mm_per_deg = 1 / 25.0
    log = pd.read_csv(sim_log / "log.csv")
    for axis in ("ap", "ml"):
        for kind in ("present", "goal"):
            log[f"{axis}_stage_{kind}"] = (log.pop(f"{axis}_{kind}_ticks") - 2048) / TICKS_PER_DEG * mm_per_deg
    log.to_csv(tmp_path / "stage.csv", index=False)
    text = MAP.read_text()
    for axis in ("ap", "ml"):
        text = text.replace(f'"{axis}_present_ticks"', f'"{axis}_stage_present"').replace(f'"{axis}_goal_ticks"',
                                                                                       f'"{axis}_stage_goal"')
    text = re.sub(r"\nzero_ticks = 2048[^\n]*|\nticks_per_rev = 4096[^\n]*", "", text)
    (tmp_path / "map.toml").write_text(text.replace('unit = "ticks"', 'unit = "mm"'))
    proc = endocal("import", "csv", tmp_path / "stage.csv", "--map", tmp_path / "map.toml", "--out", tmp_path / "run",
                   "--explain")
    assert proc.returncode == 0, proc.stderr
    assert "ap (mm) <- ap_stage_present" in proc.stdout, proc.stdout
    assert _run_json(tmp_path / "run")["drive_units"] == {"ap": "mm", "ml": "mm"}
    assert {"ap_goal_mm", "ap_pos_mm", "ap_vel_mmps"} <= set(read_stream(tmp_path / "run", "motor").columns)
    a, b = load_aligned(sim_log / "run"), load_aligned(tmp_path / "run")
    assert b.drive_units == {"ap": "mm", "ml": "mm"} and "ap_cmd_deg" not in b.table
    np.testing.assert_allclose(b.cmd("ml"), a.cmd("ml") * mm_per_deg, atol=1e-9)
    np.testing.assert_allclose(b.meas_deg("ml"), a.meas_deg("ml"), atol=1e-9)
    (tmp_path / "map.toml").write_text(text.replace('unit = "ticks"', 'unit = "deg"'))
    one_line_exit_2(endocal("import", "csv", tmp_path / "stage.csv", "--map", tmp_path / "map.toml", "--out",
                            tmp_path / "deg"),
                    "read as deg, column 'ap_stage_present'", "deg of bend per knob degree",
                    '(a tendon pulled by a linear stage: unit = "mm")')
    assert not (tmp_path / "deg").exists()
