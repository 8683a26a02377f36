"""Pure signal generators (endocal/protocols/signals.py): each shape against its definition.

Tolerances: values computed by the same closed form in a different way agree to a few
ulps of the amplitude (1e-12 deg for A <= 100 deg). Frequencies estimated from zero
crossings located by linear interpolation between 100 Hz samples: near a crossing a sine
is linear up to a cubic term, so the crossing time error is ~(2 pi f dt)^2 / 6 of a
sample, below 1e-6 s at f <= 1 Hz; relative frequency errors stay below 1e-4.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from endocal.protocols import signals

FS = 100.0


def grid(duration_s: float, fs: float = FS) -> np.ndarray:
    return np.arange(int(round(duration_s * fs)) + 1) / fs


def zero_crossings(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Times where x changes sign, by linear interpolation; exact zeros at samples included once."""
    s = np.sign(x)
    idx = np.flatnonzero(s[:-1] * s[1:] < 0)
    tc = t[idx] - x[idx] * (t[idx + 1] - t[idx]) / (x[idx + 1] - x[idx])
    return np.sort(np.concatenate([tc, t[1:-1][x[1:-1] == 0.0]]))


def test_damped_sine_is_the_papers_formula_at_every_sample():
    A, f, T = 60.0, 0.05, 20.0
    t = grid(7 * T)
    x = signals.damped_sine(t, A, f, T)
    expected = np.array(
        [A * math.sin(2 * math.pi * f * ti) * (1.0 if ti < 2 * T else math.exp(-(ti - 2 * T) / (5 * T))) for ti in t]
    )
    assert t[-1] == pytest.approx(140.0, abs=1e-12)
    np.testing.assert_allclose(x, expected, rtol=0, atol=1e-12)
    # Continuous where the decay starts (exp(0) = 1) and ends at exp(-1) of a zero crossing.
    i = int(round(2 * T * FS))
    assert abs(x[i] - x[i - 1]) <= 2 * math.pi * f * A / FS
    assert abs(x[-1]) < 1e-12
    # The envelope decays with time constant 5T from 2T: |x| stays under it, and touches it
    # where sin = 1 (t = 6.25 T with f T = 1); before 2T the envelope is A.
    env = np.where(t < 2 * T, A, A * np.exp(-(t - 2 * T) / (5 * T)))
    assert np.all(np.abs(x) <= env * (1 + 1e-12))
    assert x[int(round(6.25 * T * FS))] == pytest.approx(A * math.exp(-0.85), rel=1e-12)
    assert x[int(round(0.25 * T * FS))] == pytest.approx(A, rel=1e-12)
    assert np.all(signals.damped_sine(np.array([-1.0, 7 * T + 0.01]), A, f, T) == 0.0)


def test_triangle_slopes_peaks_and_start():
    A, T = 45.0, 20.0
    t = grid(3 * T)
    x = signals.triangle(t, A, T)
    assert x[0] == 0.0 and abs(x[-1]) < 1e-12
    slope = np.diff(x) * FS
    corners = np.zeros_like(slope, bool)
    for k in range(13):  # corners at T/4 + k T/2; the sample pair straddling one has a mixed slope
        c = int(round((T / 4 + k * T / 2) * FS))
        corners[max(c - 1, 0) : c + 1] = True
    np.testing.assert_allclose(np.abs(slope[~corners]), 4 * A / T, rtol=1e-9)
    assert x[int(round(T / 4 * FS))] == pytest.approx(A, abs=1e-12)
    assert x[int(round(3 * T / 4 * FS))] == pytest.approx(-A, abs=1e-12)
    assert np.abs(x).max() == pytest.approx(A, abs=1e-12)


