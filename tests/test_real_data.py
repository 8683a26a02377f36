"""Real measured hysteresis nobody here generated: the piezo slice in data_samples/piezo."""

import functools
import json
import re
from pathlib import Path

import numpy as np
import pytest

from endocal.runs.aligned import load_aligned

PIEZO = Path(__file__).resolve().parents[1] / "data_samples" / "piezo" / "piezo_aligned.csv"
#: the RMSEs from rest and from the estimated start in a start note (validation.residuals.cut_start)
STARTED = re.compile(r"\(RMSE ([\d.]+) deg from the model's relaxed start, ([\d.]+) deg from this one\)")


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


@functools.cache
def _pi_from_cycle_0_on_cycle_4():
    """`pi` fitted on cycle 0 (the recording's first, a step from the stack's rest) and validated on
    cycle 4, estimation data cycle 0: (the model, the validation), shared by the tests that read it."""
    from endocal.models import make_model
    from endocal.validation.data import axis_data
    from endocal.validation.offline import validate_offline

    data = load_aligned(PIEZO)
    train = [_cycle(data, 0)]
    model = make_model("pi", axis="piezo").fit(axis_data(train, "piezo"))
    return model, validate_offline(model, [_cycle(data, 4)], train=train, model_path="m.json")


@pytest.mark.parametrize("est", [0, 7, 16])
def test_one_cycle_to_fit_one_to_validate_every_pair_the_first_suggestion_pays(est):
    """As a lab records: one acquisition to fit, another to validate, a cycle each, many pairs.

    validate must name a candidate that pays (the suggestion rule of suspects.scan_split), and
    the user's refit with it must cut the error on the unseen cycle by the issue's 30 % bar.
    The refit is what validate scored, so it never gets worse.

    Cycle 0 starts the recording with a step from the stack's rest, a start neither history of
    models.start gives: its first suggestion is `drift` (-40 % on cycles 4 and 19, at 2.9
    units/s, 3 % of the bend's mean speed, under the 5 % of a caution), which pays on the
    unseen cycles by taking up that step in the fit, not by any drift of the stack (0.02 units/s
    over the whole recording); validate's note on the estimation record says its start is not
    explained and a candidate may fit it.
    """
    from endocal.models import make_model
    from endocal.validation.data import axis_data
    from endocal.validation.offline import validate_offline
    from endocal.validation.predict import predict_extrapolated

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
        after = float(np.sqrt(np.mean((predict_extrapolated(refit, v)[0] - v.meas_deg) ** 2)))  # as validate scores it
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


def test_cycles_cut_from_one_recording_are_run_from_their_estimated_start():
    """Cycles cut from one continuous recording all start mid-swing, alike. Run from rest, a
    B-spline fitted on one is off by 0.56 on another, and a `drift` term lowered that by 42 % by
    following the time since each record began (5.8 units/s where the stack drifts 0.02 units/s;
    refitted with it, the model was off by 130 units on the whole recording). Each record run
    from its estimated start, the model is off by 0.19 (the fit's own 0.09 plus what one cycle
    does not pin down) and a drift fitted on such records no longer pays."""
    from endocal.models import make_model
    from endocal.validation.data import axis_data
    from endocal.validation.offline import validate_offline
    from endocal.validation.predict import predict_errors

    data = load_aligned(PIEZO)
    train = [_cycle(data, 7)]
    model = make_model("bspline", axis="piezo").fit(axis_data(train, "piezo"))
    assert model.fit_report_.estimated_starts, "the fitted cycle starts mid-swing too"
    val = _cycle(data, 19)
    res = validate_offline(model, [val], train=train, model_path="m.json")
    said = [n for n in res.notes if n.startswith("the validation record starts mid-swing")]
    assert len(said) == 1 and "run from an estimated start" in said[0], res.notes
    rest = float(STARTED.findall(said[0])[0][0])
    assert res.metrics.rmse_deg <= 0.5 * rest, (res.metrics.rmse_deg, rest)
    errors = predict_errors(model, axis_data([val], "piezo"))
    assert np.sqrt(np.mean(errors**2)) == pytest.approx(res.metrics.rmse_deg)
    drift = next(s for s in res.scan.tested if s.effect == "drift")
    assert drift.gain_pct < 0 and all(s.effect != "drift" for s in res.suspects), (drift.gain_pct, res.suspects)


