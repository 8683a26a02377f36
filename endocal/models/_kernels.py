"""Compiled recursions shared by the hysteresis models (numba, ``cache=True``).

Every kernel works on one concatenated sample axis with ``run_starts`` (int64,
first entry 0): operator states restart at the first sample of each run, so
several runs are fitted and predicted together without leaking state between them.
Angles are in degrees (or in envelope units where a docstring says so).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def play_bank_forward(x, thresholds, weights, run_starts):
    """Weighted sum of play operators (duodenoscope paper, eqs. 5 and 7).

    ``Phi_i(t_0) = max(x_0 - r_i, min(x_0 + r_i, 0))`` and
    ``Phi_i(t_k) = max(x_k - r_i, min(x_k + r_i, Phi_i(t_{k-1})))``;
    output ``sum_i w_i Phi_i``. ``x`` is the (enveloped) input, shape (n,).
    """
    n = x.shape[0]
    m = thresholds.shape[0]
    y = np.empty(n)
    state = np.zeros(m)
    n_runs = run_starts.shape[0]
    for q in range(n_runs):
        a = run_starts[q]
        b = run_starts[q + 1] if q + 1 < n_runs else n
        for i in range(m):
            state[i] = 0.0
        for k in range(a, b):
            xk = x[k]
            acc = 0.0
            for i in range(m):
                lo = xk - thresholds[i]
                hi = xk + thresholds[i]
                s = state[i]
                if s < lo:
                    s = lo
                elif s > hi:
                    s = hi
                state[i] = s
                acc += weights[i] * s
            y[k] = acc
    return y


@njit(cache=True)
def play_bank_states(x, thresholds, run_starts):
    """Every play operator's output, shape (n, m): the regressors of a PI with free weights (eq. 5)."""
    n = x.shape[0]
    m = thresholds.shape[0]
    out = np.empty((n, m))
    state = np.zeros(m)
    n_runs = run_starts.shape[0]
    for q in range(n_runs):
        a = run_starts[q]
        b = run_starts[q + 1] if q + 1 < n_runs else n
        for i in range(m):
            state[i] = 0.0
        for k in range(a, b):
            xk = x[k]
            for i in range(m):
                s = state[i]
                if s < xk - thresholds[i]:
                    s = xk - thresholds[i]
                elif s > xk + thresholds[i]:
                    s = xk + thresholds[i]
                state[i] = s
                out[k, i] = s
    return out


@njit(cache=True)
def play_bank_step(xk, thresholds, weights, state):
    """One sample of :func:`play_bank_forward` on a caller-held ``state`` (updated in place)."""
    acc = 0.0
    for i in range(thresholds.shape[0]):
        s = state[i]
        if s < xk - thresholds[i]:
            s = xk - thresholds[i]
        elif s > xk + thresholds[i]:
            s = xk + thresholds[i]
        state[i] = s
        acc += weights[i] * s
    return acc


@njit(cache=True)
def _bspline_inside(t, c, deg, x):
    """de Boor's algorithm for ``t[deg] <= x <= t[nc]``."""
    nc = c.shape[0]
    lo = deg
    hi = nc - 1
    if x >= t[hi]:
        ell = hi
    else:
        a = lo
        b = hi
        while b - a > 1:
            mid = (a + b) // 2
            if t[mid] <= x:
                a = mid
            else:
                b = mid
        ell = a
    d = np.empty(deg + 1)
    for j in range(deg + 1):
        d[j] = c[ell - deg + j]
    for r in range(1, deg + 1):
        for j in range(deg, r - 1, -1):
            left = t[ell - deg + j]
            right = t[ell + 1 + j - r]
            den = right - left
            alpha = 0.0 if den == 0.0 else (x - left) / den
            d[j] = (1.0 - alpha) * d[j - 1] + alpha * d[j]
    return d[deg]