@pytest.mark.parametrize("method", ["linear", "log"])
def test_chirp_instantaneous_frequency_at_start_and_end(method):
    A, f0, f1, D = 30.0, 0.05, 0.8, 60.0
    t = grid(D)
    x = signals.chirp(t, A, f0, f1, D, method, fade_s=5.0)
    tc = zero_crossings(t[1:], x[1:])  # x[0] = 0 is the start, not a crossing
    tc = np.concatenate([[0.0], tc])
    tc = tc[tc < D - 1e-9]
    mid, dt = 0.5 * (tc[1:] + tc[:-1]), np.diff(tc)
    f_mean = 1.0 / (2.0 * dt)  # each half cycle advances the phase by pi
    if method == "linear":
        f_mid = f_mean  # the mean of a linear f over [a, b] is f at the midpoint, exactly
    else:
        # The mean of f0 k^(t/D) over [a, b] is f(mid) sinh(u)/u with u = ln(k) (b - a) / (2 D).
        u = math.log(f1 / f0) * dt / (2 * D)
        f_mid = f_mean * u / np.sinh(u)
    np.testing.assert_allclose(f_mid, signals.chirp_frequency_hz(mid, f0, f1, D, method), rtol=1e-4)
    # Instantaneous frequency at the start and the end, extrapolated from all half cycles.
    if method == "linear":
        slope, f_start = np.polyfit(mid, f_mid, 1)
        f_end = f_start + slope * D
    else:
        slope, log_f_start = np.polyfit(mid, np.log(f_mid), 1)
        f_start, f_end = math.exp(log_f_start), math.exp(log_f_start + slope * D)
        # Equal time per octave: f(D/2) is the geometric mean.
        assert signals.chirp_frequency_hz(D / 2, f0, f1, D, method) == pytest.approx(math.sqrt(f0 * f1), rel=1e-12)
    assert f_start == pytest.approx(f0, rel=1e-4)
    assert f_end == pytest.approx(f1, rel=1e-4)
    # Starts at zero, fades to exactly zero, and the fade leaves the earlier part untouched.
    assert x[0] == 0.0 and x[-1] == 0.0
    before = t <= D - 5.0
    np.testing.assert_allclose(
        x[before], A * np.sin(signals.chirp_phase_rad(t[before], f0, f1, D, method)), rtol=0, atol=1e-12
    )


def test_chirp_rejects_bad_method_and_log_from_zero():
    with pytest.raises(ValueError, match="linear"):
        signals.chirp_phase_rad(np.zeros(3), 0.1, 0.2, 10.0, "cubic")
    with pytest.raises(ValueError, match="f0_hz > 0"):
        signals.chirp_phase_rad(np.zeros(3), 0.0, 0.2, 10.0, "log")


def test_stepped_frequency_sine_frequencies_and_phase_continuity():
    A, freqs, n = 45.0, [0.04, 0.125], 2
    seg = [n / f for f in freqs]
    t = grid(sum(seg))
    x = signals.stepped_frequency_sine(t, A, freqs, n)
    # Phase-continuous: no sample-to-sample step larger than the fastest slope allows.
    assert np.abs(np.diff(x)).max() <= 2 * math.pi * max(freqs) * A / FS * (1 + 1e-9)
    phase = signals.stepped_frequency_phase_rad(t, freqs, n)
    assert np.abs(np.diff(phase)).max() <= 2 * math.pi * max(freqs) / FS * (1 + 1e-9)
    assert phase[-1] == pytest.approx(2 * math.pi * n * len(freqs), rel=1e-12)
    tc = zero_crossings(t, x)
    for k, f in enumerate(freqs):
        t0 = sum(seg[:k])
        inside = tc[(tc > t0 + 1e-6) & (tc < t0 + seg[k] - 1e-6)]
        assert inside.size == 2 * n - 1  # whole periods: crossings at every half period
        np.testing.assert_allclose(np.diff(inside), 1 / (2 * f), rtol=1e-4)
    assert abs(x[-1]) < 1e-12


