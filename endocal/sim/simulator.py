"""The digital twin: motors -> tendons in sheaths -> bending section -> EM tracker.

Signal path of one motor tick (all in :mod:`endocal.sim.tendon`, compiled):

1. each servo's position loop moves its DoF towards the goal (critically damped, speed-limited);
2. per bending axis, the tendon pair slides through the sheath with capstan friction (or, with
   ``[tendon] friction = "bouc-wen"``, freely, its pull held back by one Bouc-Wen element at the
   knob, a friction without return-point memory), and the bend ``beta`` settles where the distal tendon tensions balance the bending section's
   moment (and a wall's, with ``[contact]``);
3. ``[creep]`` relaxes the bend (standard linear solid); a user's effects hidden with
   ``[user_effects]`` change the goals the tendons are pulled by, or the bend
   (:mod:`endocal.sim.user_effects`);
4. the two axes combine as the duodenoscope paper hypothesises (sec. 2.2, second hypothesis:
   the bending direction is the resultant of the wire pulls) into the bending vector

       b = |beta_1| u(psi_1) + |beta_2| u(psi_2),   u(psi) = (cos psi, sin psi),

   with ``psi`` the nominal half-plane direction (+y 90, -y 270, +x 0, -x 180 deg) plus its
   signed deviation (paper sec. 3.2), so a single knob moves the tip exactly in its
   (deviated) plane (paper sec. 2.2, first hypothesis);
5. the tip pose follows from constant curvature, the EM tracker samples it (see
   :mod:`endocal.sim.tracker`).
"""

from __future__ import annotations

import math

import numpy as np

from endocal.streams import StreamChunk, motor_columns
from endocal.errors import ConfigError, LimitError, ProtocolError
from endocal.kinematics import bending_angles_deg, tip_pose_in_base
from endocal.probe import ProbeConfig
from endocal.sim import tendon
from endocal.sim.config import SimConfig
from endocal.sim.tracker import empty_frames, frame_indices, sensor_frames

#: Nominal direction (deg, counter-clockwise from base +x) of each half-plane of bending.
NOMINAL_DIRECTION_DEG = {"y+": 90.0, "y-": 270.0, "x+": 0.0, "x-": 180.0}

# Speeds below which friction currents are smoothed (tanh), per unit of each DoF's velocity.
_KNOB_FRICTION_SMOOTHING_DPS = 2.0
_TRANSLATION_FRICTION_SMOOTHING_MMPS = 1.0
_ROTATION_FRICTION_SMOOTHING_DPS = 2.0
_LOAD_RANDOM_COMPONENTS = 4