def test_a_residual_that_follows_the_loop_is_never_called_nothing_missing():
    """`pi` fitted on cycle 0, which starts with a step from the stack's rest, is off by 1.97 on
    cycle 4 (0.59 from other cycles) and no candidate repairs it. Its residual stays correlated
    for 0.065 s, a fifth of the time between reversals (interpolated sensor noise: a few samples),
    so validate must not read "nothing is missing" off the scan alone."""
    res = _pi_from_cycle_0_on_cycle_4()[1]
    assert not res.suspects and not res.clean
    assert "the residual is not noise" in res.unexplained and "of a half-cycle" in res.unexplained


def test_a_record_cut_mid_swing_is_run_from_its_estimated_start():
    """Cut from the continuous recording at 1.8 V on the way down, a cycle starts where the stack's
    history left it, not where a model starts (as if the drive came from 0): run from rest, `pi`
    fitted on another cycle is off by 6.2 until the first reversal and 0.87 after it. Run as if
    the drive had come down from its top (the end the record moves away from first), it is off
    by 0.42 overall, what it is off on cycles that start where it assumes. validate says which
    start it took, with both numbers. Cut at the drive's 0 (the bottom of its sweep), the cycle
    came down from 3.6 V, not from a relaxed stack, and is run so too."""
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
    fitted = model.fit_report_.rmse_deg
    for a, words, path in ((3700, "mid-swing (command 1.8 deg within 0..3.6, moving down)", "1.8 -> 0 -> 3.6 -> 1.8"),
                           (3750, "at a turning point (command 0 deg within 0..3.6, moving up)", "0 -> 3.6 -> 0")):
        res = validate_offline(model, [cut(a)], train=train, model_path="m.json")
        said = [n for n in res.notes if n.startswith(f"the validation record starts {words}")]
        assert len(said) == 1 and f"as if the knob had come {path} deg before it" in said[0], res.notes
        rest, est = (float(x) for x in STARTED.findall(said[0])[0])
        assert est == pytest.approx(res.metrics.rmse_deg, abs=1e-3) and rest >= 5 * est, (rest, est)
        # another cycle of the same stack: within 1.5x the fit's own error (0.35), the noise and
        # what one cycle leaves loose
        assert est <= 1.5 * fitted, (est, fitted)


def test_a_start_neither_history_explains_is_still_said():
    """Cycle 0 starts the recording: a step from the stack's rest, a state neither the rest start
    nor a cut from the periodic drive gives (the estimated start leaves its first stretch far
    worse than the rest of it, so it is not taken). validate keeps the rest start and says the
    stretch before the first reversal measures the start."""
    model, res = _pi_from_cycle_0_on_cycle_4()
    assert not model.fit_report_.estimated_starts
    said = [n for n in res.notes if n.startswith("the estimation record starts")]
    assert len(said) == 1 and "No start tried predicts it" in said[0], res.notes
    before, after = (float(x) for x in re.findall(r"is ([\d.]+) deg RMS, [\d.]+x the ([\d.]+) deg", said[0])[0])
    assert before >= 2 * after


