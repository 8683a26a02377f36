"""Where a record starts (models.start): ground truth on the paper's PI model, cut from a periodic run."""

import numpy as np
import pytest

from endocal.errors import ModelError
from endocal.models import HysteresisData, PIModel, make_model
from endocal.models.start import (estimate_starts, first_reversal, first_stretch_fraction, lead_in_paths, with_lead_in,
                                  with_lead_ins)
from tests._models_signals import PAPER_TABLE1

FS_HZ = 100.0


def truth():
    return PIModel(effects=["envelope"]).set_parameters(PAPER_TABLE1)


def periodic(cycles=4, period_s=10.0, amp_deg=50.0):
    """A homed knob swept ``cycles`` times: 0 -> +amp -> -amp -> ... (a sine from rest at 0)."""
    t = np.arange(int(cycles * period_s * FS_HZ)) / FS_HZ
    return t, amp_deg * np.sin(2 * np.pi * t / period_s)


def cut(t, u, y, a, n):
    return HysteresisData(cmd_deg=u[a:a + n], meas_deg=y[a:a + n], t_s=t[a:a + n] - t[a])


def test_a_cycle_cut_mid_swing_is_run_exactly_as_the_continuous_record_from_its_estimated_start():
    # One full sweep before the cut sets the state of every play narrower than the sweep as the
    # history did (the wiping-out property): from the estimated start the model reproduces the
    # continuous record within 0.03 deg (its widest plays, wider than the sweep, still remember
    # the knob's rest). From rest (as if it came up from 0 to where it moves down) it is 2.1 deg off.
    m = truth()
    t, u = periodic()
    y = m.predict(u)
    a = int(2.4 * 10 * FS_HZ)  # 29 deg on the way down from +50
    rec = cut(t, u, y, a, 1000)
    rest = m.predict(rec)
    assert np.sqrt(np.mean((rest - rec.meas_deg) ** 2)) > 1.0
    pred, starts = estimate_starts(m.predict, rec)
    # moving down: the lead-in goes down to -50, up to +50 and down to the cut, as the history did
    assert len(starts) == 1 and starts[0].path_deg == pytest.approx((u[a], u.min(), u.max(), u[a]), abs=0.1)
    assert np.max(np.abs(pred - rec.meas_deg)) < 0.03
    assert starts[0].rmse_estimated_deg < 0.01 * starts[0].rmse_rest_deg


def test_a_record_from_rest_keeps_the_models_own_start():
    m = truth()
    t, u = periodic(cycles=2)
    y = m.predict(u) + 0.3 * np.random.default_rng(0).standard_normal(u.size)
    pred, starts = estimate_starts(m.predict, HysteresisData(cmd_deg=u, meas_deg=y, t_s=t))
    assert starts == [] and np.array_equal(pred, m.predict(u))


def test_a_fit_on_a_cut_cycle_recovers_the_plant_as_one_from_rest():
    # Fitted from rest on the cut cycle, the stretch before its first reversal pulls the loop (the
    # true model is 2.1 deg off from rest there); fitted from the estimated start, the cycle's
    # error is the added noise (0.3 deg), and another cut of the plant is predicted as well.
    m = truth()
    t, u = periodic(cycles=6)
    rng = np.random.default_rng(1)
    y = m.predict(u) + 0.3 * rng.standard_normal(u.size)
    a = int(2.4 * 10 * FS_HZ)
    fitted = make_model("pi", ["envelope"]).fit(cut(t, u, y, a, 1200))
    assert fitted.fit_report_.estimated_starts and fitted.fit_report_.rmse_deg < 1.05 * 0.3
    other = cut(t, u, m.predict(u), int(1.4 * 10 * FS_HZ), 1200)  # noise-free: the model's own error
    pred, starts = estimate_starts(fitted.predict, other)
    assert starts and np.sqrt(np.mean((pred - other.meas_deg) ** 2)) < 0.3


def test_a_short_cut_whose_first_stretch_pulled_the_rest_fit_is_fitted_from_its_history():
    # One cycle cut at 47.6 deg on the way down: 45 % of it comes before its first reversal, and
    # the fit from rest bends the loop until the periodic start no longer predicts it better
    # (0.48 deg, no start taken). Fitted from each history in turn, the periodic one reaches
    # the added noise (0.3 deg) and is the start the model records.
    m = truth()
    t, u = periodic(cycles=6)
    y = m.predict(u) + 0.3 * np.random.default_rng(1).standard_normal(u.size)
    a = int(2.3 * 10 * FS_HZ)
    rec = cut(t, u, y, a, 1000)
    assert first_stretch_fraction(rec) > 0.4
    fitted = make_model("pi", ["envelope"]).fit(rec)
    (start,) = fitted.fit_report_.estimated_starts
    assert start["path_deg"] == pytest.approx([u[a], -50.0, 50.0, u[a]], abs=0.1)
    assert fitted.fit_report_.rmse_deg < 1.05 * 0.3


