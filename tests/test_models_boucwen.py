"""The smooth friction bases `bouc-wen` and `dahl` (endocal/models/boucwen.py, dahl.py): ground truth on
simulated data with known parameters, the exact branches against a Runge-Kutta integration, the missing
return-point memory, the inverse and its refusal, and the command line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from endocal.errors import CompensationRefusedError
from endocal.models import HysteresisData, load_model, make_model, save_model
from endocal.models._smooth_friction import BOUC_WEN, DAHL, friction_states
from tests._cli import endocal, one_line_exit_2

NOISE_DEG = 0.3
#: The tip holds at a reversal from saturation when k_lin = k_hys * rho * 2 sigma; these pick up at 0.2 deg/deg.
BW_TRUTH = {"bouc-wen_k_lin": 1.0, "bouc-wen_k_hys_deg": 5.0, "bouc-wen_rho": 0.1, "bouc-wen_sigma": 0.8,
            "bouc-wen_offset_deg": 1.0}
DAHL_TRUTH = {"dahl_k_lin": 1.0, "dahl_fc_deg": 5.0, "dahl_sigma0": 0.4, "dahl_offset_deg": 1.0}


def _record(truth: dict, seed: int = 0) -> HysteresisData:
    """A decaying sine of 50 deg at 0.05 Hz, 60 s at 50 Hz, through the base with ``truth``, plus 0.3 deg noise."""
    t = np.arange(0.0, 60.0, 0.02)
    u = 50.0 * np.sin(2 * np.pi * 0.05 * t) * (1.0 - t / 120.0)
    base = next(iter(truth)).split("_")[0]
    y = make_model(base).set_parameters(truth).predict(u)
    return HysteresisData(cmd_deg=u, meas_deg=y + NOISE_DEG * np.random.default_rng(seed).standard_normal(u.size), t_s=t)


@pytest.mark.parametrize("truth", [BW_TRUTH, DAHL_TRUTH], ids=["bouc-wen", "dahl"])
def test_the_fit_finds_the_parameters_it_was_simulated_with(truth):
    d = _record(truth)
    base = next(iter(truth)).split("_")[0]
    m = make_model(base, axis="ap").fit(d)
    # the noise floor, +2 % for five parameters fitted on 3000 samples
    assert m.fit_report_.rmse_deg < 1.02 * NOISE_DEG
    for name, value in truth.items():
        # within four standard errors (the errors come from the Jacobian at the optimum), and the
        # standard error itself small: the record identifies every parameter
        assert abs(m.params_[name] - value) <= 4 * m.stderr_[name] + 1e-9, (name, m.params_[name], m.stderr_[name])
        assert m.stderr_[name] < 0.05 * max(abs(value), 1.0)
    eq = str(m)
    assert eq.startswith("ap_deg = BoucWen(cmd)" if base == "bouc-wen" else "ap_deg = Dahl(cmd)") and "+-" in eq


@pytest.mark.parametrize("family, sigma", [(BOUC_WEN, 0.8), (BOUC_WEN, 2.5), (DAHL, 1.0)])
def test_the_exact_branches_match_a_runge_kutta_integration(family, sigma):
    """n = 1 (i = 1) is solved in closed form, piecewise by the sign of the state; an exponent a hair
    above 1 takes the Runge-Kutta path of other exponents. They must agree to the integrator's error."""
    u = np.concatenate([np.linspace(0, 40, 400), np.linspace(40, -30, 700), np.linspace(-30, 10, 400),
                        np.linspace(10, 0, 100), np.linspace(0, 35, 350)])
    starts = np.zeros(1, np.int64)
    exact = friction_states(family, u, 0.12, sigma, 1.0, starts)
    rk = friction_states(family, u, 0.12, sigma, 1.0 + 1e-9, starts)
    # the law changes form at w = 0, and the Runge-Kutta sub-step that crosses it loses its order: 1.4e-6 measured
    # for sigma = 2.5 (3e-10 for Dahl, smooth there); the closed form has no such step
    assert np.max(np.abs(exact - rk)) < 1e-5
    assert np.all(np.abs(exact) <= 1.0 + 1e-12)


