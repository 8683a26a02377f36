"""Real measured hysteresis nobody here generated: the piezo slice in data_samples/piezo."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from endocal.runs.aligned import load_aligned

PIEZO = Path(__file__).resolve().parents[1] / "data_samples" / "piezo" / "piezo_aligned.csv"


def test_piezo_slice_loads_as_an_aligned_table_and_shows_hysteresis():
    data = load_aligned(PIEZO)
    assert data.axes == ["piezo"] and len(data.table) == 4000
    cmd, meas = data.cmd_deg("piezo"), data.meas_deg("piezo")
    rising = np.gradient(cmd) > 0
    # Same drive voltage, opposite directions: a hysteretic actuator sits on two branches.
    bins = np.linspace(1.2, 2.4, 7)  # mid-range voltages, visited in both directions every cycle
    gaps = []
    for lo, hi in zip(bins[:-1], bins[1:]):
        sel = (cmd >= lo) & (cmd < hi)
        gaps.append(meas[sel & rising].mean() - meas[sel & ~rising].mean())
    # Sensor noise from the sample-to-sample jitter after removing the smooth trend.
    noise = np.std(np.diff(meas, 2)) / np.sqrt(6)
    assert noise < 0.5
    assert min(abs(g) for g in gaps) > 20 * noise, (gaps, noise)
    assert np.all(np.sign(gaps) == np.sign(gaps[0]))  # one loop orientation throughout


def _cycle(data, k):
    """The k-th 1 Hz cycle (200 samples at 200 Hz) as its own record, its clock from 0."""
    from endocal.runs.aligned import AlignedData

    part = data.table.iloc[200 * k: 200 * (k + 1)].copy()
    part["t_s"] -= part["t_s"].iloc[0]
    return AlignedData(part.reset_index(drop=True), ["piezo"], Path(f"cycle{k}.csv"), str(k) * 64, {})


@pytest.mark.parametrize("est", [pytest.param(0, marks=pytest.mark.xfail(strict=True, reason=(
    "cycle 0 starts with a step from the stack's rest: the model fitted on it is off by twice as much on any "
    "later cycle, and the one candidate that cut 40 % was creep, fitted and scored on records without a hold "
    "(its refits were worse on the whole recording), so it ranks after delay (-19 %) with its caution"))), 7, 16])
def test_one_cycle_to_fit_one_to_validate_every_pair_the_first_suggestion_pays(est):
    """As a lab records: one acquisition to fit, another to validate, a cycle each, many pairs.

    validate must name a candidate that pays (the suggestion rule of suspects.scan_split), and
    the user's refit with it must cut the error on the unseen cycle by the issue's 30 % bar.
    The refit is what validate scored, so it never gets worse.
    """
    from endocal.models import make_model
    from endocal.validation.data import axis_data
    from endocal.validation.offline import validate_offline

    data = load_aligned(PIEZO)
    train = [_cycle(data, est)]
    model = make_model("linear", axis="piezo").fit(axis_data(train, "piezo"))
    for val_k in (4, 19):
        val = _cycle(data, val_k)
        res = validate_offline(model, [val], train=train, model_path="m.json")
        assert res.scan.scheme == "estimation/validation" and res.suspects, res.scan.tested
        first = res.suspects[0]
        refit = make_model("linear", [first.effect], axis="piezo").fit(axis_data(train, "piezo"))
        v = axis_data([val], "piezo")
        after = float(np.sqrt(np.mean((refit.predict(v) - v.meas_deg) ** 2)))
        assert after == pytest.approx(first.rmse_heldout_deg, rel=1e-6)  # the suggestion's number is the refit's
        assert after <= 0.7 * res.metrics.rmse_deg, (est, val_k, first.effect, res.metrics.rmse_deg, after)
        assert not res.clean


def test_a_lab_table_with_text_and_gappy_columns_fits_and_validates(tmp_path):
    """Lab tables carry more than numbers: a fixture's name, a sensor column with empty cells.

    Neither can be a load, so both are left out of the data the models see; fit and validate
    run, and naming the gappy column as a load is one line saying why it is not read.
    """
    from tests._cli import endocal, one_line_exit_2

    data = load_aligned(PIEZO)
    for name, k, fixture in (("est", 7, "clamp A"), ("val", 4, "clamp B")):
        part = _cycle(data, k).table.assign(fixture=fixture, temp_c=21.0)
        part.loc[17, "temp_c"] = np.nan  # a thermometer that missed a reading
        part.to_csv(tmp_path / f"{name}.csv", index=False)
    fit = endocal("fit", "hysteresis", tmp_path / "est.csv", "--axis", "piezo", "--model", "linear",
                  "--out", tmp_path / "m.json")
    assert fit.returncode == 0, fit.stderr
    val = endocal("validate", tmp_path / "m.json", tmp_path / "val.csv", "--json-out", tmp_path / "v.json")
    assert val.returncode == 0, val.stderr
    assert json.loads((tmp_path / "v.json").read_text())["scheme"]["name"] == "estimation/validation"
    one_line_exit_2(endocal("fit", "hysteresis", tmp_path / "est.csv", "--axis", "piezo", "--model", "linear",
                            "--effects", "load:temp_c", "--out", tmp_path / "l.json"),
                    "no column 'temp_c'", "empty cells are not read")
    assert not (tmp_path / "l.json").exists()


def test_a_drift_that_follows_how_cut_cycles_start_is_not_the_first_suggestion():
    """Cycles cut from one continuous recording all start mid-swing, alike. Fitted on one and
    validated on another, a `drift` term lowers the validation error by 42 % by following the
    time since each record began: 5.8 units/s, 6 % of the bend's mean speed, where the stack
    really drifts 0.02 units/s (0.8 over the 40 s recording); refitted with it, the model is off by
    130 units on the whole recording (measured by hand). validate keeps the gain on the list but
    ranks it after the suggestions whose values their physics can have, and says why."""
    from endocal.models import make_model
    from endocal.validation.data import axis_data
    from endocal.validation.offline import validate_offline

    data = load_aligned(PIEZO)
    train = [_cycle(data, 7)]
    model = make_model("bspline", axis="piezo").fit(axis_data(train, "piezo"))
    res = validate_offline(model, [_cycle(data, 19)], train=train, model_path="m.json")
    drift = next(s for s in res.suspects if s.effect == "drift")
    assert "of the bend's mean speed" in drift.caution and "how the records start" in drift.caution, drift.caution
    first = res.suspects[0]
    assert not first.caution and first.effect != "drift"
    assert any(n.startswith(f"drift lowers the validation RMSE more than {first.effect}") for n in res.notes), res.notes


def test_a_residual_that_follows_the_loop_is_never_called_nothing_missing():
    """`pi` fitted on cycle 0, which starts with a step from the stack's rest, is off by 1.97 on
    cycle 4 (0.59 from other cycles) and no candidate repairs it. Its residual stays correlated
    for 0.065 s, a fifth of the time between reversals (interpolated sensor noise: a few samples),
    so validate must not read "nothing is missing" off the scan alone."""
    from endocal.models import make_model
    from endocal.validation.data import axis_data
    from endocal.validation.offline import validate_offline

    data = load_aligned(PIEZO)
    train = [_cycle(data, 0)]
    model = make_model("pi", axis="piezo").fit(axis_data(train, "piezo"))
    res = validate_offline(model, [_cycle(data, 4)], train=train, model_path="m.json")
    assert not res.suspects and not res.clean
    assert res.unexplained.startswith("the residual is not noise") and "of a half-cycle" in res.unexplained


def test_a_record_cut_mid_swing_is_said_to_measure_its_cut():
    """Cut from the continuous recording at 1.8 V on the way down, a cycle starts where the stack's
    history left it, not where a model starts (as if the drive came from 0): `pi` fitted on
    another cycle is off by 6.2 until the first reversal and 0.87 after it (0.59 on a cycle cut
    on the way up, where its start from 0 is the stack's own). validate says so with those
    numbers; the cycle cut at the drive's 0 starts where a homed knob would and is not called cut."""
    from endocal.models import make_model
    from endocal.runs.aligned import AlignedData
    from endocal.validation.data import axis_data
    from endocal.validation.offline import validate_offline

    data = load_aligned(PIEZO)

    def cut(a):
        part = data.table.iloc[a: a + 200].copy()
        part["t_s"] -= part["t_s"].iloc[0]
        return AlignedData(part.reset_index(drop=True), ["piezo"], Path(f"from{a}.csv"), str(a) * 16, {})

    train = [cut(1400)]
    model = make_model("pi", axis="piezo").fit(axis_data(train, "piezo"))
    down = validate_offline(model, [cut(3700)], train=train, model_path="m.json")
    said = [n for n in down.notes if n.startswith("the validation record starts mid-swing")]
    assert len(said) == 1 and "(command 1.8 deg within 0..3.6, moving down)" in said[0], down.notes
    before, after = (float(x) for x in re.findall(r"is ([\d.]+) deg RMS, [\d.]+x the ([\d.]+) deg", said[0])[0])
    assert before >= 5 * after  # the stretch before the first reversal carries the error
    at_zero = validate_offline(model, [cut(3750)], train=train, model_path="m.json")
    assert not any("starts" in n for n in at_zero.notes), at_zero.notes


def test_fit_warns_when_its_record_was_cut_mid_swing(tmp_path):
    """The B-spline starts a record on the mid-line between its branches; the cycle cut at 1.8 V
    on the way up was on the rising branch: off by 1.03 before the first reversal, 0.25 after."""
    from tests._cli import endocal

    data = load_aligned(PIEZO)
    part = data.table.iloc[1400:1600].copy()
    part["t_s"] -= part["t_s"].iloc[0]
    part.to_csv(tmp_path / "cut.csv", index=False)
    proc = endocal("fit", "hysteresis", tmp_path / "cut.csv", "--axis", "piezo", "--model", "bspline",
                   "--out", tmp_path / "m.json")
    assert proc.returncode == 0, proc.stderr
    assert "warning: the fitted record starts mid-swing (command 1.8 deg within 0..3.6, moving up)" in proc.stdout


def test_the_verdict_that_the_residual_contradicts_prints_as_text(tmp_path):
    """The verdict line of an unexplained residual is styled like the others (no literal markup)."""
    from tests._cli import endocal

    data = load_aligned(PIEZO)
    for name, k in (("est", 0), ("val", 4)):
        _cycle(data, k).table.to_csv(tmp_path / f"{name}.csv", index=False)
    fit = endocal("fit", "hysteresis", tmp_path / "est.csv", "--axis", "piezo", "--model", "pi", "--out",
                  tmp_path / "m.json")
    assert fit.returncode == 0, fit.stderr
    val = endocal("validate", tmp_path / "m.json", tmp_path / "val.csv")
    assert val.returncode == 0, val.stderr
    assert "Which effect is missing: no catalog effect lowers the validation RMSE" in val.stdout, val.stdout
    assert "[bold]" not in val.stdout and "[/]" not in val.stdout