def test_the_same_cut_recorded_at_1_khz_is_screened_on_a_subsample_and_still_found():
    # The cut above at ten times the rate (10 000 samples): each history's fit screens on a
    # subsample of 4 000 (one of 2 here, a screening fit at full rate crawled for 90 s on a
    # 20 000-sample sweep), and the start it finds is estimated and fitted on every sample.
    m = truth()
    t = np.arange(60_000) / 1000.0
    u = 50.0 * np.sin(2 * np.pi * t / 10.0)
    y = m.predict(u) + 0.3 * np.random.default_rng(1).standard_normal(u.size)
    a = 23_000
    fitted = make_model("pi", ["envelope"]).fit(cut(t, u, y, a, 10_000))
    (start,) = fitted.fit_report_.estimated_starts
    assert start["path_deg"] == pytest.approx([u[a], -50.0, 50.0, u[a]], abs=0.1)
    assert fitted.fit_report_.rmse_deg < 1.05 * 0.3


def test_one_sweep_per_acquisition_starts_where_the_other_direction_left_the_tip():
    # A lab records each direction in turn: 0 -> +50 -> 0, then 0 -> -50 -> 0, then up again.
    # Each acquisition starts at knob 0 with the plays as the opposite sweep left them (the tip
    # still bent the other way), which neither rest nor a periodic cut (that would come down
    # from +50) reproduces: the mirrored sweep does, within 0.03 deg. A fit on such a record
    # takes that start (2.9 deg from rest) and reaches the added noise (the envelope's lower kink,
    # -8.2, is outside a sweep that never goes below 0, and is held at 0, neutral).
    m = truth()
    half = 0.5 * (1 - np.cos(2 * np.pi * np.arange(1000) / 1000))  # 0 -> 1 -> 0, at rest at both ends
    u = np.concatenate([50 * half, -50 * half, 50 * half])
    y = m.predict(u)
    third = HysteresisData(cmd_deg=u[2000:], meas_deg=y[2000:], t_s=np.arange(1000) / FS_HZ)
    assert np.sqrt(np.mean((m.predict(third) - third.meas_deg) ** 2)) > 0.5
    pred, starts = estimate_starts(m.predict, third)
    assert len(starts) == 1 and starts[0].path_deg == pytest.approx((0.0, -50.0, 0.0), abs=0.1)
    assert np.max(np.abs(pred - third.meas_deg)) < 0.03
    noisy = HysteresisData(cmd_deg=third.cmd_deg, t_s=third.t_s,
                           meas_deg=third.meas_deg + 0.3 * np.random.default_rng(2).standard_normal(1000))
    fitted = make_model("pi", ["envelope"]).fit(noisy)
    (start,) = fitted.fit_report_.estimated_starts
    assert start["path_deg"] == pytest.approx([0.0, -50.0, 0.0]) and start["rmse_rest_deg"] > 2.0
    assert fitted.fit_report_.rmse_deg < 1.05 * 0.3


def test_lead_in_paths_and_first_reversal():
    u = np.array([1.8, 1.0, 0.0, 1.0, 3.6, 2.0])
    # moving down: came down from the top; its mirror (-0) is inside its range
    assert lead_in_paths(u) == {"homed": (0.0, 1.8), "periodic": (1.8, 0.0, 3.6, 1.8)}
    # at its low end, 0: no homed lead-in, the periodic one a leg less, and the mirrored sweep
    assert lead_in_paths(np.array([0.0, 1.0, 3.6, 0.0])) == {"periodic": (0.0, 3.6, 0.0), "mirrored": (0.0, -3.6, 0.0)}
    assert lead_in_paths(np.full(5, 2.0)) == {}
    assert first_reversal(u) == 2 and first_reversal(np.arange(10.0)) is None


def test_a_lead_in_is_run_but_time_counts_from_the_record():
    # `drift` counts a record's time from its first sample, not from its lead-in's
    m = make_model("linear", ["drift"]).set_parameters(
        {"linear_up_slope": 1.0, "linear_up_offset_deg": 0.0, "linear_down_slope": 1.0,
         "linear_down_offset_deg": 0.0, "linear_transition_slope": 1.0, "drift_rate_dps": 0.5})
    t, u = periodic(cycles=1)
    rec = HysteresisData(cmd_deg=u[200:], t_s=t[200:] - t[200])
    led = with_lead_in(rec, lead_in_paths(rec.cmd_deg)["periodic"])
    n = int(led.lead_in[0])
    assert n > 0 and led.t_s[n] == 0.0 and np.all(np.diff(led.t_s) > 0)
    np.testing.assert_allclose(m.predict(led)[n:], m.predict(rec), atol=1e-12)
    both, keep = with_lead_ins(HysteresisData.from_runs([rec, rec]), [])
    assert keep.size == 2 * rec.n_samples and np.array_equal(both.cmd_deg, np.concatenate([u[200:]] * 2))


def test_a_lead_in_longer_than_its_run_is_refused():
    with pytest.raises(ModelError, match="lead_in"):
        HysteresisData(cmd_deg=np.zeros(5), lead_in=np.array([5]))
