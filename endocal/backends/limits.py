"""Limits every backend checks on every chunk of goals, before anything moves.

Knob angle, speed and acceleration limits come from the probe configuration
(:class:`endocal.probe.ProbeConfig`: ``knob_limits_deg``, ``max_knob_speed_dps``,
``max_knob_accel_dps2``), translation and rotation ranges too; the hardware backend narrows
them further by the rig's configuration. The same check runs whatever produced the goals: a
protocol, inverse kinematics, an inverse hysteresis model, a user's script.
"""

from __future__ import annotations

import numpy as np

from endocal.errors import LimitError, ProtocolError
from endocal.probe import ProbeConfig


def probe_accel_limits(probe: ProbeConfig) -> dict[str, float]:
    """The knobs' acceleration limit, deg/s^2, per bending axis."""
    return {a: probe.max_knob_accel_dps2 for a in probe.bending_axes}


class GoalChecker:
    """Checks consecutive chunks of goals against a probe's limits, carrying the last tick over.

    Parameters
    ----------
    probe : ProbeConfig
    """

    def __init__(self, probe: ProbeConfig) -> None:
        self.limits = {d: tuple(probe.limits(d)) for d in probe.dofs}
        self.max_speed = {d: (probe.max_knob_speed_dps if d in probe.bending_axes else float("inf")) for d in probe.dofs}
        self.max_accel = probe_accel_limits(probe)
        self.units = {d: probe.unit(d) for d in probe.dofs}
        self.previous: tuple | None = None

    def check(self, t_s: np.ndarray, goal: dict[str, np.ndarray]) -> None:
        """Refuse the chunk if it breaks a limit (see :func:`check_goals`); else remember its end."""
        t = np.asarray(t_s, float)
        goals = {d: np.asarray(goal[d], float) for d in self.limits if d in goal}
        check_goals(t, goals, self.limits, self.max_speed, self.units, self.previous, self.max_accel)
        if t.size:
            speeds = {}
            for d, g in goals.items():
                if g.size > 1:
                    speeds[d] = float((g[-1] - g[-2]) / (t[-1] - t[-2]))
                elif self.previous is not None:
                    speeds[d] = float((g[-1] - self.previous[1][d]) / (t[-1] - self.previous[0]))
                else:
                    speeds[d] = 0.0
            self.previous = (float(t[-1]), {d: float(g[-1]) for d, g in goals.items()}, speeds)


def check_goals(
    t_s: np.ndarray,
    goal: dict[str, np.ndarray],
    limits: dict[str, tuple[float, float]],
    max_speed: dict[str, float],
    units: dict[str, str],
    previous: tuple | None = None,
    max_accel: dict[str, float] | None = None,
    refused: str = "the chunk was refused before any of it moved",
) -> None:
    """Refuse a chunk of goals that leaves a limit or moves too fast, before anything moves.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Tick times in s, strictly increasing.
    goal : dict
        DoF -> goals, shape (n,), in the DoF's unit.
    limits : dict
        DoF -> ``(min, max)``.
    max_speed : dict
        DoF -> fastest allowed ``|d goal / dt|`` in unit/s.
    units : dict
        DoF -> unit name for messages (``deg``, ``mm``).
    previous : tuple, optional
        ``(t_s, {dof: goal})`` of the last goal already sent, so the step into this chunk
        is checked too; a third element ``{dof: speed}`` (unit/s, the speed of that last
        step) lets the acceleration into this chunk be checked as well.
    max_accel : dict, optional
        DoF -> largest allowed ``|d speed / dt|`` in unit/s^2 (DoFs not in it: unchecked).
    refused : str
        What the messages say was refused (a chunk; a whole run, before the rig is opened).

    Raises
    ------
    LimitError
        Naming the DoF, the time, the value and the limit of the first violation.
    ProtocolError
        Non-finite or non-increasing times, non-finite goals.
    """
    t = np.asarray(t_s, dtype=float)
    if t.ndim != 1 or not np.isfinite(t).all():
        raise ProtocolError("chunk times t_s must be a finite 1-D array")
    if t.size > 1 and not (np.diff(t) > 0).all():
        k = int(np.argmin(np.diff(t) > 0)) + 1
        raise ProtocolError(f"chunk times must increase strictly; t_s[{k}] = {t[k]:.6f} s follows {t[k - 1]:.6f} s")
    if previous is not None and t.size and not t[0] > previous[0]:
        raise ProtocolError(f"chunk starts at t = {t[0]:.6f} s, not after the previous chunk's last tick {previous[0]:.6f} s")
    for dof, g in goal.items():
        u = units[dof]
        g = np.asarray(g, dtype=float)
        bad = ~np.isfinite(g)
        if bad.any():
            k = int(np.argmax(bad))
            raise ProtocolError(f"goal for '{dof}' at t = {t[k]:.3f} s is {g[k]} (not a number); {refused}")
        lo, hi = limits[dof]
        out = (g < lo) | (g > hi)
        if out.any():
            k = int(np.argmax(out))
            lim = lo if g[k] < lo else hi
            raise LimitError(
                f"goal for '{dof}' at t = {t[k]:.3f} s is {g[k]:.3f} {u}, beyond its limit {lim:.3f} {u} "
                f"(allowed {lo:g}..{hi:g} {u}); {refused}"
            )
        tt, gg = t, g
        if previous is not None:
            tt = np.concatenate(([previous[0]], t))
            gg = np.concatenate(([previous[1][dof]], g))
        if tt.size > 1:
            speed = np.abs(np.diff(gg)) / np.diff(tt)
            fast = speed > max_speed[dof] * (1.0 + 1e-9)
            if fast.any():
                k = int(np.argmax(fast))
                raise LimitError(
                    f"goal for '{dof}' at t = {tt[k + 1]:.3f} s moves at {speed[k]:.1f} {u}/s "
                    f"(from {gg[k]:.3f} to {gg[k + 1]:.3f} {u}), faster than the limit {max_speed[dof]:g} {u}/s; "
                    f"{refused}"
                )
            a_max = (max_accel or {}).get(dof)
            if a_max is not None:
                v = np.diff(gg) / np.diff(tt)
                tv = tt[1:]
                if previous is not None and len(previous) > 2 and dof in previous[2]:
                    v = np.concatenate(([previous[2][dof]], v))
                    tv = np.concatenate(([previous[0]], tv))
                if v.size > 1:
                    acc = np.abs(np.diff(v)) / np.diff(tv)
                    hard = acc > a_max * (1.0 + 1e-9)
                    if hard.any():
                        k = int(np.argmax(hard))
                        raise LimitError(
                            f"goal for '{dof}' at t = {tv[k + 1]:.3f} s changes speed from {v[k]:.1f} to {v[k + 1]:.1f} "
                            f"{u}/s in one tick: {acc[k]:.0f} {u}/s^2, above the limit {a_max:g} {u}/s^2; "
                            f"{refused}"
                        )
