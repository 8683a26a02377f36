"""Run format: logging, the aligned table, eq. 1 through real sensor frames, and bad tables."""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import pyarrow.dataset as ds
import pytest

from endocal.errors import LimitError, OutputExistsError, RunFormatError
from endocal.excite import run_excitation
from endocal.runs.aligned import load_aligned
from endocal.runs.format import read_run_json
from tests.conftest import GeometryBackend


@dataclass
class Traj:
    """The smallest object with the Trajectory interface run_excitation needs."""

    t_s: np.ndarray
    goal: dict
    sample_rate_hz: float
    desired: dict = field(default_factory=dict)

    @property
    def duration_s(self):
        return float(self.t_s[-1])

    def check_limits(self, probe):
        for dof, g in self.goal.items():
            lo, hi = probe.limits(dof)
            if g.min() < lo or g.max() > hi:
                raise LimitError(f"{dof} beyond limits")


def sine_traj(probe, seconds=20.0, fs=100.0, amp=40.0):
    t = np.arange(int(seconds * fs) + 1) / fs
    goal = {dof: np.zeros_like(t) for dof in probe.dofs}
    goal[probe.bending_axes[0]] = amp * np.sin(2 * np.pi * 0.1 * t)
    goal[probe.bending_axes[1]] = -0.5 * amp * np.sin(2 * np.pi * 0.05 * t) * (t > 10)  # planar first 10 s
    return Traj(t, goal, fs)


def excite(tmp_path, probe, backend=None, traj=None, **kw):
    backend = backend or GeometryBackend(probe)
    traj = traj or sine_traj(probe)
    return run_excitation(traj, backend, probe, tmp_path / "run", protocol_info={"name": "test"}, seed=3, **kw), traj, backend


def test_run_round_trip_and_eq1_through_sensor_frames(tmp_path, tee):
    result, traj, backend = excite(tmp_path, tee)
    run = tmp_path / "run"
    meta = read_run_json(run)
    assert meta["status"] == "complete" and meta["seed"] == 3 and meta["probe"]["name"] == "tee"
    assert meta["software"]["endocal"] and meta["started_utc"].endswith("Z")
    assert backend.closed == 1
    # Streams readable by plain pyarrow.dataset and pandas, with every sample.
    motor = ds.dataset(run / "motor", format="parquet").to_table().to_pandas()
    tracker = pd.read_parquet(run / "tracker")
    assert len(motor) == traj.t_s.size == result.motor_rows
    assert len(tracker) == 2 * (int(traj.duration_s * 40) + 1)
    data = load_aligned(run)
    assert data.axes == ["ap", "ml"]
    # The geometry backend bends by exactly the knob angle (total tip angle); eq. 1 gives the
    # chord angle, which is half the tip angle for a planar arc. Single-axis instants are
    # planar, so meas = cmd / 2 up to linear interpolation between 40 Hz frames
    # (curvature error < (1/40 s)^2/8 * max|d2/dt2| = 7.8e-5 * 40*(2pi*0.1)^2/2 deg = 6e-4 deg).
    planar = np.abs(data.cmd_deg("ml")) < 1e-9
    assert planar.sum() > 900
    np.testing.assert_allclose(data.meas_deg("ap")[planar], data.cmd_deg("ap")[planar] / 2, atol=2e-3)
    # Away from planar instants eq. 1 is the projection of the tip, computed here by hand.
    bx, by = np.radians(data.cmd_deg("ml")), np.radians(data.cmd_deg("ap"))
    alpha, phi = np.hypot(bx, by), np.arctan2(by, bx)
    r = 1 - np.cos(alpha)
    expected_ap = np.degrees(np.arctan2(r * np.sin(phi), np.sin(alpha)))
    np.testing.assert_allclose(data.meas_deg("ap"), expected_ap, atol=0.05)
    assert "sheath_wrap_deg" in data.extras and "ap_pos_deg" in data.extras


