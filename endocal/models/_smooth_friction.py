"""Compiled recursions of the smooth friction bases without return-point memory (``bouc-wen``, ``dahl``).

Both bases carry one internal state ``w`` (dimensionless, in ``[-1, 1]``) driven by the input ``v``
and rate-independent: ``dw/dv`` depends on ``w`` and on the direction of motion ``s = sign(dv)``
only. Written with ``u = s w`` (the state measured in the direction of motion) and the path length
``l = |dv|``, both laws are one ordinary differential equation in ``l``:

- normalised Bouc-Wen (Ikhouane & Rodellar, Systems with Hysteresis, 2007; the form reviewed by
  Ismail, Ikhouane & Rodellar, Arch. Comput. Methods Eng. 16, 2009, eq. 13)::

      dw/dt = rho (dv/dt - sigma |dv/dt| |w|^(n-1) w + (sigma - 1) dv/dt |w|^n)
      =>  du/dl = rho (1 - u^n)                   for u >= 0
          du/dl = rho (1 + (2 sigma - 1) |u|^n)   for u <  0

- Dahl (Dahl, Aerospace Corp. report TOR-0158(3107-18)-1, 1968; AIAA J. 14, 1976, eq. 1)::

      dF/dx = sigma0 |1 - F/Fc sgn(dx)|^i sgn(1 - F/Fc sgn(dx)),  w = F/Fc, rho = sigma0/Fc
      =>  du/dl = rho |1 - u|^i sgn(1 - u)

For ``n = 1`` (Bouc-Wen) and ``i = 1`` (Dahl) the equation is linear on each sign of ``u`` and is
solved exactly (an exponential in ``l``); other exponents are integrated by classical Runge-Kutta
in sub-steps of at most ``MAX_RHO_L`` in ``rho * l`` times the law's steepest slope. Each run starts at ``w = 0`` (the
relaxed state, as the play operators start at 0). A small reversal inside the loop does not
return to the branch it left (no return-point memory): the state after a minor loop is not the
state before it, unlike a bank of plays.

The inverse is numerical: per sample, the step map ``v -> k_lin v + k_hys w(v_prev, w_prev, v)`` is
non-decreasing in ``v`` (strictly when ``k_lin > 0``), so bisection finds the unique input.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Family codes of the kernels.
BOUC_WEN = 0
DAHL = 1
#: Largest step of ``rho * l`` in one Runge-Kutta sub-step (exponents other than 1).
MAX_RHO_L = 0.05


@njit(cache=True)
def _rate(family, u, rho, sigma, expo):
    """``du/dl`` of the state in the direction of motion."""
    if family == BOUC_WEN:
        if u >= 0.0:
            return rho * (1.0 - u ** expo)
        return rho * (1.0 + (2.0 * sigma - 1.0) * (-u) ** expo)
    d = 1.0 - u
    if d >= 0.0:
        return rho * d ** expo
    return -rho * (-d) ** expo


@njit(cache=True)
def _advance(family, u, ell, rho, sigma, expo):
    """State in the direction of motion after a path length ``ell >= 0`` from ``u``."""
    if ell <= 0.0:
        return u
    if expo == 1.0:
        if family == DAHL:
            return 1.0 - (1.0 - u) * math.exp(-rho * ell)
        if u < 0.0:
            c = 2.0 * sigma - 1.0
            # du/dl = rho (1 - c u) until u reaches 0 (c >= 0: the fit bounds sigma >= 1/2)
            if c > 1e-12:
                ell0 = math.log(1.0 - c * u) / (rho * c)
                if ell < ell0:
                    return 1.0 / c + (u - 1.0 / c) * math.exp(-rho * c * ell)
            else:
                ell0 = -u / rho
                if ell < ell0:
                    return u + rho * ell
            ell = ell - ell0
            u = 0.0
        return 1.0 - (1.0 - u) * math.exp(-rho * ell)
    steep = 1.0 if family == DAHL else max(1.0, 2.0 * sigma)  # the largest |du/dl| / rho on the way
    m = int(math.ceil(steep * rho * ell / MAX_RHO_L))
    if m < 1:
        m = 1
    h = ell / m
    for _ in range(m):
        k1 = _rate(family, u, rho, sigma, expo)
        k2 = _rate(family, u + 0.5 * h * k1, rho, sigma, expo)
        k3 = _rate(family, u + 0.5 * h * k2, rho, sigma, expo)
        k4 = _rate(family, u + h * k3, rho, sigma, expo)
        u = u + h * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
    return u


@njit(cache=True)
def state_step(family, w, dv, rho, sigma, expo):
    """The state ``w`` after an input step ``dv`` (any sign)."""
    if dv > 0.0:
        return _advance(family, w, dv, rho, sigma, expo)
    if dv < 0.0:
        return -_advance(family, -w, -dv, rho, sigma, expo)
    return w


@njit(cache=True)
def friction_states(family, v, rho, sigma, expo, run_starts):
    """The internal state ``w`` (n,) driven by ``v`` (n,), restarting at 0 on each run."""
    return scaled_friction_states(family, v, rho, sigma, expo, run_starts, np.ones(v.shape[0]))


@njit(cache=True)
def _rescaled(w, f_old, f_new):
    """The state when the friction's bound changes from ``f_old`` to ``f_new`` times its own: the lag
    ``f w`` is kept, and clipped to the new bound when that falls below it (the element slips)."""
    if f_new == f_old:
        return w
    w = w * f_old / f_new
    if w > 1.0:
        return 1.0
    if w < -1.0:
        return -1.0
    return w


@njit(cache=True)
def scaled_friction_states(family, v, rho, sigma, expo, run_starts, f):
    """The state ``w`` (n,) of a friction whose bound is ``f`` (n,, > 0) times its own at each sample.

    The friction's term is then ``k_hys f w``: a holding force ``f`` times the base's (friction growing
    with speed, ``rate:friction``). Its lag ``f w`` is kept when the bound changes (clipped: the element
    slips), and the state saturates within ``f / rho`` of the input (``rho / f``: the element's stiffness
    after a reversal, ``k_hys rho``, does not change). ``f = 1`` is :func:`friction_states`.
    """
    n = v.shape[0]
    w = np.empty(n)
    n_runs = run_starts.shape[0]
    for q in range(n_runs):
        a = run_starts[q]
        b = run_starts[q + 1] if q + 1 < n_runs else n
        if a >= b:
            continue
        wk = 0.0
        w[a] = 0.0
        for k in range(a + 1, b):
            wk = state_step(family, _rescaled(wk, f[k - 1], f[k]), v[k] - v[k - 1], rho / f[k], sigma, expo)
            w[k] = wk
    return w


@njit(cache=True)
def speed_factors(v, t, gain, run_starts):
    """The friction's bound at each sample (n,), ``1 + gain |dv/dt|``, the speed over the step that ends there
    (1 on a run's first sample)."""
    n = v.shape[0]
    f = np.ones(n)
    if gain == 0.0:
        return f
    n_runs = run_starts.shape[0]
    for q in range(n_runs):
        a = run_starts[q]
        b = run_starts[q + 1] if q + 1 < n_runs else n
        for k in range(a + 1, b):
            dt = t[k] - t[k - 1]
            if dt > 0.0:
                f[k] = 1.0 + gain * abs(v[k] - v[k - 1]) / dt
    return f


@njit(cache=True)
def inverse_step(family, y, v_prev, w_prev, k_lin, k_hys, rho, sigma, expo, v_lo, v_hi):
    """The input ``v`` whose output ``k_lin v + k_hys w`` is ``y`` one step after ``(v_prev, w_prev)``,
    and the state there: ``(v, w, miss)``, ``miss`` the output error left (deg; 0 when reached).

    Bisection on ``[v_lo, v_hi]``: the step map is non-decreasing in ``v``.
    """
    y_prev = k_lin * v_prev + k_hys * w_prev
    if y == y_prev:
        return v_prev, w_prev, 0.0
    lo = v_lo
    hi = v_hi
    if y > y_prev:
        lo = v_prev
    else:
        hi = v_prev
    if lo > hi:
        lo = hi
    g_lo = k_lin * lo + k_hys * state_step(family, w_prev, lo - v_prev, rho, sigma, expo)
    g_hi = k_lin * hi + k_hys * state_step(family, w_prev, hi - v_prev, rho, sigma, expo)
    if y <= g_lo:
        return lo, state_step(family, w_prev, lo - v_prev, rho, sigma, expo), g_lo - y
    if y >= g_hi:
        return hi, state_step(family, w_prev, hi - v_prev, rho, sigma, expo), y - g_hi
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        g = k_lin * mid + k_hys * state_step(family, w_prev, mid - v_prev, rho, sigma, expo)
        if g < y:
            lo = mid
        else:
            hi = mid
    g_lo = k_lin * lo + k_hys * state_step(family, w_prev, lo - v_prev, rho, sigma, expo)
    g_hi = k_lin * hi + k_hys * state_step(family, w_prev, hi - v_prev, rho, sigma, expo)
    if abs(g_hi - y) <= abs(g_lo - y):
        return hi, state_step(family, w_prev, hi - v_prev, rho, sigma, expo), abs(g_hi - y)
    return lo, state_step(family, w_prev, lo - v_prev, rho, sigma, expo), abs(g_lo - y)


@njit(cache=True)
def first_input(y, k_lin, v_lo, v_hi):
    """The input of a run's first sample (state 0): ``v = y / k_lin``, clipped to ``[v_lo, v_hi]``; and the miss."""
    if k_lin > 0.0:
        v = y / k_lin
        if v < v_lo:
            v = v_lo
        elif v > v_hi:
            v = v_hi
        return v, abs(k_lin * v - y)
    return 0.0, abs(y)


@njit(cache=True)
def friction_inverse(family, y, k_lin, k_hys, rho, sigma, expo, v_lo, v_hi, run_starts):
    """The input (n,) whose output follows ``y`` (n,, offset removed) and the largest miss (deg)."""
    return scaled_friction_inverse(family, y, k_lin, k_hys, rho, sigma, expo, v_lo, v_hi, run_starts,
                                   np.ones(y.shape[0]))


@njit(cache=True)
def scaled_friction_inverse(family, y, k_lin, k_hys, rho, sigma, expo, v_lo, v_hi, run_starts, f):
    """:func:`friction_inverse` of a friction whose bound is ``f`` (n,, > 0, known ahead: a logged condition) times
    its own (:func:`scaled_friction_states`). At each sample the step map ``v -> k_lin v + k_hys f w`` is that of the
    unscaled law with ``k_hys f`` and ``rho / f`` from the rescaled state, so it stays non-decreasing in ``v``."""
    n = y.shape[0]
    v = np.empty(n)
    worst = 0.0
    n_runs = run_starts.shape[0]
    for q in range(n_runs):
        a = run_starts[q]
        b = run_starts[q + 1] if q + 1 < n_runs else n
        if a >= b:
            continue
        vk, miss = first_input(y[a], k_lin, v_lo, v_hi)
        wk = 0.0
        v[a] = vk
        if miss > worst:
            worst = miss
        for k in range(a + 1, b):
            vk, wk, miss = inverse_step(family, y[k], vk, _rescaled(wk, f[k - 1], f[k]), k_lin, k_hys * f[k],
                                        rho / f[k], sigma, expo, v_lo, v_hi)
            v[k] = vk
            if miss > worst:
                worst = miss
    return v, worst


@njit(cache=True)
def smooth_lag(x, lam, sigma, run_starts, f):
    """A position ``x`` (n,) seen through a smooth friction lag: ``x - lam * f * w``, the state ``w`` following
    normalised Bouc-Wen with ``n = 1`` and ``rho = 1 / (2 sigma lam)`` (module docstring; ``lam`` > 0, ``sigma`` >=
    1/2). Right after a reversal from saturation the stretch ``lam * f * w`` unwinds one to one (the output holds),
    then, slower as it slackens (``sigma`` > 1/2; one to one until slack at 1/2), winds up the other way along an
    exponential of length ``2 sigma lam f`` (the output follows, ``lam f`` behind at saturation): the smooth
    counterpart of a play of half-width ``lam``, without return-point memory. ``f`` (n,, > 0) scales the friction's
    bound at each sample as :func:`scaled_friction_states` does (ones: a constant bound). ``w = 0`` at each run's
    start (the output starts at ``x``)."""
    lam = max(lam, 1e-12)
    w = scaled_friction_states(BOUC_WEN, x, 1.0 / (2.0 * sigma * lam), sigma, 1.0, run_starts, f)
    return x - lam * f * w
