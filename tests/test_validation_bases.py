"""validate scores the other bases (endocal/validation/bases.py): on a plant whose friction has no return-point
memory it names the base change with its refit and says that the base's memory rule misses the minor loops;
on a plant with it, it names none."""

from __future__ import annotations

import numpy as np
from endocal.models import HysteresisData, make_model
from endocal.validation.bases import minor_loop_mask, minor_loops, scan_bases_split
from endocal.validation.offline import validate_offline
from endocal.validation.predict import predict_errors
from endocal.validation.units import make_units
from endocal.views import validation_summary

NOISE_DEG = 0.3
#: A Bouc-Wen plant whose tip holds at a reversal from saturation (k_lin = k_hys * rho * 2 sigma), as in the issue.
BOUC_WEN = {"bouc-wen_k_lin": 1.0, "bouc-wen_k_hys_deg": 8.0, "bouc-wen_rho": 0.0625, "bouc-wen_sigma": 1.0,
            "bouc-wen_offset_deg": 0.0}
#: A bank of plays (return-point memory), the same loop height.
PLAYS = {"pi_r": 0.8, "pi_w": 0.12, "pi_beta": 0.05}


def _records(plant):
    """Estimation: a decaying sine (large sweeps, few small reversals); validation: three sines laid over each
    other (many small reversals inside the loop). 10 Hz (the loops are below 0.25 Hz), 0.3 deg noise."""
    t = np.arange(0.0, 90.0, 0.1)
    est = 55.0 * np.sin(2 * np.pi * 0.04 * t) * (1.0 - t / 140.0)
    val = 30 * np.sin(2 * np.pi * 0.03 * t) + 15 * np.sin(2 * np.pi * 0.11 * t + 1) + 8 * np.sin(2 * np.pi * 0.23 * t + 2)
    rng = np.random.default_rng(3)
    return [HysteresisData(cmd_deg=u, meas_deg=plant.predict(u) + NOISE_DEG * rng.standard_normal(u.size), t_s=t)
            for u in (est, val)]


def _plant(name: str):
    return (make_model("bouc-wen").set_parameters(BOUC_WEN) if name == "bouc-wen" else
            make_model("pi", weights="exponential", offset=False).set_parameters(PLAYS))


def test_a_plant_without_return_point_memory_gets_the_base_change_and_its_refit():
    est, val = _records(_plant("bouc-wen"))
    model = make_model("bspline", axis="ap").fit(est)
    res = validate_offline(model, val, train=est, model_path="m.json", n_boot=50)
    assert minor_loop_mask(val)[1] >= 3  # the validation record has the small reversals the estimation lacks
    change = res.scan.base_suggestions[0]
    assert change.base in ("bouc-wen", "dahl") and not change.return_point_memory
    # the B-spline's branches fit the sweeps and miss the minor loops; the right family reaches the noise
    assert change.gain_pct >= 50.0 and change.p_value < 0.05 and change.rmse_heldout_deg < 1.2 * NOISE_DEG
    assert (change.refit.base, change.refit.effects, change.refit.out_path) == (change.base, (), f"m-{change.base}.json")
    assert change.line().startswith(f"base: {change.base} lowers the validation RMSE by ")
    assert not res.clean
    assert any("misses the plant's minor loops" in n and "bspline base's memory rule" in n for n in res.notes), res.notes


def test_a_plant_with_return_point_memory_gets_no_base_change_and_no_minor_loop_note():
    """The plays' own base (`pi`) on a bank of plays: no other base gains (and a B-spline model there would
    rightly be told to take `pi`: its rule returns to the branch, its branch shapes are not the plays')."""
    est, val = _records(_plant("plays"))
    model = make_model("pi", axis="ap").fit(est)
    err = predict_errors(model, val)
    units = make_units(val, [err])
    bases = scan_bases_split(model, est, val, err, units, alpha=0.05, min_gain_pct=10.0, data_paths=["est"])
    assert {b.base for b in bases} == {"linear", "bspline", "bouc-wen", "dahl"}
    assert not any(b.significant for b in bases), [b.line() for b in bases]
    loops = minor_loops(model, val, err)
    assert loops.n_loops >= 3 and loops.ratio < 1.3 and not loops.note


def test_a_base_change_that_needs_an_effect_beside_it_is_tried_with_it():
    """A B-spline's free branches take up the plant's slack (a dead band on the tip's side of a Bouc-Wen
    element, 4 deg): the bases without return-point memory, with the model's effects alone, score worse than
    it, and the slack alone gains little. Where the minor-loop statistic points at the base, each of them is
    tried with the effect candidates that gained most; with the slack it reaches the noise."""
    plant = make_model("bouc-wen", ["deadzone:tip"]).set_parameters(
        {**BOUC_WEN, "deadzone_tip_slack_deg": 4.0, "deadzone_tip_band_deg": 0.0, "deadzone_tip_center_deg": 0.0})
    est, val = _records(plant)
    model = make_model("bspline", axis="ap").fit(est)
    res = validate_offline(model, val, train=est, model_path="m.json", n_boot=50)
    alone = {b.base: b for b in res.scan.bases if not b.added}
    # 2026-11-29: bouc-wen and dahl alone raise the validation RMSE by 31 and 30 %; the slack alone lowers it by 19 %
    assert alone["bouc-wen"].gain_pct < 0 and alone["dahl"].gain_pct < 0
    change = res.scan.base_suggestions[0]
    assert change.base in ("bouc-wen", "dahl") and change.added == ("deadzone:tip",), [b.line() for b in res.scan.bases]
    # 1.70 -> 0.295 deg (2026-11-29): the plant's structure, to the noise
    assert change.gain_pct >= 70.0 and change.p_value < 0.05 and change.rmse_heldout_deg < 1.1 * NOISE_DEG
    assert change.refit.effects == ("deadzone:tip",) and change.refit.out_path == f"m-{change.base}-deadzone-tip.json"
    assert change.line().startswith(f"base: {change.base} with deadzone:tip lowers the validation RMSE by ")
    lines = validation_summary(res)
    assert f"next: refit with the {change.base} base and deadzone:tip, then validate the new model:" in lines, lines