@njit(cache=True)
def bspline_eval(t, c, deg, x):
    """Clamped B-spline (knots ``t``, coefficients ``c``, degree ``deg``) at ``x``, extended linearly.

    Beyond the base interval the spline continues along its end tangent (a cubic
    extrapolated as a polynomial can turn back, which would break the monotone
    inverse). Matches :func:`bspline_eval_array`.
    """
    nc = c.shape[0]
    a = t[deg]
    b = t[nc]
    if x < a:
        slope = deg * (c[1] - c[0]) / (t[deg + 1] - t[1])
        return c[0] + slope * (x - a)
    if x > b:
        slope = deg * (c[nc - 1] - c[nc - 2]) / (t[nc + deg - 1] - t[nc - 1])
        return c[nc - 1] + slope * (x - b)
    return _bspline_inside(t, c, deg, x)


@njit(cache=True)
def bspline_eval_array(t, c, deg, x):
    """:func:`bspline_eval` over an array ``x`` (n,)."""
    out = np.empty(x.shape[0])
    for i in range(x.shape[0]):
        out[i] = bspline_eval(t, c, deg, x[i])
    return out


@njit(cache=True)
def gplay_forward(v, lower, upper, slope, run_starts):
    """Generalised play: ``y_k = clip(y_{k-1} + slope*(v_k - v_{k-1}), lower_k, upper_k)``.

    ``lower``/``upper`` are the two branches evaluated at ``v`` (the ascending and
    descending curves); each run starts on their mid-line. This is the
    direction-dependent model with a backlash transition of slope ``slope`` from
    the reversal point to the other branch (thesis, Lee et al.).
    """
    n = v.shape[0]
    y = np.empty(n)
    n_runs = run_starts.shape[0]
    for q in range(n_runs):
        a = run_starts[q]
        b = run_starts[q + 1] if q + 1 < n_runs else n
        lo = min(lower[a], upper[a])
        hi = max(lower[a], upper[a])
        yk = 0.5 * (lo + hi)
        y[a] = yk
        for k in range(a + 1, b):
            lo = min(lower[k], upper[k])
            hi = max(lower[k], upper[k])
            yk = yk + slope * (v[k] - v[k - 1])
            if yk < lo:
                yk = lo
            elif yk > hi:
                yk = hi
            y[k] = yk
    return y


@njit(cache=True)
def gplay_forward_jac(v, lower, upper, Jl, Ju, dl, du, slope, M, run_starts):
    """:func:`gplay_forward` and its Jacobian.

    ``Jl``, ``Ju`` (n, p): derivatives of the two branches at ``v`` by the base's branch
    parameters; ``dl``, ``du`` (n,): the branches' slopes in ``v``; ``M`` (n, q): ``dv/dθ``
    of the upstream (input-effect) parameters. Returns ``y`` (n,), ``dy/d(branch
    parameters, slope)`` (n, p + 1) and ``dy/dθ`` (n, q): on a branch ``y`` follows it, in
    a transition it carries the previous sample's derivatives plus the slope's step.
    """
    n = v.shape[0]
    p = Jl.shape[1]
    q = M.shape[1]
    y = np.empty(n)
    Jb = np.zeros((n, p + 1))
    Jm = np.zeros((n, q))
    n_runs = run_starts.shape[0]
    for r in range(n_runs):
        a = run_starts[r]
        b = run_starts[r + 1] if r + 1 < n_runs else n
        yk = 0.5 * (lower[a] + upper[a])
        y[a] = yk
        for j in range(p):
            Jb[a, j] = 0.5 * (Jl[a, j] + Ju[a, j])
        for j in range(q):
            Jm[a, j] = 0.5 * (dl[a] + du[a]) * M[a, j]
        for k in range(a + 1, b):
            low_is_l = lower[k] <= upper[k]
            lo = lower[k] if low_is_l else upper[k]
            hi = upper[k] if low_is_l else lower[k]
            yk = yk + slope * (v[k] - v[k - 1])
            if yk < lo or yk > hi:
                on_l = (yk < lo) == low_is_l  # the branch the output is clipped to
                yk = lo if yk < lo else hi
                for j in range(p):
                    Jb[k, j] = Jl[k, j] if on_l else Ju[k, j]
                d = dl[k] if on_l else du[k]
                for j in range(q):
                    Jm[k, j] = d * M[k, j]
            else:
                for j in range(p + 1):
                    Jb[k, j] = Jb[k - 1, j]
                Jb[k, p] += v[k] - v[k - 1]
                for j in range(q):
                    Jm[k, j] = Jm[k - 1, j] + slope * (M[k, j] - M[k - 1, j])
            y[k] = yk
    return y, Jb, Jm


