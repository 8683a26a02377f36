"""Feedforward compensation on the simulator: desired angle -> inverse model -> knob -> tip.

The thesis's first experiment and the duodenoscope paper's fig. 9b. The simulator's default
probe has tendon slack (deadzone), a stiffening bending section (envelope) and ~75 ms of servo
and tracker lag (delay), so the model carries those three effects on a B-spline base; the
paper's modified PI (`pi` + `envelope`) also needs `tension`: the capstan friction's backlash
grows with the bend, while the loops of a PI model are congruent.
"""

from __future__ import annotations

import pytest

from endocal.backends.registry import make_backend
from endocal.fitting import fit_hysteresis
from endocal.probe import PRESETS
from endocal.protocols import load_protocol
from endocal.validation.playback import validate_on_backend
from tests._cli import endocal  # in-process: the same parsing, errors and exit codes, without a start-up per call
from tests.test_cli_excite import one_line_error

PROBE = PRESETS["tee"]


@pytest.fixture(scope="module")
def training(tmp_path_factory):
    # identified on the duodenoscope paper's damped sine alone, as the paper does; the four
    # signals below are then all unseen (the random one included)
    root = tmp_path_factory.mktemp("comp")
    assert endocal("excite", "damped-sine", "--amplitude", "85", "--out", root / "train", "--seed", "2", "--quiet").returncode == 0
    return [root / "train"]


@pytest.fixture(scope="module")
def model(training):
    return fit_hysteresis(training, "ap", "bspline", ["envelope", "deadzone", "delay"]).model


@pytest.fixture(scope="module")
def pi_model(training):
    # the paper's modified PI plus what this probe has beyond it: slack, lag, and sheath
    # friction that grows with the bend (tension), which congruent PI loops cannot shape
    return fit_hysteresis(training, "ap", "pi", ["envelope", "deadzone", "delay", "tension"]).model


SIGNALS = ["damped-sine", "triangle", "chirp", "random"]  # the duodenoscope paper's four inputs


@pytest.mark.parametrize("which, signal", [("bspline", s) for s in SIGNALS] + [("pi", s) for s in SIGNALS])
def test_compensation_reaches_the_noise_floor(which, signal, request, tmp_path):
    model = request.getfixturevalue("model" if which == "bspline" else "pi_model")
    proto = load_protocol(signal, overrides={"amplitude_deg": 40.0})
    result = validate_on_backend(model, proto, lambda: make_backend("sim", PROBE, seed=1), PROBE, seed=1, out_dir=tmp_path)
    # A robot that commands the desired angle directly is far off (paper: 9-13 deg).
    assert result.uncompensated.rmse_deg > 5.0
    # Measured angles carry ~0.38 deg of tracker noise (0.5 mm at 60 mm); issue 4 asks for
    # at most 0.6 deg compensated, which leaves ~0.45 deg RMS for the model itself.
    assert result.metrics.rmse_deg <= 0.6, result.metrics
    assert result.metrics.max_deg < 3.0
    assert set(result.runs) == {"compensated", "uncompensated"} and (tmp_path / "compensated" / "run.json").exists()


def test_a_playback_without_a_folder_leaves_nothing_behind(model, tmp_path, monkeypatch):
    # without out_dir the two runs go to a temporary folder, removed once read (it used to
    # stay in /tmp, two Parquet runs per `validate --protocol`); what the runs logged is kept
    import tempfile

    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    proto = load_protocol("triangle", overrides={"amplitude_deg": 30.0, "cycles": 1})
    result = validate_on_backend(model, proto, lambda: make_backend("sim", PROBE, seed=1), PROBE, seed=1)
    assert list(scratch.iterdir()) == [] and result.runs == {}
    assert set(result.events) == {"compensated", "uncompensated"} and result.metrics.rmse_deg < 1.0


def test_task_space_excite_plays_desired_angles_through_the_inverse(model, tmp_path):
    import numpy as np

    from endocal.models import save_model
    from endocal.runs.aligned import load_aligned
    from endocal.validation.playback import PREROLL_S

    save_model(model, tmp_path / "ap.json")
    run = tmp_path / "ts"
    proc = endocal("excite", "triangle", "--set", "amplitude_deg=30", "--model", tmp_path / "ap.json", "--out", run, "--seed", "4", "--quiet")
    assert proc.returncode == 0, proc.stderr
    data = load_aligned(run)
    assert data.meta["protocol"]["hysteresis_compensation"] == {"ap": str(tmp_path / "ap.json")}
    proto = load_protocol("triangle", overrides={"amplitude_deg": 30.0}).trajectory(PROBE)
    keep = data.t_s >= PREROLL_S
    desired = np.interp(data.t_s[keep] - PREROLL_S, proto.t_s, proto.goal["ap"])
    err = data.meas_deg("ap")[keep] - desired
    # Same bar as the playback above: the tip follows the desired angle, not the knob.
    assert np.sqrt(np.mean(err**2)) <= 0.6
    one_line_error(endocal("excite", "triangle", "--model", tmp_path / "ap.json", "--model", tmp_path / "ap.json", "--out", tmp_path / "x"), "two --model files")


def test_validate_protocol_cli_prints_metrics_and_uncompensated(model, tmp_path):
    import json

    from endocal.models import save_model
    from endocal.validation.metrics import METRIC_KEYS

    save_model(model, tmp_path / "ap.json")
    proc = endocal("validate", tmp_path / "ap.json", "--protocol", "triangle", "--set", "amplitude_deg=30",
                   "--json-out", tmp_path / "v.json")
    assert proc.returncode == 0, proc.stderr
    d = json.loads((tmp_path / "v.json").read_text())
    assert set(METRIC_KEYS) <= set(d["metrics"]) and set(METRIC_KEYS) <= set(d["uncompensated"])
    assert d["metrics"]["rmse_deg"] < d["uncompensated"]["rmse_deg"] / 5
    # the summary: both errors with their intervals, and what the model saves (every metric with --explain)
    c, u = d["metrics"], d["uncompensated"]
    lines = proc.stdout.splitlines()
    assert lines[0] == (f"compensated (triangle on sim): RMSE {c['rmse_deg']:.3g} deg (95 % CI {c['ci']['rmse_deg'][0]:.3g} "
                        f".. {c['ci']['rmse_deg'][1]:.3g}), max {c['max_deg']:.3g} deg"), proc.stdout
    assert lines[1].startswith(f"uncompensated: RMSE {u['rmse_deg']:.3g} deg") and lines[1].endswith(
        f": the model lowers the RMSE {100 * (1 - c['rmse_deg'] / u['rmse_deg']):.0f} %"), proc.stdout
    assert len(lines) == 3 and lines[2].startswith("details: --explain")
    one_line_error(endocal("validate", tmp_path / "ap.json", "--protocol", "triangle", "--set", "amplitude_deg=80"), "range")
