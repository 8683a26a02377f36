"""Each effect of the simulator's catalog, switched on versus off, changes the data the way
its physics says. Short runs; tolerances argued from the noise floor or exact in comments."""

from __future__ import annotations

import numpy as np
import pytest

from endocal.sim import SimConfig
from tests.test_sim import branches, measured_angles, quiet, run, sine

STRAIGHT = {"y+": 0.0, "y-": 0.0, "x+": 0.0, "x-": 0.0}  # undeviated planes: eq. 1 = bend / 2 exactly


def _loop_area(cfg, f_hz, amp=60.0, cycles=2):
    """Area (deg^2) of the knob-position -> true-angle loop over the last cycle."""
    t, c = run(cfg, sine("ap", amp, f_hz), cycles / f_hz)
    sel = t >= (cycles - 1) / f_hz
    q, y = c.motor["ap_pos_deg"][sel], c.truth["ap_true_deg"][sel]
    return abs(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(q)))


def test_rate_loop_area_grows_with_frequency():
    off = SimConfig.default()
    on = off.replace(rate={"enabled": True})
    # Against the knob *position* the model is rate-independent without [rate] (quasi-static
    # tendons; the motor lag is outside this loop), so the area ratio is 1 up to the split of
    # each tick into knob and bend sub-steps, whose error grows with the knob step per tick
    # (1.9 deg at 0.5 Hz): a few percent. With [rate], mu_eff = mu(1 + 0.006 s/deg * up to
    # 190 deg/s) at 0.5 Hz, i.e. up to twice the friction, and the loop fattens by far more.
    ratio_off = _loop_area(off, 0.5) / _loop_area(off, 0.05)
    ratio_on = _loop_area(on, 0.5) / _loop_area(on, 0.05)
    assert ratio_off == pytest.approx(1.0, abs=0.05)
    assert ratio_on > ratio_off + 0.2


def _lag_s(cfg, seed=0):
    """Latency of the measured eq.-1 angle behind the true one, by least squares over lags."""
    t, c = run(cfg, sine("ap", 60, 0.5), 12.0, seed=seed)
    tf, a1, _, _ = measured_angles(c.tracker)
    keep = tf > 1.0
    lags = np.arange(0.0, 0.4, 0.0005)
    sse = [np.sum((a1[keep] - np.interp(tf[keep] - lag, t, c.truth["ap_true_deg"])) ** 2) for lag in lags]
    return lags[int(np.argmin(sse))]


def test_delay_shifts_measurements_by_the_latency():
    off = SimConfig.default()
    on = off.replace(delay={"enabled": True, "latency_s": 0.15})
    # True-angle slope up to ~90 deg/s, angle noise ~0.5 deg per frame over 440 frames: the
    # least-squares lag has a standard error well under 1 ms; allow 3 ms.
    assert _lag_s(off) == pytest.approx(0.015, abs=0.003)
    assert _lag_s(on) == pytest.approx(0.165, abs=0.003)


def test_drift_offset_grows_linearly():
    # Tip bent in the first axis' (undeviated) plane only: there the slip shifts the first angle
    # exactly by its rate and the second by its rate up to a 2nd-order cross term (see
    # endocal.sim.tracker.slip_quat).
    goals = lambda t: {"ap": np.full_like(t, 40.0)}

    def slopes(cfg):
        t, c = run(cfg, goals, 120.0, seed=1)
        tf, a1, a2, _ = measured_angles(c.tracker)
        keep = tf > 2.0
        out = []
        for a, k in ((a1, "ap_true_deg"), (a2, "ml_true_deg")):
            off = a[keep] - np.interp(tf[keep], t, c.truth[k])
            slope, _ = np.polyfit(tf[keep] / 60.0, off, 1)
            resid = off - np.polyval(np.polyfit(tf[keep] / 60.0, off, 1), tf[keep] / 60.0)
            out.append((slope, resid))
        return out

    base = SimConfig.default().replace(deviation_deg=STRAIGHT)
    (s1, r1), (s2, _) = slopes(base.replace(drift={"enabled": True, "rate_deg_per_min": [1.0, -0.5]}))
    # ~0.5 deg noise per frame, 4700 frames over ~2 min: slope SE ~0.015 deg/min; allow 0.06.
    assert s1 == pytest.approx(1.0, abs=0.06)
    assert s2 == pytest.approx(-0.5, abs=0.06)
    # Linear: no curvature left beyond the noise (a quadratic term would leave structure).
    assert np.std(r1) < 0.6
    (s1, _), (s2, _) = slopes(base)
    assert abs(s1) < 0.06 and abs(s2) < 0.06


