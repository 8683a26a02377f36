"""`validate` proven on hidden effects: simulator data with one effect switched on that the model lacks.

For each effect the scan must rank it first, the refit with it must cut the held-out RMSE by at
least 50 % and bring it within 1.5x the noise floor; a control with nothing hidden lists
nothing. Then the loop on data from a generator that is not the simulator (Bouc-Wen
hysteresis with a transport delay, written here) and on real piezo data.

Noise floor: the simulator is run twice with the same seed, with and without tracker noise;
the RMS difference of the two measured angles is exactly the measurement noise that reaches
the aligned table (about 0.33 deg: 0.5 mm tracker noise, interpolated from 40 Hz frames onto
the 100 Hz motor clock). No model can predict it, so it is the floor of any held-out RMSE.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from endocal.models import HysteresisData, make_model
from endocal.probe import PRESETS
from endocal.protocols import load_protocol
from endocal.runs.aligned import AlignedData, align, check_aligned, load_aligned
from endocal.sim import SimConfig, Simulator
from endocal.validation.data import axis_data
from endocal.validation.offline import validate_offline

TEE = PRESETS["tee"]
PIEZO = Path(__file__).resolve().parents[1] / "data_samples" / "piezo" / "piezo_aligned.csv"
NO_SLACK = {"deadzone": {"enabled": False}}


def simulate(cfg: SimConfig, protocol: str, overrides=None, seed: int = 0):
    """Aligned table of a simulated run and its noise floor (deg, first axis)."""
    traj = load_protocol(protocol, overrides=overrides or {}).trajectory(TEE, seed=seed)

    def table(c):
        chunk = Simulator(c, TEE, seed=seed).execute(traj.t_s, traj.goal)
        return align(pd.DataFrame(chunk.motor), pd.DataFrame(chunk.tracker), TEE).table

    df = table(cfg)
    quiet = table(cfg.replace(tracker={"noise_mm": 0.0, "orientation_noise_deg": 0.0}))
    noise = float(np.sqrt(np.mean((df["ap_meas_deg"].to_numpy() - quiet["ap_meas_deg"].to_numpy()) ** 2)))
    # a digest of the table, as a file's would be: records that differ never look like one (a shared dummy digest
    # made `validate` call every score in-sample, as if the validated record were in the estimation data)
    digest = hashlib.sha256(pd.util.hash_pandas_object(df, index=False).to_numpy().tobytes()).hexdigest()
    return AlignedData(df, check_aligned(df, protocol), Path(f"runs/{protocol}"), digest, {}), noise


# An ideal servo and tracker without latency: no delay-like lag besides the one hidden.
NO_LAG = {"motor": {"knob_time_constant_s": 0.0}, "tracker": {"latency_s": 0.0}}

# hidden effect: (sim sections switched on, protocol, overrides, runs, model base, effects the model has)
CASES = {
    "drift": ({"drift": {"enabled": True, "rate_deg_per_min": [3.0, -1.0]}}, "sine", {"cycles": 6}, 1, "bspline", []),
    "delay": ({"delay": {"enabled": True}}, "random", {}, 1, "bspline", []),
    # friction coefficient mu (1 + 0.02 s/deg |knob speed|): a 45 deg sine alternating between
    # 0.1 and 0.4 Hz (two cycles each, three times) reaches 113 deg/s, where the sheath's
    # capstan exponent mu*Theta has grown 3.3-fold, and every held-out block holds both
    # speeds (on a chirp the last blocks are faster than anything their fit saw, and the
    # exponential width extrapolates: 1.45-1.49x the floor on four seeds, against 1.35-1.37x)
    "rate": ({"rate": {"enabled": True, "gain_s_per_deg": 0.02}, **NO_LAG}, "sine-varying",
             {"axes": ["axis1"], "frequencies_hz": [0.1, 0.4] * 3, "cycles": 2, "rest_s": 0.0}, 1, "bspline", []),
    "creep": ({"creep": {"enabled": True}}, "staircase", {}, 2, "bspline", []),
    "load": ({"load": {"enabled": True, "amplitude_deg": 150.0}}, "sine", {"cycles": 6}, 1, "bspline", []),
    # The servo (critically damped, 2 x 30 ms) and the tracker (15 ms) always lag the command by
    # ~80 ms. On the damped sine that lag opens loops in proportion to the decaying speed, which no
    # static term can follow, and one frequency cannot reveal it to the scan. A user of this rig
    # carries the `delay` term in every model (as the compensation test does), so this model has
    # it; the slack is what is hidden. (With it, bspline+delay+deadzone fits the noise-free run to
    # 0.015 deg: the lag, not the slack term, was the ~1.8x floor.)
    "deadzone": ({"deadzone": {"enabled": True}}, "damped-sine", {}, 1, "bspline", ["delay"]),
    # The bending section stiffens (M = K beta (1 + (beta/beta_s)^2)), strongly only at large
    # bends: a 75 deg sine (a 60 deg bend, 30 % stiffer) shows it on every cycle, so each
    # held-out block holds the full amplitude range (a damped sine's early large cycles have
    # to be extrapolated from the later small ones). The model is `linear` with `tension`:
    # the sheath's capstan friction grows with the tendon tension on every probe and in the
    # simulator always (not a switchable effect), so a user carries it as the deadzone model
    # carries `delay`; without it the envelope refit stays at 2.6x the floor (-57 %). No servo
    # or tracker lag, as in the rate case: with it the model needs `delay`, which at one
    # frequency takes up part of the stiffened loop's shape. `bspline` cannot test this at all:
    # its free branch shapes absorb any static shape. -63 %, 1.35x the floor (seeds 1, 2:
    # -60 %, 1.40x).
    "envelope": ({"envelope": {"enabled": True}, **NO_LAG}, "sine", {"amplitude_deg": 75.0, "cycles": 4}, 1,
                 "linear", ["tension"]),
    # both knobs on a circle: eq. 1 reads this axis from the tip both bends put there
    # (magnification, deviated half-planes), and the other bend shifts this axis's tendon
    # anchors. Five turns, so each of the five held-out blocks spans a whole turn (with the
    # protocol's three, a block is 70 % of a turn and its fit extrapolates the rest: 1.5-1.6x).
    "coupling": ({"coupling": {"enabled": True}}, "circle", {"cycles": 5}, 1, "bspline", []),
}


SCAN_SAMPLES = 3000  # the scan's decimation budget: 10-33 Hz here, loops <= 0.4 Hz (see scan_effects)


@functools.lru_cache(maxsize=None)
def _run_case(hidden):
    sections, protocol, overrides, n_runs, base, effects = CASES[hidden]
    cfg = SimConfig.default().replace(**NO_SLACK).replace(**sections)
    runs = [simulate(cfg, protocol, overrides, seed=seed) for seed in range(n_runs)]
    aligned = [a for a, _ in runs]
    noise = float(np.sqrt(np.mean([nf**2 for _, nf in runs])))
    model = make_model(base, effects, axis="ap").fit(axis_data(aligned, "ap"))
    return validate_offline(model, aligned, max_scan_samples=SCAN_SAMPLES, model_path="m.json"), noise


def _gap(reason):
    return pytest.mark.xfail(strict=True, raises=AssertionError, reason=reason)  # a crash is no expected miss


# Where the catalog effect, fitted onto the B-spline, does not (yet) reproduce the
# simulator's physics well enough; strict, so a fix shows up as an unexpected pass.
RANK_GAPS: dict[str, str] = {}
BAR_GAPS: dict[str, str] = {}


def _cases(gaps):
    return [pytest.param(h, marks=_gap(gaps[h])) if h in gaps else h for h in CASES]


@pytest.mark.parametrize("hidden", _cases(RANK_GAPS))
def test_hidden_effect_is_ranked_first(hidden):
    result, _ = _run_case(hidden)
    assert result.suspects, (hidden, [(s.effect, round(s.gain_pct, 1), s.p_value) for s in result.scan.tested])
    top = result.suspects[0]
    assert top.effect.partition(":")[0] == hidden, [(s.effect, round(s.gain_pct, 1)) for s in result.suspects]
    assert list(top.refit.effects) == CASES[hidden][5] + [top.effect]
    assert top.p_value < 0.05 and top.refit.out_path == f"m-{top.effect.replace(':', '-')}.json"


@pytest.mark.parametrize("hidden", _cases(BAR_GAPS))
def test_refit_with_the_hidden_effect_halves_the_error_and_reaches_the_noise_floor(hidden):
    result, noise = _run_case(hidden)
    top = {s.effect.partition(":")[0]: s for s in result.scan.tested}[hidden]
    assert top.gain_pct >= 50.0, top
    assert top.rmse_heldout_deg <= 1.5 * noise, (top.rmse_heldout_deg, noise)


def test_rate_refit_finds_the_capstan_exponent():
    # The simulator's sheath friction is mu (1 + gamma |knob speed|) over a wrap Theta, so the
    # capstan's tension ratio e^{mu Theta} grows by e^{mu Theta gamma |speed|}: the rate term's
    # kappa should be mu * Theta * gamma = 0.2 * pi * 0.02 s/deg = 0.0126 s/deg. The play is a
    # knob-side proxy of the distributed profile and the speed it reads is smoothed, so only
    # the order of magnitude is asserted (no other term in the model can take the curvature).
    # A chirp to 0.4 Hz sweeps every speed up to 113 deg/s, so the curvature of width against
    # speed is sampled throughout (fitted: 0.87x the truth); the two speeds of the hidden case
    # pin it less well (1.45x).
    cfg = SimConfig.default()
    sections = CASES["rate"][0]
    aligned, _ = simulate(cfg.replace(**NO_SLACK).replace(**sections), "chirp", {"f1_hz": 0.4})
    refit = make_model("bspline", ["rate"], axis="ap").fit(axis_data([aligned], "ap"))
    kappa_true = cfg.tendon.mu * np.radians(cfg.tendon.wrap_deg) * sections["rate"]["gain_s_per_deg"]
    assert 0.67 * kappa_true <= refit.params_["rate_capstan_s_per_deg"] <= 1.5 * kappa_true


def test_control_with_nothing_hidden_lists_nothing():
    # Single-frequency sine: the B-spline loop model is the right model class here (held-out
    # RMSE at the noise floor), so any suspect would be a false alarm.
    aligned, noise = simulate(SimConfig.default().replace(**NO_SLACK), "sine", {"cycles": 6})
    model = make_model("bspline", axis="ap").fit(axis_data(aligned, "ap"))
    result = validate_offline(model, aligned, max_scan_samples=SCAN_SAMPLES)
    assert result.suspects == ()
    # the model explains the data to the noise floor (held-out on the decimated scan grid)
    assert result.scan.baseline_rmse_heldout_deg <= 1.5 * noise
    assert result.metrics.rmse_deg <= 1.1 * noise
    # one frequency, no holds, one knob: the data cannot reveal these, and says so
    notes = " ".join(result.notes)
    assert "rate cannot be identified" in notes and "creep cannot be identified" in notes
    assert "coupling cannot be identified" in notes
    # nothing missing: no suspect, and the residual points at no effect the scan could not test
    assert result.clean and result.pointers == ()


def test_control_on_rich_data_lists_nothing():
    # Several frequencies, every speed and amplitude (random input), the rig's servo and
    # tracker lag carried by the model: every catalog effect the data can reveal is tested,
    # and none may be listed (the model is at 1.2x the floor held out, the rest is noise).
    aligned, noise = simulate(SimConfig.default().replace(**NO_SLACK), "random")
    model = make_model("bspline", ["delay"], axis="ap").fit(axis_data(aligned, "ap"))
    result = validate_offline(model, aligned, max_scan_samples=SCAN_SAMPLES)
    assert {s.effect for s in result.scan.tested} >= {"rate", "envelope", "deadzone", "drift"}
    assert result.suspects == (), [(s.effect, round(s.gain_pct, 1), s.p_value) for s in result.suspects]
    assert result.scan.baseline_rmse_heldout_deg <= 1.5 * noise


def _bouc_wen(u_deg, t_s, delay_s=0.2, seed=5):
    """Bouc-Wen hysteresis (Wen 1976) driven by the command ``delay_s`` ago, plus 0.3 deg noise.

    ``dz/du = A - (beta sign(du z) + gamma) |z|^n``, ``y = a u + (1 - a) k z``: a smooth
    hysteresis family the simulator's capstan equations do not produce.
    """
    u = np.interp(t_s - delay_s, t_s, u_deg)
    A, beta, gamma, n, a, k = 1.0, 0.04, 0.01, 1.0, 0.4, 1.0
    z = np.zeros_like(u)
    for i in range(1, u.size):
        du = u[i] - u[i - 1]
        z[i] = z[i - 1] + (A - (beta * np.sign(du * z[i - 1]) + gamma) * abs(z[i - 1]) ** n) * du
    y = a * u + (1 - a) * k * z
    return y + 0.3 * np.random.default_rng(seed).standard_normal(u.size)


def test_foreign_generator_bouc_wen_with_delay():
    # Full-amplitude cycles alternating between 0.07 and 0.19 Hz: two frequencies make a delay
    # identifiable (see the control's note), full swings keep the B-spline's loop model valid.
    dt = 0.02
    cycles = [-40 * np.cos(2 * np.pi * f * np.arange(0, 1 / f, dt)) for f in [0.07, 0.19] * 4]
    u = np.concatenate(cycles)
    t = np.arange(u.size) * dt
    data = HysteresisData(cmd_deg=u, meas_deg=_bouc_wen(u, t, delay_s=0.2), t_s=t)
    model = make_model("bspline", axis="bw").fit(data)
    result = validate_offline(model, data, max_scan_samples=SCAN_SAMPLES)
    top = result.suspects[0]
    assert top.effect == "delay" and top.gain_pct >= 50.0, result.scan.tested
    # Bouc-Wen loops are not B-spline branches: the refit stays above the 0.3 deg noise
    # (in-sample ~0.54 deg), so only the halving is asserted here, not the 1.5x floor.
    refit = make_model("bspline", ["delay"], axis="bw").fit(data)
    # and the refit finds the generator's delay (0.2 s, sampled every 20 ms)
    assert refit.params_["delay_s"] == pytest.approx(0.2, abs=0.03)


def test_real_piezo_data_runs_the_loop_and_the_refit_does_not_get_worse():
    # A model that lacks something on this real data, so that the loop refits: on the piezo slice a
    # B-spline's free branches take up the whole loop (validate finds no candidate that gains), a
    # straight-line base misses its rounded ends. The scan runs at 1500 samples (75 Hz, the 1 Hz
    # loops keep their shape). The refit is the one the suggestion names, built from its Refit.
    aligned = load_aligned(PIEZO)
    data = axis_data(aligned, "piezo")
    model = make_model("linear", axis="piezo").fit(data)
    result = validate_offline(model, aligned, max_scan_samples=1500)
    assert np.isfinite(result.metrics.rmse_deg) and result.metrics.ci
    for s in result.scan.tested:
        assert 0.0 <= s.p_value <= 1.0
    assert result.suspects, [(s.effect, round(s.gain_pct, 1), s.p_value) for s in result.scan.tested]
    top = result.suspects[0]
    assert top.significant and top.gain_pct >= 10.0
    fix = top.refit
    assert (fix.base, fix.effects) == ("linear", (top.effect,))
    refit = make_model(fix.base, list(fix.effects), **fix.settings, axis="piezo").fit(data)
    again = validate_offline(refit, aligned, max_scan_samples=1500, compare=model)
    # the held-out RMSE falls by the gain the scan measured (the same folds refit the same structure)
    assert again.compare.old_heldout_rmse_deg == pytest.approx(result.scan.baseline_rmse_heldout_deg, rel=1e-9)
    assert again.compare.new_heldout_rmse_deg <= 0.9 * again.compare.old_heldout_rmse_deg
    assert again.compare.new_heldout_rmse_deg == pytest.approx(top.rmse_heldout_deg, rel=0.05)