class TestBandLimitedRandom:
    A, LO, HI, D = 40.0, 0.02, 0.3, 100.0

    def make(self, seed):
        return signals.band_limited_random(grid(self.D), self.A, self.LO, self.HI, self.D, seed)

    def test_same_seed_same_signal_different_seed_different(self):
        a, b, c = self.make(7), self.make(7), self.make(8)
        np.testing.assert_array_equal(a, b)
        # Independent random phases: the correlation of two draws is ~N(0, 1/(number of lines)),
        # |r| < 0.5 is more than 3 sigma with 29 lines.
        r = np.corrcoef(a, c)[0, 1]
        assert abs(r) < 0.5

    def test_band_limit_start_end_and_peak(self):
        x = self.make(3)
        assert abs(x[0]) < 1e-9 * self.A and abs(x[-1]) < 1e-9 * self.A
        # Peak magnitude equals the amplitude: samples never exceed it, and 100 Hz samples of a
        # <= 0.3 Hz signal miss the true peak by at most 1 - cos(pi 0.3 / 100) ~ 4e-5.
        assert np.abs(x).max() <= self.A * (1 + 1e-9)
        assert np.abs(x).max() >= self.A * (1 - 1e-4)
        # Periodic on the record with lines on the FFT grid: the spectrum outside the band is
        # rounding only (the brief asks < 1 %; anything above 1e-9 would mean leakage).
        spec = np.abs(np.fft.rfft(x[:-1])) ** 2
        f = np.fft.rfftfreq(x.size - 1, 1 / FS)
        inside = (f >= self.LO - 1e-12) & (f <= self.HI + 1e-12)
        assert spec[~inside].sum() / spec.sum() < 1e-9
        # Flat over the band: every line inside carries the same power.
        lines = spec[inside]
        np.testing.assert_allclose(lines, lines.mean(), rtol=1e-6)
        assert lines.size == int(self.D * self.HI) - int(self.D * self.LO) + 1

    def test_not_periodic_within_the_record(self):
        # The lowest line has one period per record: the two halves are not copies.
        x = self.make(5)
        n = (x.size - 1) // 2
        assert np.abs(x[:n] - x[n : 2 * n]).max() > 0.3 * self.A

    def test_empty_band_is_refused(self):
        with pytest.raises(ValueError, match="band"):
            signals.BandLimitedRandom(1.0, 0.101, 0.102, 10.0, 0)


def test_ramp_endpoints_exact_and_peak_speed():
    d = signals.ramp_duration_s(30.0, 20.0)
    assert d == pytest.approx(math.pi / 2 * 30.0 / 20.0)
    t = np.linspace(0, d, 100001)
    x = signals.ramp(t, 10.0, 40.0, d)
    assert x[0] == 10.0 and x[-1] == 40.0
    speed = np.diff(x) / np.diff(t)
    assert speed.max() == pytest.approx(20.0, rel=1e-6) and speed.min() >= 0
    assert signals.ramp(np.array([-1.0, d + 1]), 10.0, 40.0, d).tolist() == [10.0, 40.0]


def test_staircase_levels():
    lv = signals.staircase_levels(60.0, 3)
    np.testing.assert_allclose(lv, [20, 40, 60, 40, 20, 0, -20, -40, -60, -40, -20, 0], atol=1e-12)


def test_circle_radius_and_turn_rate():
    R, f, n, sp = 45.0, 0.05, 3, 5.0
    t = grid(2 * sp + n / f)
    a, b = signals.circle(t, R, f, n, sp)
    r = np.hypot(a, b)
    steady = (t >= sp) & (t <= sp + n / f)
    np.testing.assert_allclose(r[steady], R, rtol=0, atol=1e-12)
    assert r[0] == 0.0 and r[-1] < 1e-12
    assert np.all(np.diff(r[t <= sp]) >= 0)  # spirals out monotonically
    angle = np.unwrap(np.arctan2(a[steady], b[steady]))
    assert (angle[-1] - angle[0]) / (2 * math.pi) == pytest.approx(n, rel=1e-9)


def test_lissajous_axes_frequencies_and_ends():
    A, fr, D = 30.0, (0.05, 0.075), 80.0
    t = grid(D)
    a, b = signals.lissajous(t, A, fr, 90.0, D, 5.0)
    assert a[0] == 0.0 and b[0] == 0.0 and a[-1] == 0.0 and b[-1] == 0.0
    mid = (t > 5) & (t < D - 5)
    for x, f in ((a, fr[0]), (b, fr[1])):
        tc = zero_crossings(t[mid], x[mid])
        np.testing.assert_allclose(np.diff(tc), 1 / (2 * f), rtol=1e-4)
    assert max(np.abs(a).max(), np.abs(b).max()) == pytest.approx(A, rel=1e-3)