def test_a_base_change_whose_gain_is_its_effects_alone_is_not_suggested():
    from endocal.validation.bases import _joint_veto

    # the effect with the model's base scores 0.31 deg, with the other base 0.30: the base change earns 3 %
    why = _joint_veto("dahl", "deadzone:tip", 0.30, base_alone=2.2, effect_alone=0.31, min_gain_pct=10.0)
    assert why == ("deadzone:tip alone scores 0.31 deg against 0.3 together: the dahl base's own share, 3 %, is "
                   "under the 10 % bar")
    # the other base alone does the work: the effect earns nothing beside it
    assert _joint_veto("dahl", "envelope", 0.50, base_alone=0.52, effect_alone=2.0, min_gain_pct=10.0) == (
        "the dahl base alone scores 0.52 deg against 0.5 together: envelope's own share, 4 %, is under the 10 % bar")
    assert _joint_veto("dahl", "deadzone:tip", 0.30, base_alone=2.2, effect_alone=1.4, min_gain_pct=10.0) == ""


def test_a_base_change_goes_first_only_where_it_beats_the_effect_it_edges_out():
    """`scan.base_first`: the larger gain is not enough; the two refits are paired-tested against each other."""
    from types import SimpleNamespace

    from endocal.validation.bases import base_before_effect

    est, val = _records(_plant("bouc-wen"))
    rng = np.random.default_rng(7)
    err_effect = 0.5 * rng.standard_normal(val.n_samples)
    units = make_units(val, [err_effect])
    change = SimpleNamespace(name="bspline", gain_pct=13.0, rmse_heldout_deg=0.49)
    first = SimpleNamespace(effect="envelope", gain_pct=11.0, rmse_heldout_deg=0.50)
    # the base change's errors: the effect's, 2 % smaller and redrawn in part: no unit-by-unit evidence
    close = 0.98 * err_effect + 0.1 * rng.standard_normal(val.n_samples)
    ahead, note = base_before_effect(change, first, close, err_effect, units, 0.05)
    assert not ahead and note.startswith("base bspline (13 %) and envelope (11 %) lower the validation RMSE about "
                                         "equally") and note.endswith("envelope, the smaller change, first")
    # half the error, unit by unit: the base change first
    assert base_before_effect(change, first, 0.5 * err_effect, err_effect, units, 0.05) == (True, "")
    # a smaller gain never goes first; without an effect suspected, a base change does
    assert base_before_effect(SimpleNamespace(gain_pct=9.0), first, None, None, None, 0.05) == (False, "")
    assert base_before_effect(change, None, None, None, None, 0.05) == (True, "")


def test_a_change_of_memory_rule_is_judged_only_where_the_records_hold_small_reversals():
    """Return-point memory decides what follows a small reversal inside the loop, and nothing else: on a record
    without them (a plain sine) a base of the other rule gains only by its branch shapes, and is not suggested;
    a base of the same rule, or a record with small reversals, is judged as before."""
    from endocal.validation.bases import MINOR_MIN_LOOPS, memory_veto

    t = np.arange(0.0, 30.0, 0.01)
    plain = HysteresisData(cmd_deg=40.0 * np.sin(2 * np.pi * 0.2 * t), meas_deg=np.zeros(t.size), t_s=t)
    wiggly = HysteresisData(cmd_deg=40.0 * np.sin(2 * np.pi * 0.2 * t) + 6.0 * np.sin(2 * np.pi * 1.3 * t),
                            meas_deg=np.zeros(t.size), t_s=t)
    assert minor_loop_mask(plain)[1] == 0 and minor_loop_mask(wiggly)[1] >= MINOR_MIN_LOOPS
    assert memory_veto(make_model("bspline"), "dahl", plain) == (
        "a change of memory rule (to a base without return-point memory) that the validation data cannot judge: they "
        "hold 0 small reversal(s) inside the loop, where the rules differ (3 needed), so its gain is its branch "
        "shapes'; validate on a record with small reversals (a random run)")
    assert memory_veto(make_model("dahl"), "bspline", plain).startswith(
        "a change of memory rule (to a base with return-point memory) ")
    assert memory_veto(make_model("bspline"), "dahl", wiggly) == ""
    assert memory_veto(make_model("bspline"), "pi", plain) == ""
    assert memory_veto(make_model("dahl"), "bouc-wen", plain) == ""
    # the summary lists suggestions only: a base held back by its memory rule gets a note of its own
    from endocal.validation.bases import BaseCandidate, held_back

    held = BaseCandidate(base="dahl", gain_pct=19.0, p_value=0.004, p_raw=0.001, rmse_heldout_deg=0.81,
                         base_rmse_heldout_deg=1.0, significant=False, return_point_memory=False, refit=None)
    assert held_back(make_model("bspline"), [held], plain, 0.05, 10.0) == [
        "dahl lowers the validation RMSE by 19 % (p = 0.004) but is not suggested: a change of memory rule (to a "
        "base without return-point memory) that the validation data cannot judge: they hold 0 small reversal(s) "
        "inside the loop, where the rules differ (3 needed), so its gain is its branch shapes'; validate on a record "
        "with small reversals (a random run)"]
    assert held_back(make_model("bspline"), [held], wiggly, 0.05, 10.0) == []