@njit(cache=True)
def _gplay_g(u, u_prev, y_prev, slope, t_up, c_up, t_dn, c_dn, deg):
    a = bspline_eval(t_up, c_up, deg, u)
    b = bspline_eval(t_dn, c_dn, deg, u)
    lo = min(a, b)
    hi = max(a, b)
    y = y_prev + slope * (u - u_prev)
    if y < lo:
        return lo
    if y > hi:
        return hi
    return y


#: Relative difference between a target and the present output below which the inverse holds
#: the command (:func:`gplay_inverse_step`, :func:`play_inverse_step`, the rate play's inverse):
#: rounding, not a request to move.
HOLD_TOL = 1e-9


@njit(cache=True)
def gplay_inverse_step(target, u_prev, y_prev, slope, t_up, c_up, t_dn, c_dn, deg, u_min, u_max):
    """Command ``u`` whose generalised-play output from state (``u_prev``, ``y_prev``) is ``target``.

    The step map is non-decreasing in ``u``, so bisection is exact to the tolerance;
    among equal outputs the command closest to ``u_prev`` is returned (no needless
    motion inside the backlash band). A target within :data:`HOLD_TOL` (relative) of the
    present output is the present output: with a flat backlash band (slope 0) a rounding
    error of 1e-15 deg would otherwise send the command across the band, and a held target
    made it jump between the branches every sample (17.8 deg at 100 Hz on the demo's
    B-spline). Unreachable targets give the nearest bound. Returns ``(u, y)``.
    """
    g0 = _gplay_g(u_prev, u_prev, y_prev, slope, t_up, c_up, t_dn, c_dn, deg)
    if abs(g0 - target) <= HOLD_TOL * max(1.0, abs(target)):
        return u_prev, g0
    if target > g0:
        a = u_prev
        b = max(u_max, u_prev)
        gb = _gplay_g(b, u_prev, y_prev, slope, t_up, c_up, t_dn, c_dn, deg)
        if gb <= target:
            return b, gb
        # smallest u in [a, b] with g(u) >= target
        for _ in range(80):
            mid = 0.5 * (a + b)
            if mid == a or mid == b:
                break
            if _gplay_g(mid, u_prev, y_prev, slope, t_up, c_up, t_dn, c_dn, deg) >= target:
                b = mid
            else:
                a = mid
        u = b
    else:
        a = min(u_min, u_prev)
        b = u_prev
        ga = _gplay_g(a, u_prev, y_prev, slope, t_up, c_up, t_dn, c_dn, deg)
        if ga >= target:
            return a, ga
        # largest u in [a, b] with g(u) <= target
        for _ in range(80):
            mid = 0.5 * (a + b)
            if mid == a or mid == b:
                break
            if _gplay_g(mid, u_prev, y_prev, slope, t_up, c_up, t_dn, c_dn, deg) <= target:
                a = mid
            else:
                b = mid
        u = a
    return u, _gplay_g(u, u_prev, y_prev, slope, t_up, c_up, t_dn, c_dn, deg)


