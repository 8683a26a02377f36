"""`endocal validate` on recordings as labs make them: one acquisition to fit, another to validate.

The estimation/validation scheme (endocal/validation/estimation.py, suspects.scan_split): the
model file names its training data, validate refits each candidate effect on it and scores it
on the validation record, unit by unit. Checked as a user runs it, through the real commands:
fit on one acquisition, validate on another, refit with the first suggestion, validate again.

- short records on the simulator (one back-and-forth sine each, the default probe with its
  tendon slack and tracker noise) and on real piezo data (one 1 Hz cycle each);
- a residual that points at an effect the scan cannot test is named, never "nothing missing"
  (the thesis's calibration workflow: tests/test_validate_thesis.py);
- bad input: moved or changed training data, another axis, --train equal to the data.
"""

from __future__ import annotations

import json
import re
import shlex
import shutil
from pathlib import Path

import pandas as pd
import pytest

from tests.test_cli_validate import _app, runner

PIEZO = Path(__file__).resolve().parents[1] / "data_samples" / "piezo" / "piezo_aligned.csv"

def _run(*args, ok=True):
    res = runner.invoke(_app(), [str(a) for a in args])
    if ok:
        assert res.exit_code == 0, res.output
    return res


def _one_line_exit_2(res, match):
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and match in lines[0] and "Traceback" not in res.output, res.output


def _validate_json(tmp, model, *data):
    out = tmp / (Path(model).stem + ".v.json")
    _run("validate", model, *data, "--json-out", out)
    return json.loads(out.read_text())


def _loop(tmp, model, val, first=None):
    """validate MODEL VAL (unless ``first`` holds its JSON already); run the first suggestion's refit
    command; validate the new model on VAL."""
    first = _validate_json(tmp, model, val) if first is None else first
    assert first["scheme"]["name"] == "estimation/validation", first["scheme"]
    assert first["suspects"], [(s["effect"], s["gain_pct"]) for s in first["scan"]["tested"]]
    cmd = shlex.split(first["suspects"][0]["command"])
    assert cmd[:3] == ["endocal", "fit", "hysteresis"] and str(val) not in cmd  # validation data not folded in
    _run(*cmd[1:], "--force")
    second = _validate_json(tmp, cmd[cmd.index("--out") + 1], val)
    for d in (first, second):
        # a model fitted on the estimation data is scored as it is, not refitted (a refit of a
        # B-spline + delay from its own values once stopped 68 % worse than the file it came from)
        assert d["heldout_rmse_deg"] == pytest.approx(d["metrics"]["rmse_deg"], rel=1e-12)
    if first["scan"]["cv"]["stride"] == 1 and not any("beyond the model's fitted range" in n for n in first["notes"]):
        # the printed refit is the fit the scan scored (it starts from the validated model as the
        # scan did): the suggestion's validation RMSE is the refit's, not a promise
        assert second["metrics"]["rmse_deg"] == pytest.approx(first["suspects"][0]["rmse_heldout_deg"], rel=1e-6)
    return first, second


@pytest.fixture(scope="module")
def sine_sweeps(tmp_path_factory):
    """Two acquisitions of one back-and-forth knob sweep each on the default simulated probe."""
    tmp = tmp_path_factory.mktemp("sweeps")
    _run("excite", "sine", "--set", "cycles=1", "--set", "frequency_hz=0.05", "--amplitude", "60",
         "--out", tmp / "est", "--seed", "1", "--quiet")
    _run("excite", "sine", "--set", "cycles=1", "--set", "frequency_hz=0.07", "--amplitude", "50",
         "--out", tmp / "val", "--seed", "2", "--quiet")
    _run("fit", "hysteresis", tmp / "est", "--axis", "ap", "--model", "pi", "--effects", "envelope",
         "--out", tmp / "pe.json")
    return tmp


def _validate_once(monkeypatch, result=None):
    """Every ``validate`` from here on renders one validation: ``result``, else the first one run.

    For commands that validate the same model on the same records and differ only in how they
    render it (the summary, --explain, --json-out): the validation is deterministic, and its
    scan's candidate refits are most of a command's time.
    """
    from endocal.validation import offline

    real, kept = offline.validate_offline, [] if result is None else [result]

    def once(*args, **kwargs):
        if not kept:
            kept.append(real(*args, **kwargs))
        return kept[0]

    monkeypatch.setattr(offline, "validate_offline", once)