class Simulator:
    """Seeded, deterministic physics simulator of a robot-driven tendon-driven probe.

    Parameters
    ----------
    config : SimConfig
        Physics, tracker and effects.
    probe : ProbeConfig
        DoF names, knob limits and bending length.
    seed : int
        Seed of every random draw (tracker noise and dropouts, current noise, ``[load]``).

    Notes
    -----
    :meth:`execute` may be called with consecutive chunks of any length; the streams are
    identical to one call with the whole trajectory (every state, random stream and
    latency buffer is carried over).
    """

    def __init__(self, config: SimConfig, probe: ProbeConfig, seed: int = 0) -> None:
        if not isinstance(config, SimConfig):
            raise ConfigError(f"Simulator needs a SimConfig, got {type(config).__name__}")
        if not isinstance(probe, ProbeConfig):
            raise ConfigError(f"Simulator needs a ProbeConfig, got {type(probe).__name__}")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ConfigError(f"seed (--seed) must be a non-negative integer, got {seed!r}")
        self.config, self.probe, self.seed = config, probe, int(seed)
        self._axes = probe.bending_axes
        self._columns = motor_columns(probe)
        streams = np.random.SeedSequence(self.seed).spawn(5)
        self._rng_pos, self._rng_rot, self._rng_valid, self._rng_current, rng_load = (
            np.random.default_rng(s) for s in streams
        )
        self._setup_physics(rng_load)
        self._hidden = None
        if config.user_effects:
            from endocal.sim.user_effects import HiddenEffects

            self._hidden = HiddenEffects(config.user_effects, self._axes, probe.resolve_axis, self.seed)
        # State carried across chunks.
        self._held_goal = np.zeros(tendon.N_DOF)  # the probe starts at home: knobs neutral, no translation/rotation
        self._pos = np.zeros(tendon.N_DOF)
        self._vel = np.zeros(tendon.N_DOF)
        self._prof = np.zeros((2, 2, self._w.size))
        if self._e0 > 0.0:
            self._prof[:] = self._e0 / self._w.sum()  # uniform pretension, no friction history yet
        self._d_mm = np.zeros(2)
        self._beta_qs = np.zeros(2)
        self._bw_state = np.zeros((2, 2))  # [tendon] friction = "bouc-wen": per axis, the lag and the last knob (rad)
        self._creep_slow = np.zeros(2)
        self._creep_slow2 = np.zeros(2)
        self._t_last: float | None = None
        self._next_frame: int | None = None
        self._hist_t = np.empty(0)
        self._hist_state = np.empty((0, 4))

    # -- set-up ---------------------------------------------------------------------------
    def _setup_physics(self, rng_load: np.random.Generator) -> None:
        c, ten = self.config, self.config.tendon
        n = ten.n_segments
        # Node j stands for 1/(n+1) of the sheath; the last node also carries the tendon inside
        # the bending section (same tension as the distal end, no sheath friction there).
        w = np.full(n + 1, ten.sheath_length_mm / (n + 1) / ten.axial_stiffness_n)
        w[-1] += self.probe.bending_length_mm / ten.axial_stiffness_n
        self._w = w
        slack = c.deadzone.slack_mm if c.deadzone.enabled else 0.0
        self._e0 = ten.pretension_n * w.sum() - slack  # stretch at the neutral knob, mm
        m = c.motor
        self._tau = np.array([m.knob_time_constant_s, m.knob_time_constant_s,
                              m.translation_time_constant_s, m.rotation_time_constant_s])
        self._vmax = np.array([math.radians(m.knob_max_speed_dps), math.radians(m.knob_max_speed_dps),
                               m.translation_max_speed_mmps, math.radians(m.rotation_max_speed_dps)])
        self._rate_gain = math.degrees(c.rate.gain_s_per_deg) if c.rate.enabled else 0.0  # s/rad
        # [tendon] friction = "bouc-wen": the lag's limit per unit of the capstan exponent (rad); 0 = capstan
        self._bw_lag_per_mu = math.radians(ten.bouc_wen_lag_deg) if ten.friction == "bouc-wen" else 0.0
        cp = c.coupling
        self._coupling = np.array([cp.first_from_second, cp.second_from_first]) if cp.enabled else np.zeros(2)
        self._inv_bs2 = 1.0 / math.radians(c.envelope.stiffening_bend_deg) ** 2 if c.envelope.enabled else 0.0
        # [contact]: a wall at eq.-1 angle theta_w, i.e. at bend 2*theta_w (in-plane CC arc: eq. 1 gives
        # exactly half the bend), with moment k * l^2 * penetration (N*mm/rad) about the section base; or
        # a weight F whose moment is F * l sin(beta)/beta. Either tip force acts perpendicular to the tip,
        # so F = moment / L(beta) with the constant-curvature lever arm L = l sin(beta)/beta.
        self._wall_axis = -1
        self._lever_mm = self.probe.bending_length_mm
        self._wall_rad, self._wall_sign, self._k_wall, self._w_force = 0.0, 1.0, 0.0, 0.0
        if c.contact.enabled:
            try:
                axis = self.probe.resolve_axis(c.contact.axis)
            except ConfigError as exc:
                raise ConfigError(f"contact.axis: {exc}") from None
            if axis not in self._axes:
                raise ConfigError(f"contact.axis must be a bending axis ({', '.join(self._axes)}), got '{axis}'")
            if c.contact.mode == "wall" and c.contact.wall_deg == 0.0:
                raise ConfigError("contact.wall_deg must be non-zero: its sign says which half-plane the wall is on")
            self._wall_axis = self._axes.index(axis)
            if c.contact.mode == "weight":
                self._w_force = c.contact.weight_n * self._lever_mm
            else:
                self._wall_rad = 2.0 * math.radians(c.contact.wall_deg)
                self._wall_sign = 1.0 if c.contact.wall_deg > 0 else -1.0
                self._k_wall = c.contact.stiffness_n_per_mm * self._lever_mm**2
        dev = c.deviation_deg
        self._psi = np.radians([[NOMINAL_DIRECTION_DEG["y+"] + dev["y+"], NOMINAL_DIRECTION_DEG["y-"] + dev["y-"]],
                                [NOMINAL_DIRECTION_DEG["x+"] + dev["x+"], NOMINAL_DIRECTION_DEG["x-"] + dev["x-"]]])
        ld = c.load
        self._load_freq = rng_load.uniform(0.25, 1.0, _LOAD_RANDOM_COMPONENTS) * ld.bandwidth_hz
        self._load_phase = rng_load.uniform(0.0, 2.0 * np.pi, _LOAD_RANDOM_COMPONENTS)
        self._latency_s = c.tracker.latency_s + (c.delay.latency_s if c.delay.enabled else 0.0)

    # -- deterministic functions of time --------------------------------------------------
    def sheath_wrap_deg(self, t_s: np.ndarray) -> np.ndarray:
        """Sheath wrap angle (deg) at times ``t_s``: constant, or varying slowly with ``[load]``.

        ``sine``: ``wrap + A sin(2 pi t / period)``; ``random``: ``wrap + A * mean_k sin(2 pi f_k t + phi_k)``
        with four seeded frequencies in ``[bandwidth/4, bandwidth]`` (bounded by ``+-A``).
        """
        t = np.asarray(t_s, float)
        ld, wrap = self.config.load, self.config.tendon.wrap_deg
        if not ld.enabled:
            return np.full(t.shape, wrap)
        if ld.mode == "sine":
            return wrap + ld.amplitude_deg * np.sin(2.0 * np.pi * t / ld.period_s)
        s = np.sin(2.0 * np.pi * np.multiply.outer(t, self._load_freq) + self._load_phase).mean(axis=-1)
        return wrap + ld.amplitude_deg * s

    def bending_vector_rad(self, beta_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bending vector ``(b_x, b_y)`` (rad) from the per-axis bends ``beta`` (n, 2) (rad).

        Duodenoscope paper sec. 2.2 (resultant of the wire pulls) with the deviated half-planes.
        """
        beta = np.asarray(beta_rad, float)
        bx = np.zeros(beta.shape[0])
        by = np.zeros(beta.shape[0])
        for ax in range(2):
            psi = np.where(beta[:, ax] >= 0.0, self._psi[ax, 0], self._psi[ax, 1])
            mag = np.abs(beta[:, ax])
            bx += mag * np.cos(psi)
            by += mag * np.sin(psi)
        return bx, by

    # -- the contract ---------------------------------------------------------------------
    def execute(self, t_s: np.ndarray, goal: dict[str, np.ndarray], guard=None) -> StreamChunk:
        """Simulate one chunk of motor ticks.

        Parameters
        ----------
        t_s : (n,) array
            Strictly increasing motor-clock times (s from run start), later than the last chunk's.
        goal : dict
            ``dof -> (n,)`` goals for every DoF of the probe (knobs and rotation in deg,
            translation in mm), within the probe's limits.
        guard : ForceGuard, optional
            Per-tick hook (:class:`endocal.force.guard.ForceGuard`): after each tick's physics it
            sees the guarded knob's angle, speed and current and may replace the goal written at
            that tick; the chunk is then stepped tick by tick instead of in one compiled call.

        Returns
        -------
        StreamChunk
            ``motor``: :func:`~endocal.streams.motor_columns` plus ``contact_force_n`` and
            ``sheath_wrap_deg`` (and ``force_pred_n``, the guard's prediction, with a guard); ``tracker``: frames stamped in ``(previous chunk end, t_s[-1]]``;
            ``truth``: ``t_s``, ``<axis>_true_deg`` (noise- and latency-free eq.-1 angles),
            ``bend_x_rad``, ``bend_y_rad``, ``contact_force_n``.

        Raises
        ------
        ProtocolError
            Empty, non-finite or non-increasing times; missing, unknown or misshapen goals.
        LimitError
            A goal beyond the probe's limits.
        """
        t, g = self._check_input(t_s, goal)
        n = t.size
        dt = np.empty(n)
        dt[0] = 0.0 if self._t_last is None else t[0] - self._t_last
        dt[1:] = np.diff(t)
        pulled = g if self._hidden is None else np.column_stack([self._hidden.goal(t, g[:, :2]), g[:, 2:]])
        goal_int = np.column_stack([np.radians(pulled[:, 0]), np.radians(pulled[:, 1]), g[:, 2], np.radians(g[:, 3])])
        wrap_deg = self.sheath_wrap_deg(t)
        out_pos = np.empty((n, 4))
        out_vel = np.empty((n, 4))
        out_t0 = np.empty((n, 2, 2))
        out_beta = np.empty((n, 2))
        out_mwall = np.empty(n)
        outs = (out_pos, out_vel, out_t0, out_beta, out_mwall)
        noise_ma = self._rng_current.standard_normal((n, 4)) * self.config.motor.current_noise_ma
        wrap_rad = np.radians(wrap_deg)
        force_pred_n = None
        if guard is None:
            self._ticks(dt, goal_int, wrap_rad, outs)
        else:
            force_pred_n = self._guarded_ticks(t, dt, g, goal_int, wrap_rad, outs, noise_ma, guard)
        cr = self.config.creep
        beta = out_beta
        if cr.enabled and cr.fraction2 > 0.0:  # two relaxations in parallel, each its own slow state
            slow1 = tendon.creep_filter(out_beta, dt, 1.0, cr.time_constant_s, self._creep_slow)
            slow2 = tendon.creep_filter(out_beta, dt, 1.0, cr.time_constant2_s, self._creep_slow2)
            beta = (1.0 - cr.fraction - cr.fraction2) * out_beta + cr.fraction * slow1 + cr.fraction2 * slow2
        elif cr.enabled:
            beta = tendon.creep_filter(out_beta, dt, cr.fraction, cr.time_constant_s, self._creep_slow)
        if self._hidden is not None:  # a user's effects on the bend ([user_effects], endocal.sim.user_effects)
            beta = self._hidden.bend(t, beta)
        contact_force_n = np.zeros(n)
        if self._wall_axis >= 0:
            contact_force_n = out_mwall / self.lever_arm_mm(out_beta[:, self._wall_axis])
        bx, by = self.bending_vector_rad(beta)
        tip_in_base, _ = tip_pose_in_base(bx, by, self.probe.bending_length_mm)
        true1, true2 = bending_angles_deg(tip_in_base)

        motor = self._motor_stream(t, g, out_pos, out_vel, out_t0, contact_force_n, wrap_deg, noise_ma)
        if force_pred_n is not None:
            motor["force_pred_n"] = force_pred_n
        state = np.column_stack([bx, by, out_pos[:, 2], out_pos[:, 3]])
        tracker = self._tracker_stream(t, state)
        a1, a2 = self._axes
        truth = {
            "t_s": t.copy(),
            f"{a1}_true_deg": true1,
            f"{a2}_true_deg": true2,
            "bend_x_rad": bx,
            "bend_y_rad": by,
            "contact_force_n": contact_force_n.copy(),
        }
        self._t_last = float(t[-1])
        return StreamChunk(motor=motor, tracker=tracker, truth=truth)

    # -- helpers --------------------------------------------------------------------------
    def lever_arm_mm(self, bend_rad: np.ndarray) -> np.ndarray:
        """Lever arm (mm) of a tip force perpendicular to the tip about the section base.

        Constant curvature: the tip's axial distance from the base, ``l sin(beta)/beta``
        (:func:`endocal.kinematics.tip_pose_in_base`, ``z`` component).
        """
        b = np.abs(np.asarray(bend_rad, float))
        return tip_pose_in_base(b, np.zeros_like(b), self.probe.bending_length_mm)[0][:, 2]

    def _ticks(self, dt, goal_int, wrap_rad, outs) -> None:
        """Run ticks ``dt`` through the compiled kernel, updating the carried state."""
        ten = self.config.tendon
        tendon.simulate_ticks(
            dt, goal_int, wrap_rad, self._w, self._tau, self._vmax,
            ten.pulley_radius_mm, ten.offset_mm, self._e0, ten.mu, self._rate_gain, self._coupling,
            self.config.bending.stiffness_nmm_per_rad, self._inv_bs2, self.config.bending.friction_nmm,
            self._wall_axis, self._wall_rad, self._wall_sign, self._k_wall, self._w_force,
            self._held_goal, self._pos, self._vel, self._prof, self._d_mm, self._beta_qs,
            *outs, self.config.rate.enabled and self.config.rate.law == "linear",
            math.radians(self.config.deadzone.center_deg) if self.config.deadzone.enabled else 0.0,
            self._bw_lag_per_mu, ten.bouc_wen_sigma, self._bw_state,
        )

    def _guarded_ticks(self, t, dt, g, goal_int, wrap_rad, outs, noise_ma, guard) -> np.ndarray:
        """Step the chunk tick by tick with ``guard.step`` between ticks; returns its predictions (N).

        A goal written at tick ``i`` acts from ``t_i`` on, so the reading of tick ``i`` does
        not depend on it: the guard sees that reading and may replace the goal before the
        next tick (``g`` and the held goal are updated in place, so the motor stream logs
        what was written).
        """
        try:
            ax = self._axes.index(guard.axis)
        except ValueError:
            raise ConfigError(f"force guard is for axis '{guard.axis}', but probe '{self.probe.name}' "
                              f"has {', '.join(self._axes)}") from None
        m, r_p = self.config.motor, self.config.tendon.pulley_radius_mm
        out_pos, out_vel, out_t0 = outs[0], outs[1], outs[2]
        pred = np.empty(t.size)
        for i in range(t.size):
            sl = slice(i, i + 1)
            self._ticks(dt[sl], goal_int[sl], wrap_rad[sl], tuple(o[sl] for o in outs))
            vel_dps = math.degrees(out_vel[i, ax])
            # The current the motor reports (as in _motor_stream, same noise draw).
            torque_nmm = r_p * (out_t0[i, ax, 0] - out_t0[i, ax, 1]) + m.knob_friction_nmm * math.tanh(
                vel_dps / _KNOB_FRICTION_SMOOTHING_DPS)
            current_ma = torque_nmm / m.torque_constant_nm_per_a + noise_ma[i, ax]
            wanted = g[i, ax]
            allowed = guard.step(float(t[i]), math.degrees(out_pos[i, ax]), vel_dps, current_ma, wanted)
            pred[i] = guard.force_n
            if allowed != wanted:
                g[i, ax] = allowed
                self._held_goal[ax] = math.radians(allowed)
        return pred

    def _check_input(self, t_s, goal) -> tuple[np.ndarray, np.ndarray]:
        t = np.asarray(t_s, dtype=float)
        if t.ndim != 1 or t.size == 0:
            raise ProtocolError(f"t_s must be a non-empty 1-D array of times, got shape {t.shape}")
        if not np.all(np.isfinite(t)):
            raise ProtocolError("t_s contains NaN or infinite times")
        if t.size > 1 and not np.all(np.diff(t) > 0):
            raise ProtocolError("t_s must be strictly increasing")
        if self._t_last is not None and not t[0] > self._t_last:
            raise ProtocolError(f"chunk starts at t = {t[0]} s, not after the previous chunk's end {self._t_last} s")
        if not isinstance(goal, dict):
            raise ProtocolError("goal must be a dict dof -> array")
        dofs = self.probe.dofs
        unknown = sorted(set(goal) - set(dofs))
        if unknown:
            raise ProtocolError(f"goal has unknown DoF '{unknown[0]}' (probe '{self.probe.name}' has {', '.join(dofs)})")
        missing = [d for d in dofs if d not in goal]
        if missing:
            raise ProtocolError(f"goal lacks DoF '{missing[0]}' (every one of {', '.join(dofs)} is needed)")
        g = np.empty((t.size, 4))
        for i, dof in enumerate(dofs):
            v = np.asarray(goal[dof], dtype=float)
            if v.shape != t.shape:
                raise ProtocolError(f"goal '{dof}' has shape {v.shape}, t_s has {t.shape}")
            if not np.all(np.isfinite(v)):
                raise ProtocolError(f"goal '{dof}' contains NaN or infinite values")
            lo, hi = self.probe.limits(dof)
            if v.min() < lo or v.max() > hi:
                u = self.probe.unit(dof)
                raise LimitError(
                    f"goal '{dof}' reaches [{v.min():g}, {v.max():g}] {u}, beyond the probe's limits [{lo:g}, {hi:g}] {u}"
                )
            g[:, i] = v
        return t, g

    def _motor_stream(self, t, g, pos, vel, t0, contact_force_n, wrap_deg, noise) -> dict[str, np.ndarray]:
        m = self.config.motor
        r_p = self.config.tendon.pulley_radius_mm
        vel_units = np.column_stack([np.degrees(vel[:, 0]), np.degrees(vel[:, 1]), vel[:, 2], np.degrees(vel[:, 3])])
        pos_units = np.column_stack([np.degrees(pos[:, 0]), np.degrees(pos[:, 1]), pos[:, 2], np.degrees(pos[:, 3])])
        current = np.empty((t.size, 4))
        for ax in range(2):
            # Knob torque (N*mm) = pulley radius x tension difference at the knob + drive friction;
            # mA = (N*mm / 1000) / (N*m/A) * 1000.
            torque_nmm = r_p * (t0[:, ax, 0] - t0[:, ax, 1]) + m.knob_friction_nmm * np.tanh(
                vel_units[:, ax] / _KNOB_FRICTION_SMOOTHING_DPS)
            current[:, ax] = torque_nmm / m.torque_constant_nm_per_a
        current[:, 2] = m.translation_friction_ma * np.tanh(vel_units[:, 2] / _TRANSLATION_FRICTION_SMOOTHING_MMPS)
        current[:, 3] = m.rotation_friction_ma * np.tanh(vel_units[:, 3] / _ROTATION_FRICTION_SMOOTHING_DPS)
        current += noise
        out = {"t_s": t.copy()}
        for i, dof in enumerate(self.probe.dofs):
            u = self.probe.unit(dof)
            out[f"{dof}_goal_{u}"] = g[:, i].copy()
            out[f"{dof}_pos_{u}"] = pos_units[:, i]
            out[f"{dof}_vel_{u}ps"] = vel_units[:, i]
            out[f"{dof}_current_ma"] = current[:, i]
        out = {c: out[c] for c in self._columns}
        out["contact_force_n"] = contact_force_n
        out["sheath_wrap_deg"] = wrap_deg
        return out

    def _tracker_stream(self, t: np.ndarray, state: np.ndarray) -> dict[str, np.ndarray]:
        cfg = self.config.tracker
        hist_t = np.concatenate([self._hist_t, t])
        hist_state = np.concatenate([self._hist_state, state])
        if self._next_frame is None:
            self._next_frame = int(math.ceil(t[0] * cfg.rate_hz))
            while self._next_frame > 0 and (self._next_frame - 1) / cfg.rate_hz >= t[0]:
                self._next_frame -= 1
        k = frame_indices(self._next_frame, float(t[-1]), cfg.rate_hz)
        if k.size:
            self._next_frame = int(k[-1]) + 1
            t_frame = k / cfg.rate_hz
            t_src = t_frame - self._latency_s
            src = np.column_stack([np.interp(t_src, hist_t, hist_state[:, j]) for j in range(4)])
            drift = self.config.drift.rate_deg_per_min if self.config.drift.enabled else None
            frames = sensor_frames(t_frame, src, self.probe.bending_length_mm, cfg, drift,
                                   self._rng_pos, self._rng_rot, self._rng_valid, t_src)
        else:
            frames = empty_frames()
        # Keep what later frames may still look back at: latency plus a margin, and one tick before.
        keep_from = np.searchsorted(hist_t, hist_t[-1] - self._latency_s - 1.0) - 1
        keep_from = max(keep_from, 0)
        self._hist_t = hist_t[keep_from:]
        self._hist_state = hist_state[keep_from:]
        return frames