@njit(cache=True)
def gplay_midline_inverse(target, t_up, c_up, t_dn, c_dn, deg, u_min, u_max):
    """Command on the branches' mid-line (where a run starts) giving ``target``; returns ``(u, y)``."""
    lo_u = u_min
    hi_u = u_max
    for _ in range(200):
        mid = 0.5 * (lo_u + hi_u)
        if mid == lo_u or mid == hi_u:
            break
        m = 0.5 * (bspline_eval(t_up, c_up, deg, mid) + bspline_eval(t_dn, c_dn, deg, mid))
        if m < target:
            lo_u = mid
        else:
            hi_u = mid
    uk = 0.5 * (lo_u + hi_u)
    return uk, 0.5 * (bspline_eval(t_up, c_up, deg, uk) + bspline_eval(t_dn, c_dn, deg, uk))


@njit(cache=True)
def gplay_inverse(y, slope, t_up, c_up, t_dn, c_dn, deg, u_min, u_max, run_starts):
    """Numerical inverse of :func:`gplay_forward` sample by sample (bisection), per run.

    The first sample of a run is inverted on the mid-line (where the forward model
    starts); later samples with :func:`gplay_inverse_step`.
    """
    n = y.shape[0]
    u = np.empty(n)
    n_runs = run_starts.shape[0]
    for q in range(n_runs):
        a = run_starts[q]
        b = run_starts[q + 1] if q + 1 < n_runs else n
        uk, yk = gplay_midline_inverse(y[a], t_up, c_up, t_dn, c_dn, deg, u_min, u_max)
        u[a] = uk
        for k in range(a + 1, b):
            uk, yk = gplay_inverse_step(y[k], uk, yk, slope, t_up, c_up, t_dn, c_dn, deg, u_min, u_max)
            u[k] = uk
    return u


@njit(cache=True)
def count_reversals(u, tol):
    """Direction reversals of ``u`` that travel back at least ``tol`` from the last extreme."""
    direction = 0
    anchor = u[0]
    extreme = u[0]
    total = 0
    for k in range(1, u.shape[0]):
        x = u[k]
        if direction == 0:
            if x >= anchor + tol:
                direction = 1
                extreme = x
            elif x <= anchor - tol:
                direction = -1
                extreme = x
        elif direction == 1:
            if x > extreme:
                extreme = x
            elif x <= extreme - tol:
                direction = -1
                extreme = x
                total += 1
        else:
            if x < extreme:
                extreme = x
            elif x >= extreme + tol:
                direction = 1
                extreme = x
                total += 1
    return total


#: largest exponent of the PI weight law (eq. 8) evaluated: a weight ratio of e^100 across
#: the operators is far beyond any physical loop, and squared residuals summed over many
#: samples must stay finite (e^200 ~ 1e87) for the optimiser to reject such a trial step
_EXP_MAX = 100.0


@njit(cache=True)
def pi_free_forward_jac(x, thresholds, weights, G, run_starts):
    """PI with given thresholds and free weights (eqs. 5, 7) and its exact Jacobian.

    ``G`` (n, q) is the Jacobian of the input ``x`` w.r.t. q upstream parameters. A play
    output equals ``x_a -+ r_i`` with ``a`` the sample that last pushed it, so its
    sensitivity to upstream parameters is that of the anchor sample (as in
    :func:`pi_exp_forward_jac`); its sensitivity to ``ω_i`` is the play output itself.

    Returns ``y`` (n,), ``J`` (n, q + m): columns q upstream, then ``ω_0..ω_{m-1}``.
    """
    n = x.shape[0]
    q = G.shape[1]
    m = thresholds.shape[0]
    y = np.empty(n)
    J = np.zeros((n, q + m))
    z = np.zeros(m)
    anchor = np.full(m, -1)
    n_runs = run_starts.shape[0]
    for qq in range(n_runs):
        a = run_starts[qq]
        b = run_starts[qq + 1] if qq + 1 < n_runs else n
        for i in range(m):
            z[i] = 0.0
            anchor[i] = -1
        for k in range(a, b):
            xk = x[k]
            acc = 0.0
            for i in range(m):
                lo = xk - thresholds[i]
                hi = xk + thresholds[i]
                if z[i] < lo:
                    z[i] = lo
                    anchor[i] = k
                elif z[i] > hi:
                    z[i] = hi
                    anchor[i] = k
                acc += weights[i] * z[i]
                J[k, q + i] = z[i]
                ai = anchor[i]
                if ai >= 0:
                    wgt = weights[i]
                    for j in range(q):
                        J[k, j] += wgt * G[ai, j]
            y[k] = acc
    return y, J