@pytest.fixture(scope="module")
def pe_on_val(sine_sweeps):
    """``validate pe.json val --json-out``, run once for the tests that read it: (its JSON, the
    ValidationResult it rendered)."""
    from endocal.validation import offline

    tmp, real, kept = sine_sweeps, offline.validate_offline, []

    def keep(*args, **kwargs):
        kept.append(real(*args, **kwargs))
        return kept[-1]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(offline, "validate_offline", keep)
        d = _validate_json(tmp, tmp / "pe.json", tmp / "val")
    assert len(kept) == 1
    return d, kept[0]


def test_one_sweep_to_fit_one_to_validate_runs_the_whole_diagnosis(sine_sweeps, pe_on_val):
    tmp = sine_sweeps
    first, second = _loop(tmp, tmp / "pe.json", tmp / "val", first=pe_on_val[0])
    # the probe's tendon slack is what the paper's modified PI lacks: named first, and the refit
    # on the first sweep cuts the error on the second by far more than the 30 % bar
    assert first["suspects"][0]["effect"] == "deadzone"
    assert first["estimation"][0]["source"].endswith("est")
    before, after = first["metrics"]["rmse_deg"], second["metrics"]["rmse_deg"]
    assert after <= 0.7 * before, (before, after)
    # "watch the error fall" under the same scheme: the refit's validation RMSE is the scan's
    assert second["compare"]["old_heldout_rmse_deg"] == pytest.approx(first["heldout_rmse_deg"], rel=1e-9)
    assert second["compare"]["new_heldout_rmse_deg"] < second["compare"]["old_heldout_rmse_deg"]


def test_the_summary_fits_a_screen_and_explain_prints_everything(sine_sweeps, pe_on_val, monkeypatch):
    """The demo's kind of records (a PI + envelope fitted on one simulated acquisition, validated on
    another): by default at most 15 lines carry how far off (the RMSE and its interval), where (the
    worst regime), what is missing (the first suggestion, its gain and p), the untested suspects by
    name, and the refit command; ``--explain`` prints every metric, regime, candidate, suspect and
    note in full. One validation (pe_on_val's) is rendered both ways."""
    from endocal.shell import refit_command
    from endocal.cli.validate import SUMMARY_MAX_LINES
    from endocal.validation.metrics import METRIC_KEYS

    tmp, r = sine_sweeps, pe_on_val[1]
    _validate_once(monkeypatch, r)
    short = _run("validate", tmp / "pe.json", tmp / "val").stdout
    full = _run("validate", tmp / "pe.json", tmp / "val", "-v").stdout
    lines = short.splitlines()
    assert len(lines) <= SUMMARY_MAX_LINES == 15, short
    lo, hi = r.metrics.ci["rmse_deg"]
    assert lines[0].startswith(f"pi+envelope on axis ap: validation RMSE {r.metrics.rmse_deg:.3g} deg (95 % CI "
                               f"{lo:.3g} .. {hi:.3g})"), short
    w = r.regimes.worst(1)[0]
    assert f"worst regime: {w.group}: {w.name}: RMSE {w.metrics.rmse_deg:.3g} deg" in short, short
    s = r.suspects[0]
    assert s.effect == "deadzone" and s.significant
    assert (f"missing: deadzone: -{s.gain_pct:.0f} % validation RMSE ({s.base_rmse_heldout_deg:.3g} -> "
            f"{s.rmse_heldout_deg:.3g} deg), p = {s.p_value:.2g}") in short, short
    assert lines[-3:-1] == ["next: refit with deadzone, then validate the new model:", "  " + refit_command(s.refit)]
    if r.pointers:  # by name only: why and how to test them with --explain
        names = ", ".join(dict.fromkeys(p.effect for p in r.pointers))
        assert f"untested suspects: {names}" in lines and not any(p.why in short for p in r.pointers), short
    # every warning and note a line with its key, no longer than its fact
    keyed = [ln for ln in lines if ln.startswith(("warning[", "note["))]
    assert keyed and all(re.match(r"(warning|note)\[[a-z-]+\]: ", ln) for ln in keyed), short
    assert not any(n in short for n in r.notes if ": " in n), short
    # --explain: everything the summary leaves out, in full
    for k in METRIC_KEYS:
        assert k in full
    for w in r.regimes.worst(3):
        assert f"{w.group}: {w.name}: RMSE {w.metrics.rmse_deg:.3g} deg" in full
    for x in r.suspects:
        assert x.cause in full and x.signature in full and f"{x.effect}: -{x.gain_pct:.0f} %" in full
    for p in r.pointers:
        assert p.evidence in full and p.why in full and p.experiment in full
    for n in r.notes:
        assert f"note: {n}" in full
    assert r.model["equation"] in full and "  " + refit_command(s.refit) in full
    assert "Ljung-Box" in full and "estimation data:" in full