def test_fit_says_when_it_ran_its_record_from_an_estimated_start(tmp_path):
    """The B-spline starts a record on the mid-line between its branches; the cycle cut at 1.8 V
    on the way up was on the rising branch: off by 1.03 before the first reversal, 0.25 after.
    The fit runs it from its estimated start and says so."""
    from tests._cli import endocal

    data = load_aligned(PIEZO)
    part = data.table.iloc[1400:1600].copy()
    part["t_s"] -= part["t_s"].iloc[0]
    part.to_csv(tmp_path / "cut.csv", index=False)
    proc = endocal("fit", "hysteresis", tmp_path / "cut.csv", "--axis", "piezo", "--model", "bspline",
                   "--out", tmp_path / "m.json", "--explain")
    assert proc.returncode == 0, proc.stderr
    said = [line for line in proc.stdout.splitlines()
            if line.startswith("note: the fitted record starts mid-swing (command 1.8 deg within 0..3.6, moving up)")]
    assert len(said) == 1 and "run from an estimated start, as if the knob had come 0 -> 1.8 deg" in said[0], \
        proc.stdout
    rest, est = (float(x) for x in STARTED.findall(said[0])[0])
    # the start moves the stretch before the first reversal, a quarter of this record (measured: -40 %)
    assert est <= 0.75 * rest and f"RMSE {est:.3f} deg" in proc.stdout  # the fit's RMSE is from that start
    # the summary says it in one line, keyed (the docs explain the key)
    short = endocal("fit", "hysteresis", tmp_path / "cut.csv", "--axis", "piezo", "--model", "bspline",
                    "--out", tmp_path / "m.json", "--force")
    assert ("note[start-estimated]: the fitted record starts mid-swing (command 1.8 deg within 0..3.6, moving up)\n"
            in short.stdout), short.stdout


def test_the_verdict_that_the_residual_contradicts_prints_as_text(tmp_path):
    """The verdict line of an unexplained residual is styled like the others (no literal markup)."""
    from tests._cli import endocal

    data = load_aligned(PIEZO)
    for name, k in (("est", 0), ("val", 4)):
        _cycle(data, k).table.to_csv(tmp_path / f"{name}.csv", index=False)
    fit = endocal("fit", "hysteresis", tmp_path / "est.csv", "--axis", "piezo", "--model", "pi", "--out",
                  tmp_path / "m.json")
    assert fit.returncode == 0, fit.stderr
    val = endocal("validate", tmp_path / "m.json", tmp_path / "val.csv", "--explain")
    assert val.returncode == 0, val.stderr
    assert "Which effect is missing: no catalog effect lowers the validation RMSE" in val.stdout, val.stdout
    assert "[bold]" not in val.stdout and "[/]" not in val.stdout


def test_the_papers_pi_fits_one_piezo_cycle_from_0_v_below_a_two_branch_line():
    # One cycle of the piezo from 0 V (0 -> 3.6 -> 0 V, rows 150-350): `pi` + `envelope` ended at
    # 3.1, worse than `linear` (0.84). `auto` picks its weights from start values; its choice
    # here, free weights, ends at 3.4, worse than a straight line per direction of motion (1.7),
    # so the paper's law is fitted too and kept (0.33), and the fit report says so.
    from endocal.models import HysteresisData, make_model
    from endocal.models.pi import _branch_lines_rmse

    t = load_aligned(PIEZO).table.iloc[150:351]
    d = HysteresisData(cmd_deg=t["piezo_cmd_deg"].to_numpy(), meas_deg=t["piezo_meas_deg"].to_numpy(),
                       t_s=t["t_s"].to_numpy() - t["t_s"].iloc[0])
    free = make_model("pi", ["envelope"], weights="free").fit(d).fit_report_.rmse_deg
    auto = make_model("pi", ["envelope"]).fit(d)
    line = make_model("linear").fit(d).fit_report_.rmse_deg
    assert free > _branch_lines_rmse(d) and auto.structure_["weights"] == "exponential"
    assert auto.fit_report_.warnings[0].startswith("free weights fitted worse") and "law (eq. 8) taken" in \
        auto.fit_report_.warnings[0]
    assert auto.fit_report_.rmse_deg < 0.5 * line, (auto.fit_report_.rmse_deg, line)