@pytest.mark.parametrize("truth", [BW_TRUTH, DAHL_TRUTH], ids=["bouc-wen", "dahl"])
def test_a_small_reversal_inside_the_loop_does_not_return_to_the_branch_it_left(truth):
    """Return-point memory is what these bases lack and the plays have: up to 10 deg, back to 0 and up again
    passes 12 deg elsewhere than the straight sweep (by more than the noise), while a PI returns exactly."""
    base = next(iter(truth)).split("_")[0]
    straight = np.concatenate([np.linspace(0, -40, 400), np.linspace(-40, 12, 520)])
    minor = np.concatenate([np.linspace(0, -40, 400), np.linspace(-40, 10, 500), np.linspace(10, 0, 100),
                            np.linspace(0, 12, 120)])
    m = make_model(base).set_parameters(truth)
    assert abs(m.predict(minor)[-1] - m.predict(straight)[-1]) > NOISE_DEG
    assert not m.return_point_memory
    pi = make_model("pi", weights="exponential", offset=False).set_parameters({"pi_r": 1.5, "pi_w": 0.4, "pi_beta": 0.15})
    assert abs(pi.predict(minor)[-1] - pi.predict(straight)[-1]) < 1e-9 and pi.return_point_memory


@pytest.mark.parametrize("truth", [BW_TRUTH, DAHL_TRUTH], ids=["bouc-wen", "dahl"])
def test_the_inverse_compensates_and_survives_the_model_file(truth, tmp_path):
    d = _record(truth)
    base = next(iter(truth)).split("_")[0]
    m = make_model(base, ["envelope"], axis="ap").fit(d)
    desired = 30 * np.sin(np.linspace(0, 6 * np.pi, 1500)) * np.linspace(1, 0.3, 1500)
    cmd = m.inverse(desired, t_s=d.t_s[:1500])
    assert np.max(np.abs(m.predict(cmd, t_s=d.t_s[:1500]) - desired)) < 1e-6
    save_model(m, tmp_path / "m.json")
    m2 = load_model(tmp_path / "m.json")
    assert str(m2) == str(m) and json.loads((tmp_path / "m.json").read_text())["base"] == base
    np.testing.assert_array_equal(m2.inverse(desired, t_s=d.t_s[:1500]), cmd)


def test_a_base_whose_inverse_does_not_converge_refuses_compensation_in_one_line(tmp_path):
    """k_lin below k_hys * rho * 2 sigma: after a reversal the tip moves back while the knob moves on, so no
    command follows from an angle. The sweep check says so, naming the base; the model still predicts,
    validates and loads."""
    bad = {**BW_TRUTH, "bouc-wen_k_lin": 0.3}
    d = _record(bad)
    m = make_model("bouc-wen", axis="ap", fixed=bad).fit(d)
    with pytest.raises(CompensationRefusedError) as err:
        m.inverse(m.predict(0.8 * d.cmd_deg))
    msg = str(err.value)
    assert "\n" not in msg and "bouc-wen" in msg and "compensation refused" in msg
    with pytest.raises(CompensationRefusedError, match="compensation refused"):
        m.compensator()
    save_model(m, tmp_path / "bad.json")
    np.testing.assert_allclose(load_model(tmp_path / "bad.json").predict(d.cmd_deg), m.predict(d.cmd_deg))