def test_bad_estimation_data_is_one_line_and_exit_2(sine_sweeps, tmp_path):
    tmp = sine_sweeps
    # training data recorded in the model moved: named, with the way forward
    moved = tmp_path / "m.json"
    d = json.loads((tmp / "pe.json").read_text())
    d["provenance"]["data"][0]["path"] = str(tmp_path / "gone")
    moved.write_text(json.dumps(d))
    _one_line_exit_2(_run("validate", moved, tmp / "val", ok=False), "not found: give the estimation data with --train")
    # changed since the fit (hash differs)
    d["provenance"]["data"][0]["path"] = str(tmp / "val")
    d["provenance"]["data"][0]["sha256"] = "0" * 64
    moved.write_text(json.dumps(d))
    _one_line_exit_2(_run("validate", moved, tmp / "est", ok=False), "has changed since the model was fitted")
    # estimation data of another axis than the model
    _one_line_exit_2(_run("validate", tmp / "pe.json", tmp / "val", "--train", PIEZO, ok=False),
                     "is for axis 'ap' but " + str(PIEZO) + " (estimation data) has axis piezo")
    # a validation record too short to test its residual; fewer than two rolling-origin blocks
    pd.read_csv(PIEZO).iloc[:1].rename(columns=lambda c: c.replace("piezo", "ap")).to_csv(tmp_path / "one.csv",
                                                                                        index=False)
    _one_line_exit_2(_run("validate", tmp / "pe.json", tmp_path / "one.csv", ok=False),
                     "1 sample(s) of axis ap; validation needs at least 4")
    _one_line_exit_2(_run("validate", tmp / "pe.json", tmp / "val", "--cv", "rolling", "--folds", "1", ok=False),
                     "--folds must be 2 or more")
    # --train with --cv rolling, an unknown --cv, an unknown --out-of-range
    _one_line_exit_2(_run("validate", tmp / "pe.json", tmp / "val", "--train", tmp / "est", "--cv", "rolling", ok=False),
                     "exclude each other")
    _one_line_exit_2(_run("validate", tmp / "pe.json", tmp / "val", "--cv", "kfold", ok=False), "--cv must be one of")
    _one_line_exit_2(_run("validate", tmp / "pe.json", "--protocol", "triangle", "--out-of-range", "wrap", ok=False),
                     "--out-of-range must be one of")


def test_train_equal_to_the_validation_data_warns_the_scores_are_in_sample(sine_sweeps):
    tmp = sine_sweeps
    d = _validate_json(tmp, tmp / "pe.json", tmp / "est")  # fitted on est, validated on est: rolling origin
    assert d["scheme"]["name"] in ("rolling-origin", "none") and "fitted on the data validated here" in d["scheme"]["reason"]
    with pytest.MonkeyPatch.context() as mp:  # the next two commands render one validation
        _validate_once(mp)
        explained = _run("validate", tmp / "pe.json", tmp / "est", "--train", tmp / "est", "--explain")
        out = tmp / "insample.v.json"
        summary = _run("validate", tmp / "pe.json", tmp / "est", "--train", tmp / "est", "--json-out", out)
    res = explained
    # said where the numbers are, not only in a note at the end: every RMSE line calls itself in-sample
    lines = res.stdout.splitlines()
    assert any(ln.startswith("warning: the estimation data includes the record validated here") for ln in lines)
    assert not any("validation RMSE" in ln for ln in lines), res.stdout
    assert any(ln.startswith("in-sample RMSE") for ln in lines), res.stdout
    # the summary too, its headline first, and the warning keyed
    res = summary
    lines = res.stdout.splitlines()
    assert "in-sample RMSE" in lines[0] and not any("validation RMSE" in ln for ln in lines), res.stdout
    assert "warning[in-sample]: the estimation data includes the record validated here" in lines, res.stdout
    # its refit commands fit the validated record too: not under the name of a refit on estimation data
    d = json.loads(out.read_text())
    outs = [shlex.split(s["command"]) for s in d["suspects"]]
    assert outs and all(c[c.index("--out") + 1].endswith("-insample.json") for c in outs), outs
    # a model refitted on estimation + validation data (--refit-on all) finds both in its file
    _run("fit", "hysteresis", tmp / "est", tmp / "val", "--axis", "ap", "--model", "linear", "--out", tmp / "both.json")
    d = _validate_json(tmp, tmp / "both.json", tmp / "val")
    assert d["scheme"]["name"] == "estimation/validation" and d["scheme"]["in_sample"] is True, d["scheme"]


