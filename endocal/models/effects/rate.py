"""``rate``: friction that grows with knob speed (hysteresis loops widen at higher frequency).

Coulomb friction of the tendon in its sheath rises with sliding speed (lubricant
drag, stick-slip), so the drive lags the knob by more backlash the faster the knob
turns. Capstan friction is proportional to the tendon tension, and the tension grows with
the bend away from neutral, so the speed-dependent play is also wider at large knob
angles (the simulator's ``mu_eff = mu (1 + gain |u̇|)`` acts on a tension ∝ bend). And
the capstan makes friction exponential in the friction coefficient (tension ratio
``e^{μΘ}`` over a wrap ``Θ``): a coefficient growing linearly with speed, ``μ (1 + γ|u̇|)``,
widens the play by ``e^{μΘγ|u̇|} - 1``, more than linearly at high speed. Modelled as an
extra play on the command whose half width grows with the knob speed, and with the knob's
distance from neutral::

    w_k = (g + h · |u_{k-1}|) · (exp(κ ŝ_k) - 1) / κ,
    ŝ_k = ŝ_{k-1} + (1 - exp(-Δt_k / T_s)) (|u̇_{k-1}| - ŝ_{k-1})
    v_k = clip(v_{k-1}, u_k - w_k, u_k + w_k)

``g`` (``rate_gain_s``, seconds: deg of play per deg/s of slow knob speed), ``h``
(``rate_amp_s_per_deg``: the same per degree of knob angle, i.e. the tension-proportional
share) and ``κ`` (``rate_capstan_s_per_deg``: ``μΘγ``, how fast the capstan exponent grows
with speed; ``κ → 0`` is a play linear in speed, ``(e^{κs} - 1)/κ → s``) are fitted, all >= 0;
``ŝ`` is the knob speed (deg/s) from the commands up to the previous sample,
smoothed over ``T_s`` (``speed_filter_s``, a setting: the servo's own smoothing of the
knob speed). In steady motion the drive lags by ``g·|u̇|`` knob degrees; when the
knob stops the play closes (the loop narrows back to the base's). Using only past
speeds and angles keeps the inverse explicit: the command that produces a desired drive
position is exact and causal, so the effect streams (given the sample period).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from endocal.errors import ModelError
from endocal.models._kernels import play_inverse_step, play_inverse_step_jit, varplay_forward_jac
from endocal.models.data import HysteresisData
from endocal.models.effects.base import InputEffect
from endocal.models.params import Parameter


@njit(cache=True)
def smoothed_speed(u, t, tau, M, run_starts):
    """Smoothed knob speed ``ŝ`` (n,) (deg/s, from past samples only) and its Jacobian (n, q) via ``M``."""
    n = u.shape[0]
    q = M.shape[1]
    s = np.zeros(n)
    D = np.zeros((n, q))
    n_runs = run_starts.shape[0]
    for r in range(n_runs):
        a = run_starts[r]
        b = run_starts[r + 1] if r + 1 < n_runs else n
        prev_r = 0.0
        sk = 0.0
        for j in range(q):
            D[a, j] = 0.0
        for k in range(a + 1, b):
            dt = t[k] - t[k - 1]
            alpha = 1.0 - math.exp(-dt / tau)
            sk = sk + alpha * (prev_r - sk)
            s[k] = sk
            # derivative: ŝ_k = (1-α) ŝ_{k-1} + α r_{k-1}
            if k - 1 > a:
                dtp = t[k - 1] - t[k - 2]
                du = u[k - 1] - u[k - 2]
                sg = 1.0 if du > 0 else (-1.0 if du < 0 else 0.0)
                for j in range(q):
                    D[k, j] = (1.0 - alpha) * D[k - 1, j] + alpha * sg * (M[k - 1, j] - M[k - 2, j]) / dtp
            else:
                for j in range(q):
                    D[k, j] = (1.0 - alpha) * D[k - 1, j]
            prev_r = abs(u[k] - u[k - 1]) / dt
    return s, D


@njit(cache=True)
def capstan_speed(s, kappa):
    """``(exp(κ s) - 1) / κ`` (deg/s), the speed term of the play width; ``s`` at ``κ = 0`` (module docstring)."""
    ks = kappa * s
    if ks < 1e-8:
        return s * (1.0 + 0.5 * ks)
    return math.expm1(ks) / kappa


def capstan_speed_jac(s: np.ndarray, kappa: float):
    """``F = (e^{κs} - 1)/κ``, ``∂F/∂s = e^{κs}`` and ``∂F/∂κ = (κ s e^{κs} - (e^{κs} - 1))/κ²`` (series for small κs)."""
    ks = kappa * s
    small = ks < 1e-4
    safe_k = kappa if kappa > 0 else 1.0
    e = np.exp(ks)
    F = np.where(small, s * (1.0 + ks / 2.0 + ks * ks / 6.0), np.expm1(ks) / safe_k)
    dk = np.where(small, s * s * (0.5 + ks / 3.0 + ks * ks / 8.0), (ks * e - np.expm1(ks)) / safe_k**2)
    return F, e, dk


@njit(cache=True)
def rate_inverse(v, t, g, h, kappa, tau, run_starts):
    """Commands whose rate play output is ``v`` (exact, causal: the width uses past commands only)."""
    n = v.shape[0]
    u = np.empty(n)
    n_runs = run_starts.shape[0]
    for r in range(n_runs):
        a = run_starts[r]
        b = run_starts[r + 1] if r + 1 < n_runs else n
        u[a] = v[a]
        prev_r = 0.0
        sk = 0.0
        for k in range(a + 1, b):
            dt = t[k] - t[k - 1]
            sk = sk + (1.0 - math.exp(-dt / tau)) * (prev_r - sk)
            u[k] = play_inverse_step_jit(v[k], v[k - 1], u[k - 1], capstan_speed(sk, kappa) * (g + h * abs(u[k - 1])))
            prev_r = abs(u[k] - u[k - 1]) / dt
    return u


class Rate(InputEffect):
    """Speed-dependent friction play on the command (module docstring).

    Parameters
    ----------
    speed_filter_s : float
        Time constant ``T_s`` (s) smoothing the knob speed that sets the play's width.

    Fitted parameters (prefix ``rate_``): ``gain_s`` (s), play half width per deg/s of
    knob speed; ``amp_s_per_deg`` (s/deg), the same per deg/s and per degree of knob angle
    from neutral (friction ∝ tendon tension ∝ bend); ``capstan_s_per_deg`` (s/deg), the
    growth of the capstan exponent with knob speed (the play widens faster than linearly).
    """

    name = "rate"
    order = 20
    streamable = True
    stateful = True
    needs_period = True
    cause = ("friction between tendon and sheath that grows with sliding speed "
             "(lubricant drag, stick-slip): the faster the knob turns, the more it leads the tip")
    signature = ("residual proportional to knob speed with the sign of the motion, vanishing when the knob "
                 "stops; loops wider at high frequency than at low")
    protocol = "the same motion at several frequencies (a chirp, or slow and fast sines)"
    units = {"gain_s": "s", "amp_s_per_deg": "s/deg", "capstan_s_per_deg": "s/deg"}

    def __init__(self, speed_filter_s: float = 0.1):
        if not (isinstance(speed_filter_s, (int, float)) and math.isfinite(speed_filter_s) and speed_filter_s > 0):
            raise ModelError(f"rate: speed_filter_s must be a positive number of seconds, got {speed_filter_s!r}")
        self.speed_filter_s = float(speed_filter_s)

    def settings(self) -> dict:
        return {"speed_filter_s": self.speed_filter_s}

    def check(self, data: HysteresisData) -> None:
        data.require_time("effect 'rate'")

    def _upper(self) -> float:
        # the inverse feeds its own command jumps back into the width: keep that loop gain below 1/2
        return 0.5 * self.speed_filter_s

    def _amp_upper(self, u: np.ndarray) -> float:
        # g + h |u| stays below 0.9 T_s over the fitted commands (inverse loop gain < 0.9)
        return 0.4 * self.speed_filter_s / max(float(np.max(np.abs(u))), 1e-9)

    def _capstan_upper(self, u: np.ndarray, data: HysteresisData) -> float:
        # the play at the fastest fitted knob speed stays within e^2 (7.4x) of a linear law's
        s, _ = self._speed(u, data, np.zeros((len(u), 0)))
        return 2.0 / max(float(np.max(s)) if s.size else 0.0, 1e-9)

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        return [Parameter(f"{self.prefix}_gain_s", 0.05 * self._upper(), 0.0, self._upper()),
                Parameter(f"{self.prefix}_amp_s_per_deg", 0.05 * self._amp_upper(u), 0.0, self._amp_upper(u)),
                Parameter(f"{self.prefix}_capstan_s_per_deg", 0.05 * self._capstan_upper(u, data), 0.0,
                          self._capstan_upper(u, data))]

    def start_candidates(self, data: HysteresisData, u: np.ndarray) -> list[dict]:
        """Start values tried before the fit (the best is kept): uniform play, or play growing with the angle."""
        ha = self._amp_upper(u)
        return ([{"gain_s": f * self._upper(), "amp_s_per_deg": 0.01 * ha} for f in (0.02, 0.2, 0.6)]
                + [{"gain_s": 0.01 * self._upper(), "amp_s_per_deg": f * ha} for f in (0.2, 0.6)])

    @staticmethod
    def _gains(p: dict) -> tuple[float, float, float]:
        return float(p["gain_s"]), float(p["amp_s_per_deg"]), float(p["capstan_s_per_deg"])

    def _speed(self, u, data, M):
        t = data.require_time("effect 'rate'")
        return smoothed_speed(np.ascontiguousarray(u, dtype=float), t, self.speed_filter_s,
                              np.ascontiguousarray(M, dtype=float), data.run_starts)

    def apply(self, p: dict, u: np.ndarray, data: HysteresisData) -> np.ndarray:
        v, _, _ = self.apply_jac(p, u, data, np.zeros((len(u), 0)))
        return v

    def apply_jac(self, p: dict, u: np.ndarray, data: HysteresisData, M: np.ndarray):
        g, h, kappa = self._gains(p)
        s, D = self._speed(u, data, M)
        F, dF_ds, dF_dk = capstan_speed_jac(s, kappa)
        u = np.asarray(u, dtype=float)
        M = np.asarray(M, dtype=float)
        # the angle of the previous sample (the width at a run's first sample is 0 anyway: ŝ = 0)
        prev = np.concatenate([u[:1], u[:-1]])
        Mprev = np.concatenate([M[:1], M[:-1]])
        a = np.abs(prev)
        gain = g + h * a
        Wg = np.column_stack([(gain * dF_ds)[:, None] * D + (h * F * np.sign(prev))[:, None] * Mprev,
                              F, F * a, gain * dF_dk])
        v, J = varplay_forward_jac(np.ascontiguousarray(u, dtype=float), gain * F, Wg,
                                   np.ascontiguousarray(M, dtype=float), data.run_starts)
        q = M.shape[1]
        return v, J[:, q:], J[:, :q]

    def invert(self, p: dict, v: np.ndarray, data: HysteresisData) -> np.ndarray:
        t = data.require_time("effect 'rate'")
        return rate_inverse(np.ascontiguousarray(v, dtype=float), t, *self._gains(p), self.speed_filter_s,
                            data.run_starts)

    def stream_state(self, p: dict, dt_s: float | None = None) -> np.ndarray:
        if dt_s is None or not dt_s > 0:
            raise ModelError("effect 'rate' streams only with a fixed sample period: give dt_s (s) to the compensator")
        # [started, v_prev, u_prev, speed_prev, smoothed speed, alpha]
        return np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0 - math.exp(-dt_s / self.speed_filter_s), dt_s])

    def invert_step(self, p: dict, v: float, state: np.ndarray) -> float:
        if state[0] == 0.0:
            state[0], state[1], state[2] = 1.0, v, v
            return v
        alpha, dt = state[5], state[6]
        state[4] += alpha * (state[3] - state[4])
        u_prev = state[2]
        g, h, kappa = self._gains(p)
        w = capstan_speed(state[4], kappa) * (g + h * abs(u_prev))
        u = play_inverse_step(v, state[1], u_prev, w)
        state[3] = abs(u - u_prev) / dt
        state[1], state[2] = v, u
        return u

    def wrap(self, inner: str) -> str:
        return f"rateplay({inner})"

    def describe(self, p: dict, se: dict) -> str:
        return f"rateplay = rate{self._bracket(p, se)[:-1]}, T_s={self.speed_filter_s:g} s (fixed)]"

    def is_zero(self, p: dict) -> bool:
        g, h, _ = self._gains(p)
        return g == 0.0 and h == 0.0