def test_the_command_line_fits_validates_and_refuses_with_the_friction_bases(tmp_path):
    d = _record(BW_TRUTH).decimate(5)  # 600 samples at 10 Hz: the 0.05 Hz loops keep their shape, the scan is quick
    import pandas as pd

    for name, sl in (("fit", slice(0, 300)), ("val", slice(300, None))):
        pd.DataFrame({"t_s": d.t_s[sl] - d.t_s[sl][0], "ap_cmd_deg": d.cmd_deg[sl], "ap_meas_deg": d.meas_deg[sl]}).to_csv(
            tmp_path / f"{name}.csv", index=False)
    out = tmp_path / "bw.json"
    proc = endocal("fit", "hysteresis", tmp_path / "fit.csv", "--axis", "ap", "--model", "bouc-wen", "--set", "n=1",
                   "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("ap_deg = BoucWen(cmd)")
    assert load_model(out).base_name == "bouc-wen"
    proc = endocal("validate", out, tmp_path / "val.csv", "--json")
    assert proc.returncode == 0, proc.stderr
    v = json.loads(proc.stdout)
    # fitted on 300 samples: the parameters' own error adds a few per cent to the noise on an unseen record (1.11x)
    assert v["model"]["base"] == "bouc-wen" and v["metrics"]["rmse_deg"] < 1.2 * NOISE_DEG
    assert {b["base"] for b in v["scan"]["bases"]} == {"linear", "bspline", "pi", "dahl"}
    assert all(b["command"].startswith("endocal fit hysteresis") for b in v["scan"]["bases"])
    one_line_exit_2(endocal("fit", "hysteresis", tmp_path / "fit.csv", "--axis", "ap", "--model", "bouc-wen",
                            "--set", "n=0.5", "--out", tmp_path / "x.json"), "n (the Bouc-Wen exponent)")


# ------------------------------------------------------------------ rate:friction
#: the holding force twice its own at 62.5 deg/s, on the Dahl truth
SPEED_TRUTH = {**DAHL_TRUTH, "rate_friction_gain_s_per_deg": 0.016}


def _speed_record(seed: int = 0) -> HysteresisData:
    """Sines of 50 deg at 0.05, 0.2 and 0.5 Hz (up to 157 deg/s), 20 s each at 100 Hz, through Dahl with its
    holding force growing with speed (SPEED_TRUTH), plus 0.3 deg noise."""
    t = np.arange(0.0, 60.0, 0.01)
    f_hz = np.where(t < 20, 0.05, np.where(t < 40, 0.2, 0.5))
    u = 50.0 * np.sin(2 * np.pi * np.cumsum(f_hz) * 0.01)
    y = make_model("dahl", ["rate:friction"]).set_parameters(SPEED_TRUTH).predict(HysteresisData(cmd_deg=u, t_s=t))
    return HysteresisData(cmd_deg=u, meas_deg=y + NOISE_DEG * np.random.default_rng(seed).standard_normal(u.size), t_s=t)


def test_a_holding_force_growing_with_speed_is_found_as_simulated(tmp_path):
    d = _speed_record()
    m = make_model("dahl", ["rate:friction"], axis="ap").fit(d)
    assert m.fit_report_.rmse_deg < 1.02 * NOISE_DEG
    for name, value in SPEED_TRUTH.items():
        assert abs(m.params_[name] - value) <= 4 * m.stderr_[name] + 1e-9, (name, m.params_[name], m.stderr_[name])
    assert "rate:friction[gain_s_per_deg=" in str(m)
    # without it the base misses the fast sines, and the play widening with speed (rate) misses them too
    # (2026-11-29: 1.97 and 0.75 deg, against 0.298 with it)
    assert make_model("dahl", axis="ap").fit(d).fit_report_.rmse_deg > 3 * NOISE_DEG
    assert make_model("dahl", ["rate"], axis="ap").fit(d).fit_report_.rmse_deg > 2 * NOISE_DEG
    save_model(m, tmp_path / "m.json")
    back = load_model(tmp_path / "m.json")
    assert back.effects_[0].label == "rate:friction"
    assert np.max(np.abs(back.predict(d) - m.predict(d))) <= 1e-12


def test_a_friction_growing_with_speed_predicts_but_refuses_compensation_in_one_line():
    d = _speed_record()
    m = make_model("dahl", ["rate:friction"], axis="ap").set_parameters(SPEED_TRUTH)
    for refuse in (lambda: m.inverse(m.predict(d), t_s=d.t_s), lambda: m.compensator(dt_s=0.01)):
        with pytest.raises(CompensationRefusedError) as err:
            refuse()
        msg = str(err.value)
        assert "\n" not in msg and msg.startswith("effect 'rate:friction' has no inverse: ")
        assert "several commands" in msg and "compensation refused" in msg


@pytest.mark.parametrize("base", ["pi", "bspline", "linear"])
def test_a_base_without_a_friction_state_refuses_rate_friction_in_one_line(base, tmp_path):
    from endocal.errors import ModelError

    d = _speed_record()
    with pytest.raises(ModelError, match=f"the {base} base has none: fit --model dahl or bouc-wen"):
        make_model(base, ["rate:friction"]).fit(d)
    import pandas as pd

    pd.DataFrame({"t_s": d.t_s, "ap_cmd_deg": d.cmd_deg, "ap_meas_deg": d.meas_deg}).to_csv(tmp_path / "r.csv", index=False)
    one_line_exit_2(endocal("fit", "hysteresis", tmp_path / "r.csv", "--axis", "ap", "--model", base,
                            "--effects", "rate:friction", "--out", tmp_path / "x.json"), f"the {base} base has none")