def test_invalid_frames_are_dropped_and_counted(tmp_path, tee):
    backend = GeometryBackend(tee, invalid_every=5)
    excite(tmp_path, tee, backend=backend)
    meta = read_run_json(tmp_path / "run")
    assert meta["counts"]["tracker_invalid_dropped"] == pytest.approx(meta["counts"]["tracker_frames"] / 5, abs=1)
    data = load_aligned(tmp_path / "run")
    assert np.isfinite(data.table.to_numpy()).all()


def test_existing_output_refused_without_force(tmp_path, tee):
    excite(tmp_path, tee)
    before = (tmp_path / "run" / "run.json").read_text()
    with pytest.raises(OutputExistsError, match="--force"):
        excite(tmp_path, tee)
    assert (tmp_path / "run" / "run.json").read_text() == before  # nothing lost
    excite(tmp_path, tee, force=True)


def test_limits_refused_before_anything_is_written(tmp_path, tee):
    traj = sine_traj(tee, amp=120.0)  # knob limit is 90 deg
    backend = GeometryBackend(tee)
    with pytest.raises(LimitError):
        excite(tmp_path, tee, backend=backend, traj=traj)
    assert not (tmp_path / "run").exists()


def test_interrupt_leaves_a_valid_run(tmp_path, tee):
    class Interrupting(GeometryBackend):
        calls = 0

        def execute(self, t_s, goal):
            self.calls += 1
            if self.calls == 3:
                raise KeyboardInterrupt
            return super().execute(t_s, goal)

    backend = Interrupting(tee)
    traj = sine_traj(tee, seconds=100.0)
    result = run_excitation(traj, backend, tee, tmp_path / "run", protocol_info={}, seed=0)
    assert result.status == "interrupted" and backend.closed == 1
    assert result.logged_s == pytest.approx(2 * 30.0 - 0.01, abs=0.02)  # two 30 s chunks made it
    meta = read_run_json(tmp_path / "run")
    assert meta["status"] == "interrupted"
    assert len(load_aligned(tmp_path / "run").table) > 5000


def test_failure_closes_backend_and_keeps_what_was_logged(tmp_path, tee):
    class Failing(GeometryBackend):
        calls = 0

        def execute(self, t_s, goal):
            self.calls += 1
            if self.calls == 2:
                raise RuntimeError("bus error")
            return super().execute(t_s, goal)

    backend = Failing(tee)
    with pytest.raises(RuntimeError):
        run_excitation(sine_traj(tee, seconds=100.0), backend, tee, tmp_path / "run", protocol_info={}, seed=0)
    assert backend.closed == 1
    meta = json.loads((tmp_path / "run" / "run.json").read_text())
    assert meta["status"] == "failed" and "bus error" in meta["error"]
    assert meta["counts"]["motor_rows"] == 3000


def test_killed_run_without_aligned_table_is_rebuilt_from_streams(tmp_path, tee):
    excite(tmp_path, tee)
    run = tmp_path / "run"
    complete = load_aligned(run).table
    (run / "aligned.parquet").unlink()
    meta = json.loads((run / "run.json").read_text())
    meta["status"] = "running"
    (run / "run.json").write_text(json.dumps(meta))
    rebuilt = load_aligned(run).table
    pd.testing.assert_frame_equal(rebuilt, complete)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda df: df.drop(columns=["t_s"]), "no 't_s' column"),
        (lambda df: df.drop(columns=["ap_meas_deg", "ml_meas_deg"]), "found only ap_cmd_deg"),
        (lambda df: df.assign(ap_meas_deg=df["ap_meas_deg"].where(df.index != 7)), "'ap_meas_deg' is NaN at line 9; drop such rows (a tracker dropout)"),
        (lambda df: df.assign(ml_cmd_deg=df["ml_cmd_deg"].where(df.index != 3, np.inf)), "'ml_cmd_deg' is infinite at line 5; drop or fill"),
        (lambda df: df.assign(t_s=df["t_s"].where(df.index != 10, 0.0)), "time must increase, but t_s goes from 0.09 to 0 at line 12"),
        (lambda df: df.iloc[:0], "no rows"),
        (lambda df: df.assign(t_s=df["t_s"].astype(object).where(df.index != 4, "abc")), "'t_s' is not numeric"),
    ],
)
def test_bad_aligned_tables(tmp_path, mutate, message):
    t = np.arange(50) * 0.01
    df = pd.DataFrame({"t_s": t, "ap_cmd_deg": np.sin(t), "ap_meas_deg": np.sin(t), "ml_cmd_deg": t, "ml_meas_deg": t})
    path = tmp_path / "bad.csv"
    mutate(df).to_csv(path, index=False)
    with pytest.raises(RunFormatError, match=message.replace("(", r"\(").replace(")", r"\)")):
        load_aligned(path)


