"""``delay``: a time shift between the commands and the measured angles.

Transport and tracker latency, and the servo's lag behind its goal, make the measured
angle answer the command late by ``τ`` (``delay_s``, fitted, sub-sample)::

    v(t) = u(t - τ)      (linear interpolation between samples, per run; before the
                          run's first sample the first command is held)

The inverse advances the desired drive position in time, ``u(t) = v(t + τ)`` (the last
value held at the run's end): it needs the future of the trajectory, so the effect cannot
stream, and it is exact when ``τ`` is a whole number of samples; otherwise the two linear
interpolations leave an error of at most ``dt²·|v̈|/8`` (sub-sample smoothing).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from endocal.models.data import HysteresisData
from endocal.models.effects.base import InputEffect
from endocal.models.effects.rate import Rate
from endocal.models.effects.requirements import TIME_STAMPS, speeds_spanning
from endocal.models.params import Parameter


@njit(cache=True)
def shift_jac(u, t, tau, M, run_starts):
    """``u`` read at ``t - tau`` per run (linear interpolation, first value held before the start).

    Returns ``v`` (n,), ``dv/dtau`` (n,) and ``G`` (n, q) = the interpolated rows of ``M``.
    ``tau`` may be negative (an advance; the last value is held past the end).
    """
    n = u.shape[0]
    q = M.shape[1]
    v = np.empty(n)
    dtau = np.zeros(n)
    G = np.zeros((n, q))
    n_runs = run_starts.shape[0]
    for r in range(n_runs):
        a = run_starts[r]
        b = run_starts[r + 1] if r + 1 < n_runs else n
        j = a
        for k in range(a, b):
            x = t[k] - tau
            if x <= t[a]:
                v[k] = u[a]
                for c in range(q):
                    G[k, c] = M[a, c]
                continue
            if x >= t[b - 1]:
                v[k] = u[b - 1]
                for c in range(q):
                    G[k, c] = M[b - 1, c]
                continue
            while j + 1 < b and t[j + 1] < x:
                j += 1
            while j > a and t[j] >= x:
                j -= 1
            h = t[j + 1] - t[j]
            f = (x - t[j]) / h
            v[k] = (1.0 - f) * u[j] + f * u[j + 1]
            dtau[k] = -(u[j + 1] - u[j]) / h
            for c in range(q):
                G[k, c] = (1.0 - f) * M[j, c] + f * M[j + 1, c]
    return v, dtau, G


class Delay(InputEffect):
    """Time shift ``τ`` (s) of the command (module docstring). Parameter: ``delay_s``."""

    name = "delay"
    order = 10
    cause = "latency: tracker and transport delay, and the servo lagging its goal"
    signature = ("residual proportional to the command's rate of change (the measured angle lags), "
                 "peaking where the motion is fastest, cross-correlated with the input at a lag")
    protocol = "fast motions, steps and chirps (the lag shows against speed)"
    units = {"s": "s"}
    needs = ("t_s",)
    requires = (TIME_STAMPS, speeds_spanning("at one frequency a time shift looks like a wider loop: run `chirp` or "
                                             "`random`"))
    residual = ("speed",)
    lookalikes = {"rate": 'a delay shifts the whole response in time at every speed, while speed-dependent friction widens the loop only when the knob moves fast: run `chirp` (or `sine-set`) and compare the loop at low and high frequency, or `staircase`: a delay shows as the same lag at the start of every step'}
    sim_section = "delay"
    at_stake = Rate.at_stake
    segment_order = 60

    def segment(self, design, n_half_cycles: int):
        """The same sine at several frequencies up to the probe's limits (shared with ``rate``)."""
        return design.speeds(self.name, n_half_cycles)

    def param_names(self) -> list[str]:
        return ["s"]

    def check(self, data: HysteresisData) -> None:
        data.require_time("effect 'delay'")

    def _bounds(self, data: HysteresisData) -> float:
        t = data.require_time("effect 'delay'")
        spans = [t[sl.stop - 1] - t[sl.start] for sl in data.run_slices()]
        return float(min(2.0, 0.25 * min(spans)))

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        hi = self._bounds(data)
        return [Parameter(f"{self.prefix}_s", 0.0, -0.25 * hi, hi)]

    def start_candidates(self, data: HysteresisData, u: np.ndarray) -> list[dict]:
        """Start values tried before the fit (the best is kept)."""
        hi = self._bounds(data)
        return [{"s": tau} for tau in (0.0, 0.05, 0.1, 0.2, 0.4, 0.8) if tau <= hi]

    def _shift(self, u, tau, data, M):
        t = data.require_time("effect 'delay'")
        return shift_jac(np.ascontiguousarray(u, dtype=float), t, float(tau), np.ascontiguousarray(M, dtype=float),
                         data.run_starts)

    def apply(self, p: dict, u: np.ndarray, data: HysteresisData) -> np.ndarray:
        return self._shift(u, p["s"], data, np.zeros((len(u), 0)))[0]

    def apply_jac(self, p: dict, u: np.ndarray, data: HysteresisData, M: np.ndarray):
        v, dtau, G = self._shift(u, p["s"], data, M)
        return v, dtau[:, None], G

    def invert(self, p: dict, v: np.ndarray, data: HysteresisData) -> np.ndarray:
        return self._shift(v, -p["s"], data, np.zeros((len(v), 0)))[0]

    def wrap(self, inner: str) -> str:
        return f"{inner}(t - tau)"

    def describe(self, p: dict, se: dict) -> str:
        return "tau = delay" + self._bracket(p, se)

    def is_zero(self, p: dict) -> bool:
        return p["s"] == 0.0