def test_creep_keeps_moving_after_the_knob_stops_with_time_constant_tau():
    tau = 2.0
    goals = lambda t: {"ap": np.where(t >= 1.0, 50.0, 0.0)}
    on = quiet(deviation_deg=STRAIGHT, creep={"enabled": True, "fraction": 0.3, "time_constant_s": tau})
    t, c = run(on, goals, 16.0)
    y = c.truth["ap_true_deg"]
    late = (t > 1.5) & (t < 7.0)  # knob settled (its 30 ms loop has decayed by e^-16)
    y_inf = y[-1]  # 7.5 tau after the step: within e^-7.5 of equilibrium
    assert y[np.searchsorted(t, 1.5)] < y_inf - 2.0  # still well short of equilibrium
    slope, _ = np.polyfit(t[late], np.log(y_inf - y[late]), 1)
    # In-plane, eq. 1 is exactly half the bend and the bend relaxes exactly exponentially once
    # the tendons stop (friction holds them); e^-7.5 of the remainder biases tau by < 0.1 %.
    assert -1.0 / slope == pytest.approx(tau, rel=0.01)
    t, c = run(quiet(deviation_deg=STRAIGHT), goals, 16.0)
    # Without creep the angle only follows the knob's last 5e-5 deg of settling (30 ms loop, 0.5 s on).
    assert np.ptp(c.truth["ap_true_deg"][t > 1.5]) < 1e-3


def test_coupling_moving_only_knob_2_changes_axis_1():
    goals = sine("ml", 70, 0.1)
    off = quiet(deviation_deg=STRAIGHT)
    t, c = run(off, goals, 20.0)
    # Undeviated planes and no coupling: the first axis' bend is exactly zero.
    assert np.abs(c.truth["ap_true_deg"]).max() < 1e-9
    t, c = run(off.replace(coupling={"enabled": True}), goals, 20.0)
    ap = c.truth["ap_true_deg"]
    # The second axis' bend (~1.7 rad) shifts the first axis' tendon anchors by 0.3 * 5 mm * 1.7
    # = 2.5 mm in opposite directions: far more than the friction backlash, so the first axis bends.
    assert np.ptp(ap) > 5.0
    # ... against the second bend (anchors moved as if the first axis had bent the other way).
    ml = c.truth["ml_true_deg"]
    assert np.corrcoef(ap, ml)[0, 1] < -0.8


def test_envelope_incremental_gain_falls_at_large_bends():
    def gain_ratio(cfg):
        t, c = run(cfg, sine("ap", 85, 0.05), 40.0)
        sel = t > 20.0
        up, _ = branches(c.motor["ap_pos_deg"][sel], c.truth["ap_true_deg"][sel], np.array([15.0, 30.0, 60.0, 80.0]))
        return ((up[3] - up[2]) / 20.0) / ((up[1] - up[0]) / 15.0)

    base = quiet(deviation_deg=STRAIGHT, deadzone={"enabled": False})
    off = gain_ratio(base.replace(envelope={"enabled": False}))
    on = gain_ratio(base)
    # Linear section: tension grows with the bend, so the capstan elongation eats a little more
    # knob travel at large bends, still near 1. Stiffening (beta_s = 110 deg, bends ~110 deg)
    # doubles the stiffness there and the gain drops clearly.
    assert off > 0.85
    assert on < off - 0.15


def test_deadzone_widens_the_frozen_band():
    def frozen_range(cfg):
        t, c = run(cfg, sine("ap", 40, 0.05), 40.0)
        sel = (t > 20) & (c.motor["ap_vel_degps"] < 0)
        q, y = c.motor["ap_pos_deg"][sel], c.truth["ap_true_deg"][sel]
        still = np.abs(np.diff(y)) < 1e-9
        return np.sum(np.abs(np.diff(q))[still])

    on = SimConfig.default()
    off = on.replace(deadzone={"enabled": False})
    # Default slack 1.5 mm minus the 0.53 mm pretension stretch, on both tendons, through a
    # 10 mm pulley: 2 * 0.97 / 10 rad = 11.1 deg of extra frozen knob travel.
    assert frozen_range(on) - frozen_range(off) == pytest.approx(np.degrees(2 * (1.5 - 4.0 * 1060 / 8000) / 10), rel=0.25)


def test_load_loop_width_follows_sheath_wrap():
    period = 40.0
    on = SimConfig.default().replace(load={"enabled": True, "mode": "sine", "amplitude_deg": 150.0, "period_s": period})
    f = 0.5

    def per_cycle(cfg):
        t, c = run(cfg, sine("ap", 60, f), 80.0)
        q, y, wrap = c.motor["ap_pos_deg"], c.truth["ap_true_deg"], c.motor["sheath_wrap_deg"]
        widths, wraps = [], []
        for k in range(1, int(80 * f)):
            sel = (t >= k / f) & (t < (k + 1) / f)
            up, dn = branches(q[sel], y[sel], np.linspace(-45, 45, 19))
            widths.append(np.mean(dn - up))
            wraps.append(wrap[sel].mean())
        return np.array(widths), np.array(wraps), t, wrap

    widths, wraps, t, wrap = per_cycle(on)
    np.testing.assert_allclose(wrap, 180.0 + 150.0 * np.sin(2 * np.pi * t / period))
    # Wrap 30..330 deg changes mu*Theta five-fold: the tension-dependent backlash follows it.
    assert np.corrcoef(widths, wraps)[0, 1] > 0.9
    assert widths.max() > widths.min() + 1.0
    widths, wraps, _, wrap = per_cycle(SimConfig.default())
    assert np.all(wrap == 180.0) and np.ptp(widths) < 0.05