@njit(cache=True)
def pi_exp_forward_jac(x, r, w, beta, n_ops, G, run_starts):
    """PI with ``r_i = r·i``, ``ω_i = ω e^{-β r_i}`` (eqs. 5, 7, 8) and its exact Jacobian.

    ``G`` (n, q) is the Jacobian of the input ``x`` w.r.t. q upstream parameters (the
    envelope's, eq. 6). A play output equals ``x_a ∓ r_i`` with ``a`` the last sample at
    which it was pushed, so its sensitivities are those of that anchor sample.

    Returns ``y`` (n,) and ``J`` (n, q + 3): columns q upstream, then r, ω, β.
    """
    n = x.shape[0]
    q = G.shape[1]
    m = n_ops + 1
    y = np.empty(n)
    J = np.zeros((n, q + 3))
    idx = np.arange(m) * 1.0
    thr = r * idx
    # exponent clipped where exp overflows (a trial step of the optimiser far outside
    # any physical β); the weights are then huge and the step is rejected
    wi = w * np.exp(np.minimum(np.maximum(-beta * thr, -_EXP_MAX), _EXP_MAX))
    z = np.zeros(m)
    anchor = np.full(m, -1)
    cr = np.zeros(m)
    gacc = np.zeros(q)
    n_runs = run_starts.shape[0]
    for qq in range(n_runs):
        a = run_starts[qq]
        b = run_starts[qq + 1] if qq + 1 < n_runs else n
        for i in range(m):
            z[i] = 0.0
            anchor[i] = -1
            cr[i] = 0.0
        for k in range(a, b):
            xk = x[k]
            acc = 0.0
            d_r = 0.0
            d_b = 0.0
            cur = -1
            wsum = 0.0
            for i in range(m):
                lo = xk - thr[i]
                hi = xk + thr[i]
                if z[i] < lo:
                    z[i] = lo
                    anchor[i] = k
                    cr[i] = -idx[i]
                elif z[i] > hi:
                    z[i] = hi
                    anchor[i] = k
                    cr[i] = idx[i]
                wz = wi[i] * z[i]
                acc += wz
                d_r += wi[i] * cr[i] - beta * idx[i] * wz
                d_b -= thr[i] * wz
                # plays pushed at the same sample share its sensitivities: sum their weights, then one
                # row of G per anchor (a few per sample) instead of one per play (m)
                ai = anchor[i]
                if ai != cur:
                    if cur >= 0:
                        for j in range(q):
                            gacc[j] += wsum * G[cur, j]
                    cur = ai
                    wsum = 0.0
                wsum += wi[i]
            if cur >= 0:
                for j in range(q):
                    gacc[j] += wsum * G[cur, j]
            for j in range(q):
                J[k, j] = gacc[j]
                gacc[j] = 0.0
            y[k] = acc
            J[k, q] = d_r
            J[k, q + 1] = acc / w
            J[k, q + 2] = d_b
    return y, J


