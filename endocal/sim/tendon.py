"""Tendon-sheath mechanics of the bending axes, compiled with numba.

Physics (one bending axis)
--------------------------
An antagonistic tendon pair runs from the knob pulley (radius ``r_p``) through the sheath
of the insertion tube to the bending section, where it sits at ``r_t`` from the neutral
axis. The agonist (``k = 0``, sign ``s = +1``) is pulled by a positive knob angle ``q``,
the antagonist (``k = 1``, ``s = -1``) by a negative one. Each tendon is discretised into
``N + 1`` nodes along the sheath, node ``j`` at cumulative wrap angle
``Theta_j = Theta * j / N`` from the knob; its state is the tension profile ``T_j`` (N).

Coulomb friction against the sheath is proportional to the normal force, i.e. to tension
times curvature, so along a slipping stretch ``|d ln T / d Theta| = mu`` (capstan) and a
stored profile always satisfies ``|d ln T / d Theta| <= mu``. When one end of the tendon
moves while the other is held, the tendon slips in a zone next to the moving end and sticks
beyond it; with that end's tension ``T_e`` the new profile is exactly

    T_j(new) = clamp(T_j(old), T_e * exp(-mu * Theta'_j), T_e * exp(+mu * Theta'_j))     (capstan)

with ``Theta'_j`` the wrap between node ``j`` and the moving end (the stored profile's slope
bound makes the stuck zone start where the clamp stops acting). The tendon's total stretch
(its extension beyond its natural length, mm) is the sum of the node elongations

    stretch = sum_j w_j * T_j,   w_j = segment length / EA   (mm/N),

and kinematics fixes it: ``stretch = e_pre - slack + s * (r_p * q - d)``, with ``d`` the
distal displacement of the tendon's anchor, ``d = r_t * (beta + c * beta_other)`` for a bend
``beta`` of this axis (``c`` = tendon-hole coupling). ``stretch <= 0`` means a slack tendon
whose profile is zero (a capstan cannot hold tension against a free end).
``sum_j w_j clamp(...)`` is piecewise linear and strictly increasing in ``T_e``, so the end
tension for a given stretch is found exactly by a bracketed Newton iteration.

One motor tick is split in the two boundary motions, each a valid quasi-static sub-step
(the split error vanishes with the tick length; at 100 Hz it is far below the tracker noise):

1. the knob moves with the distal anchor held: proximal clamp, end tension ``T_0``;
2. the bend ``beta`` moves with the knob held: distal clamp, end tension ``T_N``, where
   ``beta`` solves the moment balance of the bending section

       r_t * (T_N,agonist - T_N,antagonist) = M_bend(beta) + M_contact(beta) +- M_f,
       M_bend = K * beta * (1 + e * (beta / beta_s)^2)        ([envelope] stiffening, e = 0/1),

   where ``M_f`` is the Coulomb friction moment of the snake-bone joints and cover: the bend
   sticks while the imbalance stays within ``+-M_f`` (a tension-independent backlash that
   keeps the loop open near the neutral bend, where slack tendons carry no tension and the
   sheath friction alone would pinch it shut). The left side falls and the right side rises
   with ``beta``, so the root is unique; it is found by a safeguarded Newton iteration
   warm-started at the previous tick.

This differs from the lumped one-sided model in the brief in one respect: the distal anchor's
motion is applied at the distal end (sub-step 2) instead of being absorbed at the knob. That
is what makes a bend forced from outside (the other axis through ``coupling``, a wall)
change the tendon tensions at once, as it does in a real sheath. While the tendon keeps
slipping along its whole length (steady pulling) both formulations coincide.

Everything here is in mm, N, rad and s; the caller converts degrees at the edges.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from endocal.models._smooth_friction import state_step

#: Indices of the degrees of freedom in the motor arrays: two knobs, translation, rotation.
N_DOF = 4


@njit(cache=True)
def _clamped_sum(old, w, lo_f, hi_f, t_end):
    """``g(T) = sum_j w_j clamp(old_j, T lo_f_j, T hi_f_j)`` and its right-hand slope ``dg/dT``.

    A node exactly on its lower bound counts as clamped (it moves when ``T`` grows), so the
    knob-end node (``lo_f = hi_f = 1``) always contributes and the slope is positive.
    """
    g = 0.0
    dg = 0.0
    for j in range(old.size):
        lo = t_end * lo_f[j]
        hi = t_end * hi_f[j]
        if old[j] <= lo:
            g += w[j] * lo
            dg += w[j] * lo_f[j]
        elif old[j] > hi:
            g += w[j] * hi
            dg += w[j] * hi_f[j]
        else:
            g += w[j] * old[j]
    return g, dg


@njit(cache=True)
def end_tension(old, w, lo_f, hi_f, sum_w_lo, sum_w_hi, target, guess):
    """End tension ``T_e`` (N) that gives the tendon the stretch ``target`` (mm).

    Solves ``sum_j w_j clamp(old_j, T_e lo_f_j, T_e hi_f_j) = target`` (capstan clamp, see
    the module docstring) for ``target > 0``; returns ``(T_e, dg/dT_e)``. ``(0, 0)`` for a
    slack tendon (``target <= 0``). The root lies in
    ``[target / sum_w_hi, target / sum_w_lo]`` because every clamp lies between ``T_e lo_f_j``
    and ``T_e hi_f_j``; inside, Newton is exact once it lands on the right linear piece and
    bisection takes over whenever a step leaves the bracket.
    """
    if target <= 0.0:
        return 0.0, 0.0
    a = target / sum_w_hi
    b = target / sum_w_lo
    t = min(max(guess, a), b)
    dg = sum_w_lo
    for _ in range(100):
        g, dg = _clamped_sum(old, w, lo_f, hi_f, t)
        r = g - target
        if abs(r) <= 1e-13 * target:
            return t, dg
        if r > 0.0:
            b = t
        else:
            a = t
        tn = t - r / dg if dg > 0.0 else 0.5 * (a + b)
        if not (a < tn < b):
            tn = 0.5 * (a + b)
        if b - a <= 1e-15 * b:
            return tn, dg
        t = tn
    return t, dg


@njit(cache=True)
def _apply_clamp(old, lo_f, hi_f, t_end, out):
    for j in range(old.size):
        lo = t_end * lo_f[j]
        hi = t_end * hi_f[j]
        v = old[j]
        if v < lo:
            v = lo
        elif v > hi:
            v = hi
        out[j] = v


@njit(cache=True)
def _weight_moment(beta, w_force):
    """Moment (N*mm) of a tip weight about the section base and its derivative in ``beta``.

    ``w_force * sin(beta) / beta``: force times the constant-curvature lever arm (the tip's
    axial distance from the base, ``l sin(beta)/beta``), ``w_force = F * l`` (N*mm).
    """
    if w_force == 0.0:
        return 0.0, 0.0
    if abs(beta) < 1e-4:
        return w_force * (1.0 - beta * beta / 6.0), -w_force * beta / 3.0
    return w_force * math.sin(beta) / beta, w_force * (beta * math.cos(beta) - math.sin(beta)) / (beta * beta)


@njit(cache=True)
def _moment_residual(beta, mid, w, lo_d, hi_d, swlo_d, swhi_d, base_ag, base_an, r_t, c_other, k_bend, inv_bs2,
                     wall, wall_sign, k_wall, w_force, guess_ag, guess_ant):
    """Moment balance ``R(beta)`` (N*mm), ``dR/dbeta`` and the two distal tensions (N).

    ``base_ag``, ``base_an`` are the tendons' stretches before the distal anchor displacement
    ``d = r_t (beta + c beta_other)`` is taken off (agonist) or added (antagonist).
    ``R`` is strictly decreasing in ``beta``.
    """
    d = r_t * (beta + c_other)
    t_ag, g_ag = end_tension(mid[0], w, lo_d, hi_d, swlo_d, swhi_d, base_ag - d, guess_ag)
    t_an, g_an = end_tension(mid[1], w, lo_d, hi_d, swlo_d, swhi_d, base_an + d, guess_ant)
    m_bend = k_bend * beta * (1.0 + inv_bs2 * beta * beta)
    dm = k_bend * (1.0 + 3.0 * inv_bs2 * beta * beta)
    pen = wall_sign * (beta - wall)
    m_wall = 0.0
    if k_wall > 0.0 and pen > 0.0:
        m_wall = wall_sign * k_wall * pen
        dm += k_wall
    m_w, dm_w = _weight_moment(beta, w_force)
    dm += dm_w
    r = r_t * (t_ag - t_an) - m_bend - m_wall - m_w
    dr = -dm
    if g_ag > 0.0:
        dr -= r_t * r_t / g_ag
    if g_an > 0.0:
        dr -= r_t * r_t / g_an
    return r, dr, t_ag, t_an


@njit(cache=True)
def axis_step(prof, mid, w, lo_p, hi_p, lo_d, hi_d, q_rad, d_old, beta_prev, beta_other,
              r_p, r_t, e0, c_couple, k_bend, inv_bs2, m_fric, wall, wall_sign, k_wall, w_force):
    """Advance one bending axis by one motor tick (both sub-steps); updates ``prof`` in place.

    Parameters
    ----------
    prof : (2, N+1) array
        Tension profiles (N) of agonist and antagonist, knob end first; updated.
    mid : (2, N+1) array
        Work space.
    w : (N+1,) array
        Node compliances (mm/N).
    lo_p, hi_p, lo_d, hi_d : (N+1,) arrays
        Capstan factors ``exp(-+mu Theta'_j)`` seen from the knob (``_p``) and from the distal end (``_d``).
    q_rad : float
        Knob angle at the end of the tick (rad).
    d_old : float
        Distal displacement of the tendon anchors used at the previous tick (mm).
    beta_prev, beta_other : float
        This axis' bend at the previous tick and the other axis' latest bend (rad).
    r_p, r_t, e0 : float
        Pulley radius, tendon offset, and ``e_pre - slack`` (mm).
    c_couple : float
        Coupling ratio (0 without ``coupling``).
    k_bend, inv_bs2 : float
        Bending stiffness (N*mm/rad) and ``1/beta_s^2`` of the envelope (0 without it).
    m_fric : float
        Coulomb friction moment of the bending section's joints (N*mm): the bend sticks while
        the moment imbalance stays within ``+-m_fric`` and otherwise slides to where the
        imbalance equals ``+-m_fric``.
    wall, wall_sign, k_wall : float
        Wall bend (rad), its half-plane (+-1) and rotational stiffness (N*mm/rad, 0 = no wall).
    w_force : float
        Tip weight times the bending length (N*mm, 0 = none): moment ``w_force sin(beta)/beta``.

    Returns
    -------
    beta : float
        New bend (rad).
    d_new : float
        Distal anchor displacement now (mm).
    m_wall : float
        Contact moment magnitude (N*mm, >= 0): the wall's or the weight's.
    """
    n = prof.shape[1]
    swlo_p = 0.0
    swhi_p = 0.0
    swlo_d = 0.0
    swhi_d = 0.0
    for j in range(n):
        swlo_p += w[j] * lo_p[j]
        swhi_p += w[j] * hi_p[j]
        swlo_d += w[j] * lo_d[j]
        swhi_d += w[j] * hi_d[j]
    pull = r_p * q_rad
    base_ag = e0 + pull  # agonist stretch before the distal displacement is subtracted
    base_an = e0 - pull  # antagonist stretch before the distal displacement is added
    # Sub-step 1: the knob moves, the distal anchors stay where they were.
    t0, _ = end_tension(prof[0], w, lo_p, hi_p, swlo_p, swhi_p, base_ag - d_old, prof[0, 0])
    _apply_clamp(prof[0], lo_p, hi_p, t0, mid[0])
    t0, _ = end_tension(prof[1], w, lo_p, hi_p, swlo_p, swhi_p, base_an + d_old, prof[1, 0])
    _apply_clamp(prof[1], lo_p, hi_p, t0, mid[1])
    # Sub-step 2: the bend settles, the knob stays where it is.
    c_other = c_couple * beta_other
    b = beta_prev
    r, dr, t_ag, t_an = _moment_residual(b, mid, w, lo_d, hi_d, swlo_d, swhi_d, base_ag, base_an, r_t, c_other, k_bend,
                                         inv_bs2, wall, wall_sign, k_wall, w_force, mid[0, n - 1], mid[1, n - 1])
    # Joint friction: stick inside the friction cone, else slide to its edge on the side of the imbalance.
    slide = 0.0
    if r > m_fric:
        slide = m_fric
    elif r < -m_fric:
        slide = -m_fric
    else:
        r = 0.0
    r -= slide
    lo = -math.inf
    hi = math.inf
    for it in range(200):
        if r == 0.0:
            break
        if r > 0.0:
            lo = b
        else:
            hi = b
        step = -r / dr
        if step > 0.5:
            step = 0.5
        elif step < -0.5:
            step = -0.5
        bn = b + step
        if (lo > -math.inf and hi < math.inf) and (not (lo < bn < hi) or it > 40):
            bn = 0.5 * (lo + hi)
        if abs(bn - b) <= 1e-13 * (1.0 + abs(b)):
            b = bn
            break
        b = bn
        r, dr, t_ag, t_an = _moment_residual(b, mid, w, lo_d, hi_d, swlo_d, swhi_d, base_ag, base_an, r_t, c_other, k_bend,
                                             inv_bs2, wall, wall_sign, k_wall, w_force, t_ag, t_an)
        r -= slide
        if abs(r) <= 1e-11 * (1.0 + k_bend):
            break
    d_new = r_t * (b + c_other)
    t_ag, _ = end_tension(mid[0], w, lo_d, hi_d, swlo_d, swhi_d, base_ag - d_new, t_ag)
    t_an, _ = end_tension(mid[1], w, lo_d, hi_d, swlo_d, swhi_d, base_an + d_new, t_an)
    _apply_clamp(mid[0], lo_d, hi_d, t_ag, prof[0])
    _apply_clamp(mid[1], lo_d, hi_d, t_an, prof[1])
    pen = wall_sign * (b - wall)
    m_wall = k_wall * pen if (k_wall > 0.0 and pen > 0.0) else 0.0
    m_w, _ = _weight_moment(b, w_force)
    return b, d_new, m_wall + abs(m_w)


@njit(cache=True)
def _motor(pos, vel, goal, tau, vmax, dt):
    """Critically damped second-order position loop, zero-order hold on the goal, speed-limited.

    Exact solution of ``x'' = w^2 (g - x) - 2 w x'`` with ``w = 1/tau`` over ``dt``; the speed
    limit then caps both the velocity and the distance moved in the tick. ``tau = 0`` is an
    ideal (only speed-limited) servo.
    """
    if dt <= 0.0:
        return pos, vel
    if tau <= 0.0:
        dx = goal - pos
        lim = vmax * dt
        if dx > lim:
            dx = lim
        elif dx < -lim:
            dx = -lim
        return pos + dx, dx / dt
    wn = 1.0 / tau
    e0 = pos - goal
    c1 = vel + wn * e0
    ex = math.exp(-wn * dt)
    e1 = (e0 + c1 * dt) * ex
    v1 = (vel - wn * c1 * dt) * ex
    dx = e1 - e0
    lim = vmax * dt
    if dx > lim:
        dx = lim
    elif dx < -lim:
        dx = -lim
    if v1 > vmax:
        v1 = vmax
    elif v1 < -vmax:
        v1 = -vmax
    return pos + dx, v1


@njit(cache=True)
def bouc_wen_lag(h, dq, lag_max, sigma):
    """``[tendon] friction = "bouc-wen"``: the knob lag ``h`` (rad) after a knob step ``dq`` (rad).

    The normalised Bouc-Wen law (Ismail, Ikhouane & Rodellar 2009, eq. 13) with ``n = 1`` on the state
    ``w = h / lag_max`` and ``rho = 1 / (2 sigma lag_max)``: right after a reversal from saturation the lag
    changes as fast as the knob (the tendon, and the tip, hold), then the pull picks up along an
    exponential. ``lag_max`` follows the friction (mu, wrap, speed), so a lag above a lower new limit is
    clipped to it (the element slips). No return-point memory: the state after a small reversal and
    back is not the state before it.
    """
    if lag_max <= 0.0:
        return 0.0
    wk = h / lag_max
    if wk > 1.0:
        wk = 1.0
    elif wk < -1.0:
        wk = -1.0
    return lag_max * state_step(0, wk, dq, 1.0 / (2.0 * sigma * lag_max), sigma, 1.0)


@njit(cache=True)
def simulate_ticks(dt_s, goal, wrap_rad, w, tau_s, vmax, r_p, r_t, e0, mu, rate_gain_s_per_rad, coupling,
                   k_bend, inv_bs2, m_fric, wall_axis, wall_rad, wall_sign, k_wall, w_force,
                   held, pos, vel, prof, d_mm, beta_qs, out_pos, out_vel, out_t0, out_beta, out_mwall,
                   rate_linear=False, band_center_rad=0.0, bw_lag_per_mu=0.0, bw_sigma=1.0, bw_state=None):
    """Run a chunk of motor ticks; every state array is updated in place.

    Parameters
    ----------
    dt_s : (n,) array
        Tick lengths (s); the first tick of a run has 0.
    goal : (n, 4) array
        Goals of knob 1, knob 2 (rad), translation (mm), rotation (rad).
    wrap_rad : (n,) array
        Sheath wrap angle at each tick (rad).
    w : (N+1,) array
        Node compliances (mm/N).
    tau_s, vmax : (4,) arrays
        Position-loop time constants (s) and speed limits (goal units per s).
    r_p, r_t, e0, mu : float
        Pulley radius, tendon offset, ``e_pre - slack`` (mm), friction coefficient.
    rate_gain_s_per_rad : float
        ``[rate]``: relative friction increase per rad/s of knob speed (0 = off).
    rate_linear : bool
        ``[rate] law = "linear"``: the slip thresholds, not the friction coefficient, grow linearly
        with speed: the capstan's bound ``e^{mu Theta}`` becomes ``1 + (e^{mu Theta} - 1)(1 + g |v|)``.
    band_center_rad : float
        ``[deadzone] center_deg``: the knob angle at which the two tendons are equally slack (the
        agonist has ``r_p * center`` less slack than the antagonist): a dead band not centred at 0.
    coupling : (2,) array
        Coupling ratios of axis 1 (from axis 2) and axis 2 (from axis 1).
    k_bend, inv_bs2 : float
        Bending stiffness (N*mm/rad) and envelope ``1/beta_s^2`` (1/rad^2).
    m_fric : float
        Joint friction moment of the bending section (N*mm).
    wall_axis : int
        Axis the wall blocks (0, 1) or -1 for none.
    wall_rad, wall_sign, k_wall : float
        Wall bend (rad), half-plane sign, rotational stiffness (N*mm/rad).
    w_force : float
        Tip weight on ``wall_axis`` times the bending length (N*mm; 0 = none).
    held : (4,) array
        Goal of the previous tick, held by the servos over the current tick (a goal written at
        tick ``i`` acts from ``t_i`` on; the position read at ``t_i`` has not seen it yet).
    pos, vel : (4,) arrays
        Motor states (goal units, per s).
    prof : (2, 2, N+1) array
        Tension profiles per axis and tendon (N).
    d_mm, beta_qs : (2,) arrays
        Distal anchor displacements (mm) and quasi-static bends (rad).
    out_pos, out_vel : (n, 4) arrays
    out_t0 : (n, 2, 2) array
        Knob-end tension per axis and tendon (N).
    out_beta : (n, 2) array
        Quasi-static bend per axis (rad).
    out_mwall : (n,) array
        Contact moment magnitude (N*mm) of the wall or weight.
    bw_lag_per_mu, bw_sigma : float
        ``[tendon] friction = "bouc-wen"`` (``bw_lag_per_mu > 0``): the sheath is frictionless and one
        Bouc-Wen element at the knob holds the pull back by a lag (:func:`bouc_wen_lag`) that saturates at
        ``bw_lag_per_mu * mu_eff * wrap`` (rad).
    bw_state : (2, 2) array
        Per axis, the element's lag (rad) and the knob angle it last saw (rad); updated.
    """
    n_nodes = prof.shape[2]
    n_seg = n_nodes - 1
    lo_p = np.empty(n_nodes)
    hi_p = np.empty(n_nodes)
    lo_d = np.empty(n_nodes)
    hi_d = np.empty(n_nodes)
    mid = np.empty((2, n_nodes))
    last_mu_theta = -1.0
    last_factor = -1.0
    for i in range(dt_s.size):
        for dof in range(4):
            pos[dof], vel[dof] = _motor(pos[dof], vel[dof], held[dof], tau_s[dof], vmax[dof], dt_s[i])
            held[dof] = goal[i, dof]
        m_wall_tick = 0.0
        for ax in range(2):
            speed_factor = 1.0 + rate_gain_s_per_rad * abs(vel[ax])
            mu_theta = mu * wrap_rad[i] * (1.0 if rate_linear else speed_factor)  # [rate]: mu_eff
            factor = speed_factor if rate_linear else 1.0
            q_pull = pos[ax] - band_center_rad
            if bw_lag_per_mu > 0.0:
                # the friction is the element's: its lag takes the knob's pull back, the sheath slides freely
                bw_state[ax, 0] = bouc_wen_lag(bw_state[ax, 0], pos[ax] - bw_state[ax, 1],
                                               bw_lag_per_mu * mu_theta * factor, bw_sigma)
                bw_state[ax, 1] = pos[ax]
                q_pull -= bw_state[ax, 0]
                mu_theta = 0.0
            if mu_theta != last_mu_theta or factor != last_factor:
                for j in range(n_nodes):
                    th = mu_theta * j / n_seg
                    if rate_linear:  # [rate] law "linear": the thresholds scale with speed
                        hi_p[j] = 1.0 + (math.exp(th) - 1.0) * factor
                        lo_p[j] = 1.0 / hi_p[j]
                    else:
                        lo_p[j] = math.exp(-th)
                        hi_p[j] = math.exp(th)
                for j in range(n_nodes):
                    lo_d[j] = lo_p[n_seg - j]
                    hi_d[j] = hi_p[n_seg - j]
                last_mu_theta = mu_theta
                last_factor = factor
            other = beta_qs[1 - ax]
            has_wall = wall_axis == ax
            b, d_new, m_wall = axis_step(prof[ax], mid, w, lo_p, hi_p, lo_d, hi_d, q_pull, d_mm[ax], beta_qs[ax],
                                         other, r_p, r_t, e0, coupling[ax], k_bend, inv_bs2, m_fric,
                                         wall_rad if has_wall else 0.0, wall_sign, k_wall if has_wall else 0.0,
                                         w_force if has_wall else 0.0)
            beta_qs[ax] = b
            d_mm[ax] = d_new
            if has_wall:
                m_wall_tick = m_wall
            out_t0[i, ax, 0] = prof[ax, 0, 0]
            out_t0[i, ax, 1] = prof[ax, 1, 0]
        for dof in range(4):
            out_pos[i, dof] = pos[dof]
            out_vel[i, dof] = vel[dof]
        out_beta[i, 0] = beta_qs[0]
        out_beta[i, 1] = beta_qs[1]
        out_mwall[i] = m_wall_tick


@njit(cache=True)
def creep_filter(beta_qs, dt_s, fraction, tau_s, slow):
    """Standard-linear-solid relaxation of the bend, exact for a zero-order-hold input.

    ``beta = (1 - a) beta_qs + a beta_slow``, ``d beta_slow/dt = (beta_qs - beta_slow)/tau``.
    ``slow`` (2,) is the state, updated in place. Returns the (n, 2) output bends (rad).
    """
    out = np.empty_like(beta_qs)
    for i in range(beta_qs.shape[0]):
        ex = math.exp(-dt_s[i] / tau_s)
        for ax in range(2):
            slow[ax] = beta_qs[i, ax] + (slow[ax] - beta_qs[i, ax]) * ex
            out[i, ax] = (1.0 - fraction) * beta_qs[i, ax] + fraction * slow[ax]
    return out
