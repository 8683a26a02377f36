"""Test inputs of the duodenoscope paper (section 3.2), generated with numpy."""

import numpy as np

T_S = 20.0  # period T of the damped sine (s)
F_HZ = 0.05  # its frequency f (Hz)

PAPER_TABLE1 = {
    "envelope_theta0_deg": -8.174, "envelope_theta1_deg": 3.731, "envelope_theta2_deg": 7.27,
    "envelope_k0": 0.02846, "envelope_k1": 0.01111, "envelope_k2": 0.03495,
    "pi_r": 0.1183, "pi_w": 13.35, "pi_beta": 3.396,
}


def damped_sine(amp_deg=60.0, dt_s=0.01):
    """A sin(2πft) for 0 <= t < 2T, A sin(2πft) exp(-(t-2T)/(5T)) for 2T <= t <= 7T (paper, section 3.2)."""
    t = np.arange(0.0, 7 * T_S + dt_s / 2, dt_s)
    u = amp_deg * np.sin(2 * np.pi * F_HZ * t)
    late = t >= 2 * T_S
    u[late] *= np.exp(-(t[late] - 2 * T_S) / (5 * T_S))
    return t, u


def triangle(amp_deg=60.0, period_s=20.0, n_periods=3, dt_s=0.01):
    t = np.arange(0.0, n_periods * period_s, dt_s)
    phase = (t / period_s + 0.25) % 1.0
    return t, amp_deg * (4 * np.abs(phase - 0.5) - 1.0)


def chirp(amp_deg=60.0, f0_hz=0.02, f1_hz=0.2, duration_s=60.0, dt_s=0.01):
    t = np.arange(0.0, duration_s, dt_s)
    phase = 2 * np.pi * (f0_hz * t + 0.5 * (f1_hz - f0_hz) / duration_s * t ** 2)
    return t, amp_deg * np.sin(phase)


def non_periodic(amp_deg=60.0, duration_s=60.0, dt_s=0.01, seed=3):
    """Sum of incommensurate sines with random phases, scaled to peak ``amp_deg``."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, dt_s)
    freqs = np.array([0.031, 0.057 * np.sqrt(2), 0.11 / np.sqrt(3)])
    u = sum(np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) for f in freqs)
    return t, amp_deg * u / np.max(np.abs(u))