def test_moved_run_folder_is_found_beside_the_model(sine_sweeps, tmp_path):
    """Recorded relative paths are also looked up relative to the model file's folder."""
    tmp = sine_sweeps
    shutil.copytree(tmp / "est", tmp_path / "est")
    # a linear model: the lookup is the same for every model, and its scan takes a second, not ten
    _run("fit", "hysteresis", tmp / "est", "--axis", "ap", "--model", "linear", "--out", tmp_path / "fitted.json")
    d = json.loads((tmp_path / "fitted.json").read_text())
    d["provenance"]["data"][0]["path"] = "est"
    (tmp_path / "m.json").write_text(json.dumps(d))
    v = _validate_json(tmp_path, tmp_path / "m.json", tmp / "val")
    assert v["scheme"]["name"] == "estimation/validation"


def test_records_named_relative_to_the_fit_folder_are_found_from_anywhere(sine_sweeps, tmp_path, monkeypatch):
    """A lab fits in its project folder (`fit runs/est --planes planes.json --out models/m.json`)
    and validates from another: the relative paths are looked up where the fit ran (recorded
    as provenance.cwd), not only in today's working folder or beside the model."""
    tmp = sine_sweeps
    proj = tmp_path / "proj"
    shutil.copytree(tmp / "est", proj / "runs" / "est")
    monkeypatch.chdir(proj)
    _run("fit", "hysteresis", "runs/est", "--axis", "ap", "--model", "linear", "--out", "models/m.json")
    assert json.loads((proj / "models" / "m.json").read_text())["provenance"]["cwd"] == str(proj)
    monkeypatch.chdir(tmp_path)
    v = _validate_json(tmp_path, "proj/models/m.json", tmp / "val")
    assert v["scheme"]["name"] == "estimation/validation" and v["estimation"][0]["source"].endswith("runs/est"), v["scheme"]


def test_report_ladder_follows_validates_scheme(sine_sweeps, pe_on_val):
    """The report's ladder scores a model fitted on another acquisition by the same
    estimation/validation split as validate: its held-out RMSE is validate's validation RMSE."""
    from endocal.report import build_report

    tmp, v = sine_sweeps, pe_on_val[0]
    rep = build_report([tmp / "pe.json"], [tmp / "val", tmp / "est"], regime_boot=0)
    on_val = next(s for s in rep.ladder if s["data"] == "val")
    assert on_val["scheme"] == "estimation/validation", on_val
    assert on_val["heldout_rmse_deg"] == pytest.approx(v["heldout_rmse_deg"], rel=1e-9)
    on_est = next(s for s in rep.ladder if s["data"] == "est")  # fitted on it: rolling origin, as validate would
    assert on_est["scheme"] in ("rolling-origin", None), on_est
    # the summary names the scheme its rungs ran
    _run("fit", "hysteresis", tmp / "est", "--axis", "ap", "--model", "pi", "--effects", "envelope,deadzone",
         "--start-from", tmp / "pe.json", "--out", tmp / "pe-dz.json", "--force")
    rep = build_report([tmp / "pe.json", tmp / "pe-dz.json"], [tmp / "val"], regime_boot=0)
    line = next(x for x in rep.summary_lines() if x.startswith("ladder val"))
    assert "(held-out RMSE deg, fitted on the estimation data)" in line, line
    # the rung's test is validate's: the same units of the validation record, the same p (before Holm)
    step = next(s for s in rep.ladder if s["data"] == "val" and s["model"] == "pe-dz")
    cand = next(t for t in v["scan"]["tested"] if t["effect"] == "deadzone")
    assert step["heldout_rmse_deg"] == pytest.approx(cand["rmse_heldout_deg"], rel=1e-9)
    assert step["p_value"] == pytest.approx(cand["p_raw"], rel=1e-9)


