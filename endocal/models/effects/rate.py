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
    ŝ_k = ŝ_{k-1} + (1 - exp(-Δt_k / T_s)) (|u_k - u_{k-1}| / Δt_k - ŝ_{k-1})
    v_k = clip(v_{k-1}, u_k - w_k, u_k + w_k)

``g`` (``rate_gain_s``, seconds: deg of play per deg/s of slow knob speed), ``h``
(``rate_amp_s_per_deg``: the same per degree of knob angle, i.e. the tension-proportional
share) and ``κ`` (``rate_capstan_s_per_deg``: ``μΘγ``, how fast the capstan exponent grows
with speed; ``κ → 0`` is a play linear in speed, ``(e^{κs} - 1)/κ → s``) are fitted, all >= 0;
``ŝ`` is the knob speed (deg/s) up to the current sample, smoothed over ``T_s``
(``speed_filter_s``, a setting: the servo's own smoothing of the knob speed). The knob's
speed, not the tip's: the tendon's proximal end slides with the pulley (the simulator's
friction follows the motor speed too). In steady motion the drive lags by
``(g + h|u|)(e^{κ|u̇|} - 1)/κ`` knob degrees; when the knob stops the play closes (the loop
narrows back to the base's).

The inverse solves one scalar equation per sample (:func:`knob_for_drive`): the knob that
pushes the drive to the desired position given the friction its own speed adds, causal
and exact wherever the drive can follow, so the effect streams (given the sample period).
Where ``(g + h|u|) e^{κŝ} α/Δt`` exceeds 1 a faster knob would move the drive less within
the sample: a desired drive faster than that cannot be reached, and the inverse pushes the
knob to where the drive gets furthest. (Reading the speed one sample late instead makes
the inverse feed its own jumps at reversals back into the width, which diverges once the
capstan term is on.)

``rate:friction`` (:class:`FrictionRate`) is the same physics where the base is one friction element
(``dahl``, ``bouc-wen``): the friction's holding force grows with the knob's speed, so the element's
bound is ``1 + γ|v̇|`` times its own (the simulator's ``[rate]`` acting on its ``bouc-wen`` element). A
play in front of such a base adds a second friction, whose lag opens as a dead band after each reversal;
a stronger friction instead holds more of the same exponential. Written on the base's input ``v``::

    f_k = 1 + γ |v_k - v_{k-1}| / Δt_k                      (the speed over the step to sample k)
    y_k = k_lin v_k - k_hys f_k w_k,  w from the base's law at rho / f_k

with the lag ``f w`` kept when the bound changes, clipped when it falls below (the element slips):
:func:`endocal.models._smooth_friction.scaled_friction_states`. On the speed ladder `--next` designs,
the Bouc-Wen plant with friction growing with speed is fitted by ``bouc-wen`` with ``delay``,
``envelope`` and ``rate:friction`` at 1.16 times the noise, and with ``rate`` above 3
(tests/test_friction_family_limits.py).

It has no inverse. Within one sample, a knob that slows lowers the bound below the friction held, and
the element slips: the tip jumps ahead. So once the element slides fast (by 90 deg/s on the
Bouc-Wen plant's ladder), the angle a sample reaches is not monotone in its command: one angle is
reached by several commands, and no sample-by-sample inverse is unique
(tests/test_friction_family_limits.py). A model with ``rate:friction`` predicts and validates;
compensation refuses it in one line (``rate``, the play, has an exact causal inverse).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from endocal.errors import CompensationRefusedError, ModelError
from endocal.models._kernels import HOLD_TOL, play_reference, play_reference_jit, varplay_forward_jac
from endocal.models._smooth_friction import speed_factors
from endocal.models.data import HysteresisData
from endocal.models.effects.base import InputEffect, from_form
from endocal.models.effects.requirements import TIME_STAMPS, speeds_spanning
from endocal.models.params import Parameter


@njit(cache=True)
def smoothed_speed(u, t, tau, M, run_starts):
    """Smoothed knob speed ``ŝ`` (n,) (deg/s, up to the current sample) and its Jacobian (n, q) via ``M``."""
    n = u.shape[0]
    q = M.shape[1]
    s = np.zeros(n)
    D = np.zeros((n, q))
    n_runs = run_starts.shape[0]
    for r in range(n_runs):
        a = run_starts[r]
        b = run_starts[r + 1] if r + 1 < n_runs else n
        sk = 0.0
        for k in range(a + 1, b):
            dt = t[k] - t[k - 1]
            alpha = 1.0 - math.exp(-dt / tau)
            du = u[k] - u[k - 1]
            sk += alpha * (abs(du) / dt - sk)
            s[k] = sk
            sg = 1.0 if du > 0 else (-1.0 if du < 0 else 0.0)
            for j in range(q):  # ŝ_k = (1-α) ŝ_{k-1} + α |u_k - u_{k-1}| / Δt_k
                D[k, j] = (1.0 - alpha) * D[k - 1, j] + alpha * sg * (M[k, j] - M[k - 1, j]) / dt
    return s, D


@njit(cache=True)
def capstan_terms(s, kappa):
    """``F = (e^{κs} - 1)/κ`` (deg/s; ``s`` at ``κ = 0``), ``∂F/∂s = e^{κs}`` and ``∂F/∂κ`` (module docstring).

    ``∂F/∂κ = (κ s e^{κs} - (e^{κs} - 1))/κ²``; below ``κs = 1e-4`` both come from the series.
    """
    ks = kappa * s
    e = math.exp(ks)
    if ks < 1e-4:
        return s * (1.0 + ks / 2.0 + ks * ks / 6.0), e, s * s * (0.5 + ks / 3.0 + ks * ks / 8.0)
    em1 = math.expm1(ks)
    return em1 / kappa, e, (ks * e - em1) / (kappa * kappa)


@njit(cache=True)
def capstan_speed(s, kappa):
    """``(e^{κs} - 1)/κ`` (deg/s), the speed term of the play width."""
    return capstan_terms(s, kappa)[0]


@njit(cache=True)
def capstan_speed_jac(s, kappa):
    """:func:`capstan_terms` over an array of speeds: ``F``, ``∂F/∂s``, ``∂F/∂κ`` (each (n,))."""
    F = np.empty(s.shape[0])
    dF_ds = np.empty(s.shape[0])
    dF_dk = np.empty(s.shape[0])
    for i in range(s.shape[0]):
        F[i], dF_ds[i], dF_dk[i] = capstan_terms(s[i], kappa)
    return F, dF_ds, dF_dk


@njit(cache=True)
def _bisect_root(y, x_prev, s_rest, c, G, kappa, lo, hi):
    """Root of ``x - y - G F(s_rest + c |x - x_prev|)`` in ``[lo, hi]`` (negative at lo, >= 0 at hi)."""
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid == lo or mid == hi:
            break
        if mid - y - G * capstan_speed(s_rest + c * abs(mid - x_prev), kappa) < 0.0:
            lo = mid
        else:
            hi = mid
    return hi


@njit(cache=True)
def knob_for_drive(v, v_prev, u_prev, s_prev, alpha, dt, G, kappa):
    """One sample of the inverse: the knob ``u`` that moves the drive from ``v_prev`` to ``v``.

    The width ``G F(ŝ)`` grows with the knob's own speed in this sample, ``ŝ = (1-α) s_prev +
    α |u - u_prev| / Δt``, so ``u`` solves ``σ (u - v) = G F(ŝ(u))`` (σ the drive's direction;
    a drive at rest keeps the knob inside its window). Writing ``x = σ u``, the residual
    ``x - σv - G F`` rises while the knob turns back (``x < σ u_prev``) and is concave beyond;
    its smallest root is bracketed and bisected. Where the residual stays negative the
    desired drive is faster than the knob can push it (the friction the knob's speed adds
    outgrows its travel): the knob goes to where the drive gets furthest. A target within
    :data:`~endocal.models._kernels.HOLD_TOL` of ``v_prev`` (where the drive is:
    :func:`~endocal.models._kernels.play_reference`) is a drive at rest.
    """
    c = alpha / dt
    s_rest = (1.0 - alpha) * s_prev
    w_rest = G * capstan_speed(s_rest, kappa)
    if abs(v - v_prev) <= HOLD_TOL * max(1.0, abs(v)):  # rounding, not a reversal (play_inverse_step)
        if abs(u_prev - v) <= w_rest:
            return u_prev
        sig = 1.0 if u_prev > v else -1.0  # the window closed past the knob: move it back in
        x_prev, y = sig * u_prev, sig * v
        # root of x - y - w(x) between y (negative) and x_prev (positive)
        return sig * _bisect_root(y, x_prev, s_rest, c, G, kappa, y, x_prev)
    sig = 1.0 if v > v_prev else -1.0
    x_prev, y = sig * u_prev, sig * v
    lo = y
    if x_prev > y and x_prev - y - w_rest >= 0.0:
        return sig * _bisect_root(y, x_prev, s_rest, c, G, kappa, lo, x_prev)
    lo = max(y, x_prev)
    slope = 1.0 - G * c * math.exp(kappa * (s_rest + c * (lo - x_prev)))
    if slope <= 0.0:
        return sig * lo  # the drive cannot advance faster: push as far as it helps
    if kappa > 0.0:
        s_star = math.log(1.0 / (G * c)) / kappa  # where the residual peaks
        hi = x_prev + (s_star - s_rest) / c
    else:
        hi = lo + 2.0 * (G * capstan_speed(s_rest + c * (lo - x_prev), kappa) + 1.0) / slope
    if hi - y - G * capstan_speed(s_rest + c * abs(hi - x_prev), kappa) < 0.0:
        return sig * hi
    return sig * _bisect_root(y, x_prev, s_rest, c, G, kappa, lo, hi)


@njit(cache=True)
def rate_inverse(v, t, g, h, kappa, tau, run_starts):
    """Commands whose rate play output is ``v`` (exact where the drive can follow; causal)."""
    n = v.shape[0]
    u = np.empty(n)
    n_runs = run_starts.shape[0]
    for r in range(n_runs):
        a = run_starts[r]
        b = run_starts[r + 1] if r + 1 < n_runs else n
        u[a] = v[a]
        ref = v[a]  # where the drive is (play_reference)
        sk = 0.0
        for k in range(a + 1, b):
            dt = t[k] - t[k - 1]
            alpha = 1.0 - math.exp(-dt / tau)
            u[k] = knob_for_drive(v[k], ref, u[k - 1], sk, alpha, dt, g + h * abs(u[k - 1]), kappa)
            ref = play_reference_jit(v[k], ref, u[k], u[k - 1])
            sk += alpha * (abs(u[k] - u[k - 1]) / dt - sk)
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
    needs = ("t_s",)
    requires = (TIME_STAMPS, speeds_spanning("speed-dependent friction needs the same motion at several frequencies: "
                                             "run `chirp` or `sine-set`"))
    residual = ("speed", "abs speed")
    lookalikes = {"delay": 'a delay shifts the whole response in time at every speed, while speed-dependent friction widens the loop only when the knob moves fast: run `chirp` (or `sine-set`) and compare the loop at low and high frequency, or `staircase`: a delay shows as the same lag at the start of every step'}
    sim_section = "rate"
    #: --next considers it whatever validate said: a lag and friction growing with speed both widen the loop
    #: with speed, and the records may not reach the speeds at which the two differ
    at_stake = ("speeds", "a lag and friction growing with speed both widen the loop with speed; the records may "
                "not reach the speeds at which the two differ")
    segment_order = 60

    def segment(self, design, n_half_cycles: int):
        """The same sine at several frequencies up to the probe's limits (shared with ``delay``)."""
        return design.speeds(self.name, n_half_cycles)

    #: the form for a friction base: its holding force grows with speed (``rate:friction``)
    variants = ("rate:friction",)

    @classmethod
    def from_argument(cls, arg: str):
        """``rate:friction``: the friction base's holding force grows with knob speed."""
        if arg.strip() != "friction":
            raise ModelError(f"effect 'rate:{arg.strip()}': write rate (a play in front of the base that widens with "
                             "knob speed) or rate:friction (a friction base's holding force grows with it)")
        return FrictionRate()

    @classmethod
    def from_settings(cls, settings: dict):
        """A model file's entry: ``{"form": "friction"}`` for :class:`FrictionRate`; files without it are the play's."""
        return from_form("rate", settings, {"play": cls, "friction": FrictionRate}, "play")

    def __init__(self, speed_filter_s: float = 0.1):
        if not (isinstance(speed_filter_s, (int, float)) and math.isfinite(speed_filter_s) and speed_filter_s > 0):
            raise ModelError(f"rate: speed_filter_s must be a positive number of seconds, got {speed_filter_s!r}")
        self.speed_filter_s = float(speed_filter_s)

    def settings(self) -> dict:
        return {"speed_filter_s": self.speed_filter_s}

    def check(self, data: HysteresisData) -> None:
        data.require_time("effect 'rate'")

    def _upper(self) -> float:
        # without the capstan term, g α/Δt < 1 keeps the knob -> drive map monotone (module docstring)
        return 0.5 * self.speed_filter_s

    def _amp_upper(self, u: np.ndarray) -> float:
        # g + h |u| stays below 0.9 T_s over the fitted commands (still monotone at κ = 0)
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
        # apply_jac's output without its Jacobian (an (n, 3) design and an (n, 3) Jacobian on a prediction)
        g, h, kappa = self._gains(p)
        s, _ = self._speed(u, data, np.zeros((len(u), 0)))
        F = capstan_speed_jac(s, float(kappa))[0]
        u = np.asarray(u, dtype=float)
        prev = np.concatenate([u[:1], u[:-1]])
        gain = g + h * np.abs(prev)
        none = np.zeros((u.size, 0))  # no Jacobian columns: the output alone
        return varplay_forward_jac(np.ascontiguousarray(u, dtype=float), gain * F, none, none, data.run_starts)[0]

    def apply_jac(self, p: dict, u: np.ndarray, data: HysteresisData, M: np.ndarray):
        g, h, kappa = self._gains(p)
        s, D = self._speed(u, data, M)
        F, dF_ds, dF_dk = capstan_speed_jac(s, float(kappa))
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
        # [started, v_prev, u_prev, smoothed knob speed, alpha, dt]
        return np.array([0.0, 0.0, 0.0, 0.0, 1.0 - math.exp(-dt_s / self.speed_filter_s), dt_s])

    def invert_step(self, p: dict, v: float, state: np.ndarray) -> float:
        if state[0] == 0.0:
            state[0], state[1], state[2] = 1.0, v, v
            return v
        alpha, dt = state[4], state[5]
        u_prev = state[2]
        g, h, kappa = self._gains(p)
        u = knob_for_drive(v, state[1], u_prev, state[3], alpha, dt, g + h * abs(u_prev), kappa)
        state[3] += alpha * (abs(u - u_prev) / dt - state[3])
        state[1], state[2] = play_reference(v, state[1], u, u_prev), u
        return u

    def wrap(self, inner: str) -> str:
        return f"rateplay({inner})"

    def describe(self, p: dict, se: dict) -> str:
        return f"rateplay = rate{self._bracket(p, se)[:-1]}, T_s={self.speed_filter_s:g} s (fixed)]"

    def is_zero(self, p: dict) -> bool:
        g, h, _ = self._gains(p)
        return g == 0.0 and h == 0.0


class FrictionRate(Rate):
    """``rate:friction``: a friction base's holding force grows with the knob's speed (module docstring).

    Fitted parameter (prefix ``rate_friction_``): ``gain_s_per_deg`` (``γ``, s/deg), the relative growth of the
    holding force per deg/s of the base's input. The command passes unchanged: the base scales its friction
    (:meth:`friction_factor`); a base without a friction state refuses it.
    """

    units = {"gain_s_per_deg": "s/deg"}
    form = "friction"
    usage = "rate:friction"
    streamable = False
    needs_friction_state = "it scales that state's holding force"
    has_inverse = False
    no_inverse = ("its friction follows the knob's speed, so a knob that slows lets the element slip ahead and one "
                  "angle is reached by several commands; 'rate' (a play) has an inverse")

    def __init__(self):
        self.speed_filter_s = 0.0

    def settings(self) -> dict:
        return {"form": self.form}

    def friction_factor(self, p: dict, v: np.ndarray, data: HysteresisData) -> np.ndarray:
        """The base's friction bound, ``1 + γ |v̇|`` times its own (the speed over the step that ends at each sample)."""
        t = data.require_time(f"effect '{self.label}'")
        return speed_factors(np.ascontiguousarray(v, dtype=float), np.ascontiguousarray(t, dtype=float),
                             float(p["gain_s_per_deg"]), data.run_starts)

    def _upper(self, u: np.ndarray, data: HysteresisData) -> float:
        # the holding force at most ten times its own at the fastest speed of the data
        t = data.require_time("effect 'rate:friction'")
        speed = np.abs(np.diff(np.asarray(u, dtype=float))) / np.maximum(np.diff(t), 1e-12)
        inside = np.ones(speed.size, dtype=bool)
        inside[np.asarray(data.run_starts[1:], dtype=int) - 1] = False  # no speed across two runs
        fastest = float(np.max(speed[inside])) if inside.any() else 0.0
        return 9.0 / max(fastest, 1e-9)

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        hi = self._upper(u, data)
        return [Parameter(f"{self.prefix}_gain_s_per_deg", 0.02 * hi, 0.0, hi)]

    def start_candidates(self, data: HysteresisData, u: np.ndarray) -> list[dict]:
        """Start values tried before the fit (the best is kept): the force at the fastest speed 1.1 to 4 times its own."""
        hi = self._upper(u, data)
        return [{"gain_s_per_deg": f * hi} for f in (0.01, 0.1, 0.33)]

    def apply(self, p: dict, u: np.ndarray, data: HysteresisData) -> np.ndarray:
        return np.asarray(u, dtype=float)

    apply_jac = None  # the base's friction carries the term: the fit differentiates numerically

    def invert(self, p: dict, v: np.ndarray, data: HysteresisData) -> np.ndarray:
        raise CompensationRefusedError(f"effect 'rate:friction' has no inverse: {self.no_inverse}; compensation refused")

    def wrap(self, inner: str) -> str:
        return inner

    def describe(self, p: dict, se: dict) -> str:
        return "friction x (1 + gamma |dv/dt|): rate:friction" + self._bracket(p, se)

    def is_zero(self, p: dict) -> bool:
        return p["gain_s_per_deg"] == 0.0