@njit(cache=True)
def varplay_forward_jac(u, w, Wg, M, run_starts):
    """Play operator of time-varying half width: ``v_k = clip(v_{k-1}, u_k - w_k, u_k + w_k)``, ``v_0 = u_0``.

    The extra friction backlash of the ``rate`` and ``load`` effects (widths ``w`` >= 0,
    deg of knob). ``M`` (n, q) is the Jacobian of ``u`` w.r.t. q upstream parameters and
    ``Wg`` (n, q + p) that of ``w`` w.r.t. those and the effect's p own parameters. A play
    output is the carried value or ``u_k -+ w_k`` at the sample that last pushed it, so its
    derivatives are those of that sample.

    Returns ``v`` (n,) and ``J`` (n, q + p).
    """
    n = u.shape[0]
    q = M.shape[1]
    P = Wg.shape[1]
    v = np.empty(n)
    J = np.zeros((n, P))
    n_runs = run_starts.shape[0]
    for r in range(n_runs):
        a = run_starts[r]
        b = run_starts[r + 1] if r + 1 < n_runs else n
        vk = u[a]
        v[a] = vk
        for j in range(q):
            J[a, j] = M[a, j]
        for k in range(a + 1, b):
            lo = u[k] - w[k]
            hi = u[k] + w[k]
            if vk < lo:
                vk = lo
                for j in range(P):
                    J[k, j] = -Wg[k, j]
                for j in range(q):
                    J[k, j] += M[k, j]
            elif vk > hi:
                vk = hi
                for j in range(P):
                    J[k, j] = Wg[k, j]
                for j in range(q):
                    J[k, j] += M[k, j]
            else:
                for j in range(P):
                    J[k, j] = J[k - 1, j]
            v[k] = vk
    return v, J


def play_inverse_step(v, v_prev, u_prev, w):
    """One sample of a play's inverse: the knob that moves the drive from ``v_prev`` to ``v`` with half width ``w``.

    The drive moving up means the knob pushes from below (``u = v + w``), down from above;
    a drive at rest leaves the knob where it was unless the window forces it. A target within
    :data:`HOLD_TOL` (relative) of ``v_prev`` is a drive at rest: rounding, not a reversal (a held
    angle that wobbles by 1e-15 deg turned the knob across the whole play at every wobble). The
    caller keeps ``v_prev`` where the drive is (:func:`play_reference`).
    """
    tol = HOLD_TOL * max(1.0, abs(v))
    if v - v_prev > tol:
        return v + w
    if v_prev - v > tol:
        return v - w
    return min(max(u_prev, v - w), v + w)


def play_reference(v, v_prev, u, u_prev):
    """Where the drive is after an inverse step from ``v_prev`` to ``v`` that turned the knob from ``u_prev`` to
    ``u``: at ``v``, unless the step was a hold within :data:`HOLD_TOL` that left the knob still (then where it
    was, so that a slow creep of the target adds up until it moves the drive)."""
    if u == u_prev and abs(v - v_prev) <= HOLD_TOL * max(1.0, abs(v)):
        return v_prev
    return v


play_inverse_step_jit = njit(cache=True)(play_inverse_step)
play_reference_jit = njit(cache=True)(play_reference)


@njit(cache=True)
def causal_play_inverse(v, w0, w1, run_starts):
    """Commands whose :func:`varplay_forward_jac` output is ``v`` (exact, causal).

    The half width at sample ``k`` is ``max(w0_k + w1_k |u_{k-1}|, 0)``: known widths
    (``w1 = 0``) or widths growing with the previous command (the ``load`` and ``tension``
    effects), which keeps the inverse explicit.
    """
    n = v.shape[0]
    u = np.empty(n)
    n_runs = run_starts.shape[0]
    for r in range(n_runs):
        a = run_starts[r]
        b = run_starts[r + 1] if r + 1 < n_runs else n
        u[a] = v[a]
        ref = v[a]  # where the drive is (play_reference)
        for k in range(a + 1, b):
            u[k] = play_inverse_step_jit(v[k], ref, u[k - 1], max(w0[k] + w1[k] * abs(u[k - 1]), 0.0))
            ref = play_reference_jit(v[k], ref, u[k], u[k - 1])
    return u
