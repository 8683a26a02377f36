"""End to end through the real `endocal` command: excite on the simulator, info, bad input, kill -9."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.dataset as ds
import pytest

from endocal.runs.aligned import load_aligned
from tests._cli import endocal as in_process

ROOT = Path(__file__).resolve().parents[1]


def endocal(*args, cwd=None, timeout=300):
    """Run the installed command line exactly as a user would, in a child process.

    The first run and the signal tests go through it; the other tests run the same root app
    in this process (``in_process``, tests/_cli.py: the same parsing, errors and exit codes,
    without a Python start-up and a numba cache load per command).
    """
    return subprocess.run(
        [sys.executable, "-m", "endocal", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd or ROOT,
        timeout=timeout,
    )


def one_line_error(proc, *fragments):
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    for f in fragments:
        assert f in lines[0], lines[0]
    return lines[0]


def test_excite_on_the_simulator_writes_a_complete_run(tmp_path):
    run = tmp_path / "ds"
    proc = endocal("excite", "damped-sine", "--out", run, "--seed", "4", "--amplitude", "60")
    assert proc.returncode == 0, proc.stderr
    assert "run complete" in proc.stdout
    meta = json.loads((run / "run.json").read_text())
    assert meta["status"] == "complete" and meta["backend"]["name"] == "sim" and meta["seed"] == 4
    assert meta["protocol"]["name"] == "damped-sine" and meta["protocol"]["params"]["amplitude_deg"] == 60
    assert meta["protocol"]["sha256"] and meta["software"]["numpy"]
    data = load_aligned(run)
    assert data.axes == ["ap", "ml"]
    assert data.t_s[-1] == pytest.approx(140.0, abs=0.05)  # 7T with T = 20 s
    # The knob command is the paper's damped sine on the driven axis.
    driven = max(data.axes, key=lambda a: np.ptp(data.cmd_deg(a)))
    assert np.max(np.abs(data.cmd_deg(driven))) == pytest.approx(60.0, rel=0.01)
    # The tip follows: measured bending correlates strongly with the command.
    r = np.corrcoef(data.cmd_deg(driven), data.meas_deg(driven))[0, 1]
    assert r > 0.9
    assert {"contact_force_n", "sheath_wrap_deg", f"{driven}_current_ma"} <= set(data.extras)
    info = endocal("info", run, "--json")
    assert info.returncode == 0, info.stderr
    assert json.loads(info.stdout)["protocol"] == "damped-sine"


def test_same_seed_same_run_other_seed_other_noise(tmp_path):
    for name, seed in (("a", 1), ("b", 1), ("c", 2)):
        assert in_process("excite", "triangle", "--out", tmp_path / name, "--seed", seed, "--set", "cycles=1").returncode == 0
    a, b, c = (load_aligned(tmp_path / n).table for n in "abc")
    pd.testing.assert_frame_equal(a, b)
    assert not np.allclose(a["ap_meas_deg"], c["ap_meas_deg"])


@pytest.mark.parametrize(
    "args, fragments",
    [
        (["excite", "no-such-protocol", "--out", "{tmp}/r"], ["no-such-protocol"]),
        (["excite", "damped-sine", "--out", "{tmp}/r", "--axes", "zz"], ["zz"]),
        (["excite", "damped-sine", "--out", "{tmp}/r", "--amplitude", "400"], ["limit"]),
        (["excite", "damped-sine", "--out", "{tmp}/r", "--set", "no_such_param=3"], ["no_such_param"]),
        (["excite", "{tmp}/bad.toml", "--out", "{tmp}/r"], ["bad.toml"]),
        (["excite", "damped-sine", "--out", "{tmp}/r", "--sim-config", "{tmp}/bad.toml"], ["bad.toml"]),
        (["excite", "damped-sine", "--out", "{tmp}/r", "--backend", "warp"], ["warp"]),
        (["excite", "damped-sine", "--out", "{tmp}/afile/r"], ["afile", "is not a folder"]),
        # a shortcut the protocol has no parameter for names the flag and what the protocol has
        (["excite", "sine-set", "--out", "{tmp}/r", "--amplitude", "40"], ["--amplitude sets amplitude_deg",
                                                                          "amplitudes_deg"]),
        (["info", "{tmp}/noversion"], ["records no run format version"]),
        (["excite", "random", "--out", "{tmp}/r", "--seed", "-1"], ["--seed must be a non-negative integer"]),
        (["info", "{tmp}/missing.parquet"], ["does not exist"]),
        (["info", "{tmp}/nocols.csv"], ["_cmd_deg"]),
        (["info", "{tmp}/nan.csv"], ["NaN", "at line 4;"]),  # the file's line: header 1, rows from 2
        (["info", "{tmp}/backwards.csv"], ["time must increase"]),
    ],
)
def test_bad_input_gets_one_line_and_exit_2(tmp_path, args, fragments):
    (tmp_path / "bad.toml").write_text("name = 'x'\n[[broken\n")
    (tmp_path / "afile").write_text("a file where a folder should be\n")
    (tmp_path / "noversion").mkdir()
    (tmp_path / "noversion" / "run.json").write_text('{"format": "endocal-run"}')
    pd.DataFrame({"t_s": [0.0, 0.1], "ap_deg": [1.0, 2.0]}).to_csv(tmp_path / "nocols.csv", index=False)
    pd.DataFrame({"t_s": [0.0, 0.1, 0.2], "ap_cmd_deg": [0, 1, 2], "ap_meas_deg": [0, 1, np.nan]}).to_csv(tmp_path / "nan.csv", index=False)
    pd.DataFrame({"t_s": [0.0, 0.2, 0.1], "ap_cmd_deg": [0, 1, 2], "ap_meas_deg": [0, 1, 2]}).to_csv(tmp_path / "backwards.csv", index=False)
    proc = in_process(*[a.replace("{tmp}", str(tmp_path)) for a in args])
    one_line_error(proc, *fragments)
    assert not (tmp_path / "r").exists()  # nothing half-written


def test_existing_output_is_kept_unless_forced(tmp_path):
    run = tmp_path / "r"
    assert in_process("excite", "triangle", "--out", run, "--set", "cycles=1").returncode == 0
    before = (run / "run.json").read_text()
    one_line_error(in_process("excite", "triangle", "--out", run, "--set", "cycles=1"), "already exists", "--force")
    assert (run / "run.json").read_text() == before
    assert in_process("excite", "triangle", "--out", run, "--set", "cycles=1", "--force").returncode == 0


def test_kill_9_loses_at_most_two_seconds(tmp_path):
    run = tmp_path / "killed"
    proc = subprocess.Popen(
        [sys.executable, "-m", "endocal", "excite", "sine-set", "--out", str(run), "--realtime", "--quiet"],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not list((run / "motor").glob("part-*.parquet")):
            assert proc.poll() is None, proc.stderr.read().decode()
            time.sleep(0.05)
        first_part_wall = time.monotonic()
        first = ds.dataset(run / "motor", format="parquet").to_table().to_pandas()
        time.sleep(4.0)
        killed_wall = time.monotonic()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    # Realtime pacing: run time advances with the wall clock, so by the kill the run had
    # reached at least this t_s; everything older than 2 s must be on disk.
    reached_t_s = first["t_s"].max() + (killed_wall - first_part_wall)
    motor = ds.dataset(run / "motor", format="parquet").to_table().to_pandas()
    tracker = pd.read_parquet(run / "tracker")
    assert motor["t_s"].max() >= reached_t_s - 2.0
    assert tracker["t_s"].max() >= reached_t_s - 2.0
    assert np.all(np.diff(motor["t_s"].to_numpy()) > 0)
    meta = json.loads((run / "run.json").read_text())
    assert meta["status"] == "running"  # honest: nobody wrote "complete"
    assert not (run / "aligned.parquet").exists()
    data = load_aligned(run)  # rebuilt from the streams
    assert data.t_s[-1] >= reached_t_s - 2.0 - 0.1


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)  # whatever the test runner's own disposition


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


# started as a shell script's background job (`endocal excite ... &`) the process begins with
# SIGINT ignored, and Python leaves it so: the run must still stop on it
@pytest.mark.parametrize("started", ["from a terminal", "with SIGINT ignored"])
def test_ctrl_c_stops_cleanly_and_leaves_a_valid_run(tmp_path, started):
    run = tmp_path / "stopped"
    proc = subprocess.Popen(
        [sys.executable, "-m", "endocal", "excite", "sine-set", "--out", str(run), "--realtime", "--quiet"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_ignore_sigint if started == "with SIGINT ignored" else _default_sigint,
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list((run / "motor").glob("part-*.parquet")):
        time.sleep(0.05)
    time.sleep(1.5)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, (stdout, stderr)
    assert "interrupted" in stderr and "Traceback" not in stderr
    meta = json.loads((run / "run.json").read_text())
    assert meta["status"] == "interrupted"
    data = load_aligned(run)  # the aligned table was written for what was logged
    assert (run / "aligned.parquet").exists() and data.t_s[-1] == pytest.approx(meta["logged_s"], abs=0.05)


def test_out_of_range_on_excite_model_errors_by_default_and_clamps_on_request(tmp_path):
    # The sample triangle run spans +-45 deg of knob: a linear model fitted on it cannot reach
    # the protocol's larger desired angles without leaving that range.
    model = tmp_path / "lin.json"
    fit = in_process("fit", "hysteresis", ROOT / "data_samples" / "sim-triangle", "--model", "linear", "--axis", "ap",
                  "--out", model)
    assert fit.returncode == 0, fit.stderr
    refused = in_process("excite", "triangle", "--model", model, "--axes", "ap", "--out", tmp_path / "r1")
    one_line_error(refused, "outside the fitted command range", "--out-of-range clamp")
    assert not (tmp_path / "r1").exists()
    # in a child process: its stderr holds every warning the run raised, not only those the command prints
    clamped = endocal("excite", "triangle", "--model", model, "--axes", "ap", "--out-of-range", "clamp",
                      "--out", tmp_path / "r2", "-q")
    assert clamped.returncode == 0, clamped.stderr
    warnings = [ln for ln in clamped.stderr.splitlines() if ln.strip()]
    assert len(warnings) == 1 and warnings[0].startswith("warning:") and "clamped" in warnings[0], clamped.stderr
    meta = json.loads((tmp_path / "r2" / "run.json").read_text())
    assert meta["protocol"]["out_of_range"] == {"ap": "clamp"}
    cmd = load_aligned(tmp_path / "r2").table["ap_cmd_deg"].to_numpy()
    assert np.abs(cmd).max() <= 45.0 + 0.5  # clamped to the fitted range (0.5 deg: servo resolution and lag)
    one_line_error(in_process("excite", "triangle", "--out-of-range", "clamp", "--out", tmp_path / "r3"), "--model")
    one_line_error(in_process("excite", "triangle", "--model", model, "--out-of-range", "wrap", "--out", tmp_path / "r4"),
                   "--out-of-range must be one of")
    # a model of the axis the protocol holds still: nothing it moves would be compensated
    other = json.loads(model.read_text())
    other["axis"] = "ml"
    (tmp_path / "ml.json").write_text(json.dumps(other))
    one_line_error(in_process("excite", "triangle", "--model", tmp_path / "ml.json", "--axes", "ap", "--out",
                           tmp_path / "r5"), "are for axis 'ml', but this protocol moves ap", "--axes ml")
    assert not (tmp_path / "r5").exists()