def test_a_zero_moved_between_the_records_is_named(sine_sweeps, tmp_path):
    """The base sensor re-seated between the records: the second sweep's angle is 3 deg off throughout."""
    tmp = sine_sweeps
    from endocal.runs.aligned import load_aligned

    table = load_aligned(tmp / "val").table.copy()
    table["ap_meas_deg"] += 3.0
    table.to_csv(tmp_path / "moved.csv", index=False)
    d = _validate_json(tmp_path, tmp / "pe.json", tmp_path / "moved.csv")
    drift = [p for p in d["pointers"] if p["effect"] == "drift"]
    assert drift and "shifting the prediction by +" in drift[0]["evidence"], d["pointers"]
    # the 3 deg put in, give or take the model's own mean error on this sweep: its 0.88 deg RMS (the
    # slack it lacks) has both signs along the loop, so the mean is a fraction of it (0.03 deg measured)
    assert d["shift"]["zero_deg"] == pytest.approx(3.0, abs=0.2)


def test_the_same_condition_names_no_change_between_the_records(pe_on_val):
    d = pe_on_val[0]
    assert not {"load", "drift"} & {p["effect"] for p in d["pointers"]}, d["pointers"]
    s = d["shift"]
    # the same sheath and the same zero: neither a zero shift nor a friction change explains the record
    # (measured: the zero 0.03 deg, leaving the 0.88 deg RMSE as it is; the friction change 0.77 deg, the
    # loop width taking up part of the slack the model lacks, which the scan names as deadzone instead)
    assert abs(s["zero_deg"]) < 0.2 and s["zero_rmse_deg"] > 0.95 * s["rmse_deg"], s
    assert s["friction_rmse_deg"] > 0.7 * s["rmse_deg"], s
    assert d["suspects"][0]["effect"] == "deadzone", d["suspects"]


def _wide_sweep_validated(tmp):
    """A `bspline` fitted on the 60 deg sweep, validated on a sweep to 70 deg: validate's JSON, the model (its
    predictions clamped at the fitted range), the sweep's data and the clamped prediction's RMSE (deg)."""
    import numpy as np

    from endocal.models import load_model
    from endocal.runs.aligned import load_aligned
    from endocal.validation.data import axis_data

    if not (tmp / "wide").exists():
        _run("excite", "sine", "--set", "cycles=1", "--set", "frequency_hz=0.04", "--amplitude", "70", "--out",
             tmp / "wide", "--seed", "3", "--quiet")
    _run("fit", "hysteresis", tmp / "est", "--axis", "ap", "--model", "bspline", "--out", tmp / "bs.json", "--force")
    d = _validate_json(tmp, tmp / "bs.json", tmp / "wide")
    model = load_model(tmp / "bs.json")
    model.out_of_range = "clamp"
    v = axis_data([load_aligned(tmp / "wide")], "ap")
    with pytest.warns(UserWarning):
        clamped = float(np.sqrt(np.mean((model.predict(v) - v.meas_deg) ** 2)))
    return d, model, v, clamped


