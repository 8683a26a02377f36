"""Speed of the hysteresis models (issue 4). Prints; asserts nothing.

Targets: fitting the modified PI (pi + envelope) on 100 000 samples in <= 2 s; batch
inverse >= 1 million samples/s; one streaming compensation step <= 20 µs. Each is
shown beside a plain-Python reference implementation of the same model in the same
run, as a ratio.

Run: ``.venv/bin/python bench/bench_models.py``
"""

from __future__ import annotations

import math
import time

import numpy as np

from endocal.models import PIModel, StreamingCompensator
from endocal.models.pi import pi_exp_weights, pi_inverse_parameters, pi_thresholds

TABLE1 = {
    "envelope_theta0_deg": -8.174, "envelope_theta1_deg": 3.731, "envelope_theta2_deg": 7.27,
    "envelope_k0": 0.02846, "envelope_k1": 0.01111, "envelope_k2": 0.03495,
    "pi_r": 0.1183, "pi_w": 13.35, "pi_beta": 3.396,
}


# ---------------------------------------------------------------- plain-Python reference
def ref_envelope(th, p):
    t0, t1, t2 = p["envelope_theta0_deg"], p["envelope_theta1_deg"], p["envelope_theta2_deg"]
    k0, k1, k2 = p["envelope_k0"], p["envelope_k1"], p["envelope_k2"]
    if th < t0:
        return k0 * (th - t0) + k1 * (t0 - t1)
    if th > t2:
        return k2 * (th - t2) + k1 * (t2 - t1)
    return k1 * (th - t1)


def ref_envelope_inv(x, p):
    t0, t1, t2 = p["envelope_theta0_deg"], p["envelope_theta1_deg"], p["envelope_theta2_deg"]
    k0, k1, k2 = p["envelope_k0"], p["envelope_k1"], p["envelope_k2"]
    if x < k1 * (t0 - t1):
        return (x - k1 * (t0 - t1)) / k0 + t0
    if x > k1 * (t2 - t1):
        return (x - k1 * (t2 - t1)) / k2 + t2
    return x / k1 + t1


def ref_forward(u, p, n=20):
    r = [p["pi_r"] * i for i in range(n + 1)]
    w = [p["pi_w"] * math.exp(-p["pi_beta"] * ri) for ri in r]
    z = [0.0] * (n + 1)
    out = []
    for th in u:
        x = ref_envelope(th, p)
        acc = 0.0
        for i in range(n + 1):
            z[i] = max(x - r[i], min(x + r[i], z[i]))
            acc += w[i] * z[i]
        out.append(acc)
    return out


class RefStepper:
    def __init__(self, p, n=20):
        r = pi_thresholds(p["pi_r"], n)
        rp, wp = pi_inverse_parameters(r, pi_exp_weights(p["pi_w"], p["pi_beta"], r))
        self.rp, self.wp, self.p = [float(x) for x in rp], [float(x) for x in wp], p
        self.z = [0.0] * (n + 1)

    def step(self, y):
        acc = 0.0
        z, rp, wp = self.z, self.rp, self.wp
        for i in range(len(z)):
            z[i] = max(y - rp[i], min(y + rp[i], z[i]))
            acc += wp[i] * z[i]
        return ref_envelope_inv(acc, self.p)


def best_of(fn, repeat=3):
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    n = 100_000
    t = np.linspace(0.0, 140.0, n)
    u = 60 * np.sin(2 * np.pi * 0.05 * t)
    u[t >= 40] *= np.exp(-(t[t >= 40] - 40) / 100)
    truth = PIModel(effects=["envelope"]).set_parameters(TABLE1)
    y = truth.predict(u) + 0.3 * np.random.default_rng(0).standard_normal(n)

    # warm up numba (compiled code is cached on disk after the first run)
    PIModel(effects=["envelope"]).fit(u[:20000], y[:20000])
    truth.inverse(y[:1000])

    # 1. fit on 100 000 samples
    holder = {}
    t_fit = best_of(lambda: holder.setdefault("m", PIModel(effects=["envelope"]).fit(u, y)), repeat=2)
    m = PIModel(effects=["envelope"]).fit(u, y)
    rep = m.fit_report_
    t_fwd = best_of(lambda: truth.predict(u), repeat=5)
    t_ref_fwd = best_of(lambda: ref_forward(u[:10000], TABLE1), repeat=1) * n / 10000
    print(f"fit modified PI, {n} samples: {t_fit:.2f} s (target <= 2 s); {rep.nfev} evaluations, "
          f"{rep.njev} Jacobians, rmse {rep.rmse_deg:.3f} deg")
    print(f"  one forward pass: {t_fwd * 1e3:.1f} ms vs plain Python {t_ref_fwd * 1e3:.0f} ms "
          f"(x{t_ref_fwd / t_fwd:.0f}); the fit at plain-Python speed would take ~{t_fit * t_ref_fwd / t_fwd:.0f} s")

    # 2. batch inverse
    y_des = truth.predict(0.9 * u)
    t_inv = best_of(lambda: truth.inverse(y_des), repeat=5)
    ref = RefStepper(TABLE1)
    t_ref_inv = best_of(lambda: [ref.step(v) for v in y_des[:20000]], repeat=1) * n / 20000
    print(f"batch inverse: {n / t_inv / 1e6:.2f} M samples/s (target >= 1), plain Python "
          f"{n / t_ref_inv / 1e6:.3f} M samples/s (x{t_ref_inv / t_inv:.0f})")

    # 3. streaming step
    comp = StreamingCompensator(truth)
    seq = [float(v) for v in y_des[:20000]]
    comp.reset()
    step = comp.step
    t_step = best_of(lambda: [step(v) for v in seq], repeat=3) / len(seq)
    ref = RefStepper(TABLE1)
    t_ref_step = best_of(lambda: [ref.step(v) for v in seq], repeat=1) / len(seq)
    print(f"streaming step: {t_step * 1e6:.2f} us (target <= 20 us), plain Python {t_ref_step * 1e6:.1f} us "
          f"(x{t_ref_step / t_step:.1f})")


if __name__ == "__main__":
    main()
