"""`endocal fit hysteresis` end to end: simulator runs and user tables in, versioned model files out."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from endocal.models import load_model
from endocal.runs.aligned import load_aligned
from tests._cli import endocal  # in-process: the same parsing, errors and exit codes, without a start-up per call
from tests.test_cli_excite import one_line_error


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    path = tmp_path_factory.mktemp("fit") / "ds"
    assert endocal("excite", "damped-sine", "--amplitude", "80", "--out", path, "--seed", "7", "--quiet").returncode == 0
    return path


def test_fit_prints_the_equation_and_saves_a_model_that_predicts_the_data(run, tmp_path):
    out = tmp_path / "bs.json"
    proc = endocal("fit", "hysteresis", run, "--axis", "ap", "--model", "bspline", "--effects", "envelope", "--out", out,
                   "--explain")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("ap_deg = BSpline3(f(cmd))") and "RMSE" in proc.stdout
    assert "evaluations; converged" in proc.stdout and "termination condition" not in proc.stdout, proc.stdout
    model = load_model(out)
    data = load_aligned(run)
    pred = model.predict(data.cmd_deg("ap"), t_s=data.t_s)
    rmse = float(np.sqrt(np.mean((pred - data.meas_deg("ap")) ** 2)))
    # Tracker noise alone is ~0.38 deg; the sim's slack and lag (not in this model) add the rest.
    assert rmse < 1.0
    assert rmse == pytest.approx(model.fit_report_.rmse_deg, rel=1e-6)
    meta = json.loads(out.read_text())
    assert meta["format"] == "endocal-model" and meta["version"] == 2 and meta["axis"] == "ap"
    assert meta["provenance"]["data"][0]["sha256"] == data.sha256
    assert meta["provenance"]["software"]["endocal"]


def test_the_papers_modified_pi_fits_and_inverts_analytically(run, tmp_path):
    out = tmp_path / "pi.json"
    proc = endocal("fit", "hysteresis", run, "--axis", "ap", "--model", "pi", "--effects", "envelope", "--out", out, "--json")
    assert proc.returncode == 0, proc.stderr
    d = json.loads(proc.stdout)
    assert d["base"] == "pi" and [e["name"] for e in d["effects"]] == ["envelope"]
    assert any(k.startswith("pi_") for k in d["parameters"]) and {"envelope_k0", "envelope_theta0_deg"} <= set(d["parameters"])
    model = load_model(out)
    desired = 30 * np.sin(np.linspace(0, 4 * np.pi, 2000))
    np.testing.assert_allclose(model.predict(model.inverse(desired)), desired, atol=1e-6)


def test_bad_input(run, tmp_path):
    one_line_error(endocal("fit", "hysteresis", run, "--axis", "zz", "--out", tmp_path / "a.json"), "no axis 'zz'")
    one_line_error(endocal("fit", "hysteresis", run, "--axis", "ap", "--effects", "bogus", "--out", tmp_path / "b.json"), "bogus")
    t = np.arange(400) * 0.01
    pd.DataFrame({"t_s": t, "ap_cmd_deg": 40 * t / t[-1], "ap_meas_deg": 30 * t / t[-1]}).to_csv(tmp_path / "ramp.csv", index=False)
    one_line_error(endocal("fit", "hysteresis", tmp_path / "ramp.csv", "--axis", "ap", "--out", tmp_path / "c.json"), "never reverses")
    pd.DataFrame({"t_s": t[:5], "ap_cmd_deg": [0, 1, 0, 1, 0], "ap_meas_deg": [0, 1, 0, 1, 0]}).to_csv(tmp_path / "short.csv", index=False)
    one_line_error(endocal("fit", "hysteresis", tmp_path / "short.csv", "--axis", "ap", "--out", tmp_path / "d.json"), "samples")
    # a tracker that lost the tip sensor and repeats its last reading
    pd.DataFrame({"t_s": t, "ap_cmd_deg": 40 * np.sin(t), "ap_meas_deg": 12.0}).to_csv(tmp_path / "frozen.csv", index=False)
    one_line_error(endocal("fit", "hysteresis", tmp_path / "frozen.csv", "--axis", "ap", "--out", tmp_path / "f.json"),
                   "never changes (12 deg throughout)")
    (tmp_path / "e.json").write_text("{}")
    one_line_error(endocal("fit", "hysteresis", run, "--axis", "ap", "--out", tmp_path / "e.json"), "already exists")
    assert not any((tmp_path / f"{n}.json").exists() for n in "abcdf")


def test_start_from_a_fitted_model_refits_from_its_values_and_records_it(run, tmp_path):
    """`--start-from`: validate's refit commands start the candidate where the scan started it.

    The new model nests the old one (the added effect at zero is the old model), so started
    from the old model's values it fits the same data at least as well; the model file says
    where it started. A model of another base lends its effects' values and the base starts afresh (a base
    change `validate` prints); another axis cannot start it: one line, exit 2, nothing written.
    """
    base = tmp_path / "bs.json"
    assert endocal("fit", "hysteresis", run, "--axis", "ap", "--model", "bspline", "--effects", "delay",
                   "--out", base).returncode == 0
    out = tmp_path / "bs-dz.json"
    proc = endocal("fit", "hysteresis", run, "--axis", "ap", "--model", "bspline", "--effects", "delay,deadzone",
                   "--start-from", base, "--out", out)
    assert proc.returncode == 0, proc.stderr
    old, new = load_model(base), load_model(out)
    assert new.fit_report_.rmse_deg <= old.fit_report_.rmse_deg * (1 + 1e-9)
    assert new.provenance_["start_from"]["path"] == str(base)
    proc = endocal("fit", "hysteresis", run, "--axis", "ap", "--model", "linear", "--effects", "delay,deadzone",
                   "--start-from", out, "--out", tmp_path / "x.json")
    assert proc.returncode == 0, proc.stderr
    lin = load_model(tmp_path / "x.json")
    assert lin.provenance_["start_from"]["path"] == str(out) and lin.base_name == "linear"
    # the same fit as validate's scan makes of the base change (validation.bases.base_fit)
    from endocal.validation.bases import base_fit
    from endocal.validation.data import axis_data

    scanned = base_fit(new, "linear", axis_data(load_aligned(run), "ap"))
    assert scanned.params_ == pytest.approx(lin.params_, rel=1e-9)
    one_line_error(endocal("fit", "hysteresis", run, "--axis", "ml", "--model", "bspline", "--effects", "deadzone",
                           "--start-from", base, "--out", tmp_path / "y.json"), "that model is a model of axis ap")
    assert not (tmp_path / "y.json").exists()


def test_the_fit_states_its_sample_rate_and_questions_a_clock_in_ms(run, tmp_path):
    ok = endocal("fit", "hysteresis", run, "--axis", "ap", "--model", "linear", "--out", tmp_path / "a.json")
    assert ok.returncode == 0 and " Hz) from 1 source(s)" in ok.stdout and "is t_s in seconds" not in ok.stdout
    # the summary: the equation, the RMSE (what the model file holds), nothing to warn of; then the
    # file written and the next command
    rmse = load_model(tmp_path / "a.json").fit_report_.rmse_deg
    lines = ok.stdout.splitlines()
    assert len(lines) == 2 and lines[0].startswith("ap_deg = ") and lines[1].startswith(f"RMSE {rmse:.3f} deg on ")
    assert ok.stderr.splitlines() == [
        f"wrote {tmp_path / 'a.json'}", f"next: endocal validate {tmp_path / 'a.json'} RECORDS (records it was not fitted on)",
        f"  only this one record? endocal validate {tmp_path / 'a.json'} {run} --cv rolling (rolling origin: each "
        "candidate effect refitted on the record's start, scored on the stretch after it); or fit on part of the log "
        "and validate on the rest with --cv split"], ok.stderr
    table = load_aligned(run).table
    table["t_s"] *= 1000.0  # a lab's clock in ms written as t_s
    table.to_csv(tmp_path / "ms.csv", index=False)
    slow = endocal("fit", "hysteresis", tmp_path / "ms.csv", "--axis", "ap", "--model", "linear", "--out",
                   tmp_path / "b.json")
    # one line, with its key (the docs explain it) and the question
    assert slow.returncode == 0 and "warning[slow-clock]: 0.1 samples per second: is t_s in seconds?\n" in slow.stdout, \
        slow.stdout
    assert len(slow.stdout.splitlines()) == 3, slow.stdout
    slow = endocal("fit", "hysteresis", tmp_path / "ms.csv", "--axis", "ap", "--model", "linear", "--out",
                   tmp_path / "b.json", "--force", "--explain")
    assert slow.returncode == 0 and "is t_s in seconds? (a clock in ms reads 1000x too slow" in slow.stdout, slow.stdout
    val = endocal("validate", tmp_path / "a.json", tmp_path / "ms.csv", "--cv", "rolling")
    assert val.returncode == 0 and "warning[slow-clock]:" in val.stdout and "is t_s in seconds?" in val.stdout, val.stdout


def test_a_start_value_is_a_second_start_kept_where_it_ends_lower(run, tmp_path):
    """`--start-value` (what validate's refit commands give for an effect whose start the scan searched): the fit
    from those values is made beside the fit from `--start-from`, and the one ending lower on the data is kept,
    so a refit is never worse on its estimation data than either start: the model kept is the lower of the two
    fits, to the digit; a start at a fit's own values keeps that fit's minimum. Bad names and values, and part of
    an effect's parameters, are one line, exit code 2, nothing written."""
    base = tmp_path / "pi.json"
    assert endocal("fit", "hysteresis", run, "--axis", "ap", "--model", "pi", "--out", base).returncode == 0
    plain = tmp_path / "pi-dz.json"
    assert endocal("fit", "hysteresis", run, "--axis", "ap", "--model", "pi", "--effects", "deadzone",
                   "--start-from", base, "--out", plain).returncode == 0
    own = load_model(plain)
    far = tmp_path / "far.json"
    proc = endocal("fit", "hysteresis", run, "--axis", "ap", "--model", "pi", "--effects", "deadzone",
                   "--start-from", base, "--start-value", "deadzone_slack_deg=30", "--start-value",
                   "deadzone_band_deg=0", "--start-value", "deadzone_center_deg=20", "--out", far)
    assert proc.returncode == 0, proc.stderr
    from endocal.models import make_model
    from endocal.validation.data import axis_data

    # the far start alone (the fit --start-value adds beside the one from --start-from)
    d = axis_data(load_aligned(run), "ap")
    alone = make_model("pi", ["deadzone"], axis="ap").fit(d, warm_start={
        **load_model(base).params_, "deadzone_slack_deg": 30.0, "deadzone_band_deg": 0.0, "deadzone_center_deg": 20.0})
    kept = load_model(far)
    lower = min(own, alone, key=lambda m: m.fit_report_.rmse_deg)
    assert kept.fit_report_.rmse_deg == pytest.approx(lower.fit_report_.rmse_deg, rel=1e-12)
    assert kept.params_ == pytest.approx(lower.params_, rel=1e-9)
    at_own = {k: v for k, v in own.params_.items() if k.startswith("deadzone_")}
    again = tmp_path / "again.json"
    assert endocal("fit", "hysteresis", run, "--axis", "ap", "--model", "pi", "--effects", "deadzone",
                   "--start-from", base, *(a for k, v in at_own.items() for a in ("--start-value", f"{k}={v!r}")),
                   "--out", again).returncode == 0
    assert load_model(again).fit_report_.rmse_deg <= own.fit_report_.rmse_deg * (1 + 1e-9)
    one_line_error(endocal("fit", "hysteresis", run, "--axis", "ap", "--model", "pi", "--effects", "deadzone",
                           "--start-value", "delay_s=0.1", "--out", tmp_path / "a.json"),
                   "--start-value delay_s: no effect of this model has that parameter; its effects' parameters are: "
                   "deadzone_slack_deg, deadzone_band_deg, deadzone_center_deg")
    one_line_error(endocal("fit", "hysteresis", run, "--axis", "ap", "--model", "pi", "--effects", "deadzone",
                           "--start-value", "deadzone_slack_deg=wide", "--out", tmp_path / "b.json"), "finite number")
    one_line_error(endocal("fit", "hysteresis", run, "--axis", "ap", "--model", "pi", "--effects", "deadzone",
                           "--start-value", "deadzone_slack_deg", "--out", tmp_path / "c.json"), "expects key=value")
    # part of an effect's start would be silently unused (its start is searched as without it)
    one_line_error(endocal("fit", "hysteresis", run, "--axis", "ap", "--model", "pi", "--effects", "deadzone",
                           "--start-value", "deadzone_slack_deg=3", "--out", tmp_path / "d.json"),
                   "--start-value gives deadzone_slack_deg of effect 'deadzone' but not deadzone_band_deg, "
                   "deadzone_center_deg: give every free parameter of the effect, or none")
    assert not any((tmp_path / f"{n}.json").exists() for n in "abcd")