def test_a_validation_sweep_wider_than_the_estimation_sweep_is_scored_on_the_model_continued(sine_sweeps):
    """A sweep to 70 deg validates a model fitted to 60 deg: beyond 60 the model's branches go on (the
    B-spline along its end tangents), as the tip does; a clamped prediction would stand still for
    10 deg of knob (about 8 deg of bend) and bury every physical effect under that artefact."""
    import numpy as np

    tmp = sine_sweeps
    d, model, v, clamped = _wide_sweep_validated(tmp)
    assert any("beyond the model's fitted range [-60, 60] deg" in n for n in d["notes"]), d["notes"]
    model.out_of_range = "extrapolate"
    continued = model.predict(v)
    model.out_of_range = "clamp"
    with pytest.warns(UserWarning):
        beyond = np.abs(continued - model.predict(v))[np.abs(v.cmd_deg) > 60.5]
    assert beyond.max() > 3.0, beyond.max()  # the branches go on: several deg from the clamped prediction
    # How well they go on is not the data's to say: the up branch's first span and the down branch's last, which
    # only a reversal reaches, are unidentified (no finite standard error), and so are the tangents the
    # continuation follows there (test_..._continued_rmse_depends_on_the_cpu)
    for name in ("bspline_up_dc1", "bspline_down_dc9"):
        assert not np.isfinite(model.stderr_[name]), (name, model.stderr_[name])
    assert d["metrics"]["rmse_deg"] < clamped, (d["metrics"]["rmse_deg"], clamped)
    # a sine to 70 deg spends a third of its time beyond 60 (|sin| > 6/7): said under the metrics,
    # before any diagnosis, not only in a note at the end
    n = d["data"][0]["n_samples"]
    assert d["beyond_samples"] == pytest.approx(n * (1 - 2 / np.pi * np.arcsin(6 / 7)), rel=0.1)
    res = _run("validate", tmp / "bs.json", tmp / "wide")
    assert f"warning[beyond-range]: {d['beyond_samples']} of {n} samples command beyond the model's fitted range" in res.stdout, \
        res.stdout


@pytest.mark.xfail(strict=False, reason=(
    "a finding (2026-12-08): the RMSE of the B-spline continued beyond its fitted range rests on end spans the data "
    "do not determine. Fitted on this machine with OpenBLAS's Haswell, SandyBridge and Nehalem kernels "
    "(OPENBLAS_CORETYPE), the validation RMSE is 0.795, 1.25 and 1.53 deg with the plain solver and 1.54, 0.785 and "
    "0.82 with the compressed one, against this bar of 1.34: it holds on some CPUs, not others, for both solvers"))
def test_the_continued_rmse_depends_on_the_cpu(sine_sweeps):
    """The bar the test above held until 2026-12-08: continued, 0.4x the clamped prediction's RMSE or better."""
    d, _, _, clamped = _wide_sweep_validated(sine_sweeps)
    assert d["metrics"]["rmse_deg"] <= 0.4 * clamped, (d["metrics"]["rmse_deg"], clamped)


def test_the_refit_folds_the_validation_data_in_only_when_asked(sine_sweeps, pe_on_val):
    tmp = sine_sweeps
    default = shlex.split(pe_on_val[0]["suspects"][0]["command"])
    assert str(tmp / "val") not in default
    out = tmp / "all.json"
    res = _run("validate", tmp / "pe.json", tmp / "val", "--refit-on", "all", "--json-out", out)
    assert "then validate the new model on a third record" in res.stdout, res.stdout
    cmd = shlex.split(json.loads(out.read_text())["suspects"][0]["command"])
    assert cmd[3:5] == [str(tmp / "est"), str(tmp / "val")], cmd
    # another model than the one the scan scored: not written under that one's name
    assert cmd[cmd.index("--out") + 1] == str(tmp / "pe-deadzone-all.json") != default[default.index("--out") + 1]
    _one_line_exit_2(_run("validate", tmp / "pe.json", tmp / "val", "--refit-on", "both", ok=False),
                     "--refit-on must be one of")


def test_a_record_mostly_beyond_the_fitted_range_gets_no_refit_command(sine_sweeps):
    # A sweep around 65 deg (45..85) validates a model fitted to +-60 deg: more than half of it
    # is extrapolated. A candidate's refit on the same estimation sweep cannot cover it, so
    # validate says to record covering data instead of printing a refit command.
    tmp = sine_sweeps
    _run("excite", "sine", "--set", "cycles=1", "--set", "frequency_hz=0.05", "--set", "offset_deg=65",
         "--amplitude", "20", "--out", tmp / "far", "--seed", "3", "--quiet")
    _run("fit", "hysteresis", tmp / "est", "--axis", "ap", "--model", "bspline", "--out", tmp / "bs-far.json",
         "--force")
    d = _validate_json(tmp, tmp / "bs-far.json", tmp / "far")
    assert d["beyond_samples"] > 0.5 * d["data"][0]["n_samples"] and d["suspects"], d["suspects"]
    res = _run("validate", tmp / "bs-far.json", tmp / "far")
    assert "next: refit on data that covers this record's commands" in res.stdout, res.stdout
    assert "endocal fit hysteresis" not in res.stdout