def test_a_bad_cell_is_named_by_its_line_in_a_csv_file_and_by_its_row_in_a_parquet_table(tmp_path):
    """A CSV file's messages name the line an editor shows (the header is line 1; a logger's notes before it
    and blank lines count); a Parquet table has no lines: its row (from 0)."""
    t = np.arange(20) * 0.01
    df = pd.DataFrame({"t_s": t, "ap_cmd_deg": np.sin(t), "ap_meas_deg": np.sin(t)})
    df.loc[12, "ap_meas_deg"] = np.nan
    rows = df.to_csv(index=False).splitlines()
    (tmp_path / "a.csv").write_text("\n".join(["# logger v2", *rows[:6], "", *rows[6:]]) + "\n")
    assert (tmp_path / "a.csv").read_text().splitlines()[15].endswith(",")  # line 16: row 12's empty cell
    with pytest.raises(RunFormatError, match="'ap_meas_deg' is NaN at line 16; .*import csv .*--draft-map"):
        load_aligned(tmp_path / "a.csv")
    df.to_parquet(tmp_path / "a.parquet")
    with pytest.raises(RunFormatError, match="'ap_meas_deg' is NaN at row 12; drop or fill such rows first$"):
        load_aligned(tmp_path / "a.parquet")


def test_user_tables_in_csv_and_parquet(tmp_path):
    t = np.arange(200) * 0.01
    df = pd.DataFrame({"t_s": t, "ud_cmd_deg": 30 * np.sin(t), "ud_meas_deg": 20 * np.sin(t), "torque_nm": t})
    df.to_csv(tmp_path / "a.csv", index=False)
    df.to_parquet(tmp_path / "a.parquet")
    for name in ("a.csv", "a.parquet"):
        data = load_aligned(tmp_path / name)
        assert data.axes == ["ud"] and data.extras == ["torque_nm"]
        np.testing.assert_allclose(data.meas_deg("ud"), 20 * np.sin(t))
    with pytest.raises(RunFormatError, match="no axis 'ap'"):
        data.cmd_deg("ap")
    with pytest.raises(RunFormatError, match="does not exist"):
        load_aligned(tmp_path / "missing.parquet")
    (tmp_path / "x.json").write_text("{}")
    with pytest.raises(RunFormatError, match="expected a run folder"):
        load_aligned(tmp_path / "x.json")


def test_backend_that_fails_to_open_leaves_no_run_folder(tmp_path, tee):
    from endocal.errors import HardwareError

    class Unplugged(GeometryBackend):
        def open(self):
            raise HardwareError("no servo answers on /dev/ttyUSB0")

    backend = Unplugged(tee)
    with pytest.raises(HardwareError):
        excite(tmp_path, tee, backend=backend)
    assert backend.closed == 1  # torque-off path runs even when open fails
    assert not (tmp_path / "run").exists()


def test_force_never_deletes_a_folder_that_is_not_a_run(tmp_path, tee):
    from endocal.errors import OutputPathError

    precious = tmp_path / "run"
    precious.mkdir()
    (precious / "thesis.tex").write_text("years of work")
    with pytest.raises(OutputPathError, match="not an endocal run"):
        excite(tmp_path, tee, force=True)
    assert (precious / "thesis.tex").read_text() == "years of work"