def test_load_random_mode_is_bounded_seeded_and_slow():
    cfg = SimConfig.default().replace(load={"enabled": True, "amplitude_deg": 60.0, "bandwidth_hz": 0.02})
    _, a = run(cfg, None, 200.0, seed=1)
    _, b = run(cfg, None, 200.0, seed=2)
    wa, wb = a.motor["sheath_wrap_deg"], b.motor["sheath_wrap_deg"]
    assert np.all(np.abs(wa - 180.0) <= 60.0) and np.ptp(wa) > 10.0
    assert not np.allclose(wa, wb)
    # Band-limited to 0.02 Hz: at most 2*pi*0.02*60 = 7.5 deg/s, i.e. <= 0.075 deg per tick.
    assert np.abs(np.diff(wa)).max() <= 0.076


# -- foreign laws (issue 31 part 4): plants whose law is not the catalogue's ------------------------
def test_rate_law_linear_scales_the_slip_thresholds_not_the_friction_coefficient():
    off = SimConfig.default()
    linear = off.replace(rate={"enabled": True, "gain_s_per_deg": 0.012, "law": "linear"})
    capstan = off.replace(rate={"enabled": True, "gain_s_per_deg": 0.012})
    ratio_off = _loop_area(off, 0.5) / _loop_area(off, 0.05)
    ratio_lin = _loop_area(linear, 0.5) / _loop_area(linear, 0.05)
    # thresholds x (1 + 0.012 s/deg * up to 190 deg/s): up to 3.3 times the slip threshold at 0.5 Hz, so the
    # loop fattens with speed; the capstan's exponential of the same gain (mu*Theta up to 3.3 times) fattens
    # it differently: the two laws are two plants
    assert ratio_lin > ratio_off + 0.2
    assert abs(_loop_area(linear, 0.5) / _loop_area(capstan, 0.5) - 1.0) > 0.05


def test_creep_with_two_time_constants_relaxes_as_their_sum():
    goals = lambda t: {"ap": np.where(t >= 1.0, 50.0, 0.0)}
    a1, tau1, a2, tau2 = 0.15, 1.0, 0.15, 12.0
    base = quiet(deviation_deg=STRAIGHT)
    t, c = run(base.replace(creep={"enabled": True, "fraction": a1, "time_constant_s": tau1, "fraction2": a2,
                                   "time_constant2_s": tau2}), goals, 30.0)
    _, q = run(base, goals, 30.0)
    y, y_qs = c.truth["ap_true_deg"], q.truth["ap_true_deg"]
    jump = y_qs[-1] - y_qs[np.searchsorted(t, 0.9)]
    # in-plane, eq. 1 is half the bend and linear in it: the remainder is the jump times the two relaxations
    # (the knob's 30 ms loop shifts the step by ~0.06 s: 6 % of tau1's term at most; 2 % of the jump)
    for s in (2.0, 5.0, 10.0, 20.0):
        k = np.searchsorted(t, 1.0 + s)
        expected = a1 * np.exp(-s / tau1) + a2 * np.exp(-s / tau2)
        assert (y_qs[k] - y[k]) / jump == pytest.approx(expected, abs=0.02 * expected + 2e-3), s


def test_deadzone_center_moves_the_frozen_band_off_neutral():
    def band_end(cfg):
        """Knob angle (deg) where the falling branch's frozen stretch (the reversal's backlash, then the
        slack band) ends and the tip moves again."""
        t, c = run(cfg, sine("ap", 50, 0.05), 40.0)
        sel = (t > 20) & (c.motor["ap_vel_degps"] < 0)
        q, y = c.motor["ap_pos_deg"][sel], c.truth["ap_true_deg"][sel]
        still = np.abs(np.diff(y)) < 1e-9
        return float(q[1:][still].min())

    on = SimConfig.default()
    # the agonist has pulley_radius * 12 deg less slack than the antagonist: the band both tendons are slack
    # in moves by 12 deg of knob, and with it the knob angle where the antagonist takes up its slack (one
    # 25 ms tick of a 16 deg/s knob is 0.4 deg: the edge is read within that)
    assert band_end(on.replace(deadzone={"center_deg": 12.0})) - band_end(on) == pytest.approx(12.0, abs=0.5)