@pytest.mark.parametrize("write", [
    lambda df, p: df.to_csv(p.with_suffix(".csv"), index=False, sep=";", decimal=","),  # European spreadsheet
    lambda df, p: df.to_csv(p.with_suffix(".tsv"), index=False, sep="\t"),  # a data logger
    lambda df, p: p.with_suffix(".csv").write_text(df.to_csv(index=False).replace(",", ", ")),  # hand-edited
    lambda df, p: p.with_suffix(".csv").write_text(df.to_csv(index=False), encoding="utf-8-sig"),  # with a BOM
    lambda df, p: p.with_suffix(".dat").write_text(df.to_string(index=False, float_format="{:.17g}".format)),  # lined up
    lambda df, p: p.with_suffix(".csv").write_text(df.to_csv(index=False) + ",,,\n" * 3),  # a spreadsheet's empty rows
])
def test_an_aligned_table_reads_the_same_however_the_csv_was_written(tmp_path, write):
    t = np.arange(50) / 100.0
    df = pd.DataFrame({"t_s": t, "ap_cmd_deg": 30 * np.sin(t), "ap_meas_deg": 25 * np.sin(t - 0.1), "fixture": "clampA"})
    write(df, tmp_path / "table")
    data = load_aligned(next(tmp_path.iterdir()))
    assert data.axes == ["ap"] and list(data.table.columns) == list(df.columns)
    for col in ("t_s", "ap_cmd_deg", "ap_meas_deg"):
        np.testing.assert_allclose(data.table[col], df[col], rtol=1e-12, atol=1e-12)
    assert (data.table["fixture"] == "clampA").all()


def test_read_columns_gives_the_values_and_dtypes_pandas_reads(tmp_path):
    """validate and fit read aligned tables without pandas (endocal.runs.aligned.read_columns); a column must
    come out as the DataFrame read_parquet makes holds it: floats, integers, integers with nulls (NaN floats),
    booleans, text, an empty table, and a table written in several row groups (several Arrow chunks)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from endocal.runs.aligned import read_columns, read_parquet

    n = 1000
    table = pa.table({"t_s": np.arange(n) * 0.01, "count": np.arange(n, dtype=np.int64), "small": np.arange(n, dtype=np.int16),
                      "gappy": pa.array([None if i % 7 == 0 else i for i in range(n)], pa.int64()),
                      "flag": np.arange(n) % 2 == 0, "note": [f"n{i}" for i in range(n)],
                      "f32": np.linspace(0, 1, n, dtype=np.float32)})
    for name, t, kw in (("one", table, {}), ("groups", table, {"row_group_size": 128}), ("empty", table.slice(0, 0), {}),
                        ("sliced", table.slice(3, 500), {})):
        path = tmp_path / f"{name}.parquet"
        pq.write_table(t, path, **kw)
        want = read_parquet(path)
        got = read_columns(path)
        assert list(got) == list(want.columns)
        for c in want.columns:
            assert got[c].dtype == want[c].to_numpy().dtype, (name, c)
            np.testing.assert_array_equal(got[c], want[c].to_numpy(), err_msg=f"{name}: {c}")
            if got[c].dtype.kind in "iuf":
                got[c][:1] = 0  # writable, as a DataFrame's column is


def test_validate_reads_and_scores_records_without_pandas(tmp_path, tee):
    """pandas is 0.15 s of a command's start (bench/bench_loop.py): loading a record, its planes and a model, and
    scoring them, must not import it. A fresh interpreter, as a user's shell starts one."""
    import subprocess
    import sys

    run_excitation(sine_traj(tee, seconds=4.0), GeometryBackend(tee), tee, tmp_path / "run", protocol_info={}, seed=0)
    code = ("import sys; from endocal.runs.aligned import load_aligned; d = load_aligned(sys.argv[1]); "
            "import endocal.planes, endocal.fitting, endocal.cli.validate, endocal.cli.fit, endocal.validation.scan; "
            "d.meas_deg('ap'), d.cmd_deg('ap'), d.t_s; print('pandas' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code, str(tmp_path / "run")], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "False", done.stderr
