"""A trajectory: goals of every degree of freedom of a probe on the motor clock, and its limit checks."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from endocal.errors import LimitError, ProtocolError
from endocal.probe import ProbeConfig

#: Most samples one trajectory may hold: a day of recording at about 230 Hz.
MAX_SAMPLES = 20_000_000


def check_samples(duration_s: float, sample_rate_hz: float, what: str, check: str) -> None:
    """Refuse a trajectory of more than :data:`MAX_SAMPLES` samples before any of them is made.

    A duration, speed or rate changed by a factor by mistake would otherwise fill the memory before
    anything else is checked. ``what`` names the trajectory (``protocol 'chirp'``), ``check`` what
    to look at.

    Raises
    ------
    ProtocolError
        One line: the duration, the rate, the cap, and ``check``.
    """
    n_f = duration_s * sample_rate_hz
    if not (math.isfinite(n_f) and n_f < MAX_SAMPLES):
        raise ProtocolError(f"{what}: {duration_s:.4g} s at {sample_rate_hz:.4g} Hz is more than {MAX_SAMPLES:,} "
                            f"samples (a day at {MAX_SAMPLES / 86400:.0f} Hz); check {check}")


@dataclass(frozen=True)
class Segment:
    """A labelled stretch of a trajectory (one sine block, one sweep, ...).

    ``dofs`` are the degrees of freedom that move in it; times in s on the motor clock.
    """

    label: str
    dofs: tuple[str, ...]
    start_s: float
    stop_s: float


@dataclass
class Trajectory:
    """Goals of every degree of freedom of a probe on the motor clock.

    Attributes
    ----------
    t_s : (n,) array
        ``0, 1/fs, 2/fs, ...`` s.
    goal : dict of str to (n,) array
        One entry per DoF of the probe, in its unit (deg for knobs and rotation, mm for
        translation); DoFs the protocol does not drive hold at 0.
    sample_rate_hz : float
        ``fs``, the motor clock.
    protocol : str
        Name of the protocol it came from (for messages).
    segments : tuple of Segment
        What happens when, e.g. each sweep of ``planes``.
    desired : dict of str to (n,) array
        Bending angles the user asked for (deg), for axes whose ``goal`` is no longer the
        protocol's own but a compensated knob command (orthogonal compensation, inverse
        hysteresis models); empty otherwise. Logged as ``<axis>_desired_deg``.
    tip_desired_mm : (n, 3) array or None
        Desired tip position in the base_home frame (see :mod:`endocal.protocols.paths`), mm,
        for trajectories that walk a tip path; logged as ``tip_desired_{x,y,z}_mm``.
    conditions : dict of str to float
        Conditions of the rig the user set for this run (the protocol's ``[conditions]``),
        logged as constant columns of those names where the backend does not log them itself.
    """

    t_s: np.ndarray
    goal: dict[str, np.ndarray]
    sample_rate_hz: float
    protocol: str = ""
    segments: tuple[Segment, ...] = ()
    desired: dict[str, np.ndarray] = field(default_factory=dict)
    tip_desired_mm: np.ndarray | None = None
    conditions: dict[str, float] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        """Time of the last sample, s."""
        return float(self.t_s[-1]) if self.t_s.size else 0.0

    @property
    def n_samples(self) -> int:
        return int(self.t_s.size)

    @property
    def moving_dofs(self) -> tuple[str, ...]:
        """DoFs whose goal is not identically zero, in probe order."""
        return tuple(d for d, g in self.goal.items() if np.any(g != 0.0))

    def goal_array(self, dofs: tuple[str, ...] | list[str] | None = None) -> np.ndarray:
        """Goals as one ``(n_samples, n_dofs)`` array, columns in the order of ``dofs`` (default: all)."""
        dofs = list(self.goal) if dofs is None else list(dofs)
        return np.column_stack([self.goal[d] for d in dofs]) if dofs else np.empty((self.n_samples, 0))

    def speed_per_s(self, dof: str) -> np.ndarray:
        """Goal speed between consecutive samples, unit/s, shape ``(n - 1,)`` (what a servo must follow)."""
        return np.diff(self.goal[dof]) * self.sample_rate_hz

    def check_limits(self, probe: ProbeConfig) -> None:
        """Refuse a trajectory the probe cannot play.

        Parameters
        ----------
        probe : ProbeConfig
            Its ``limits(dof)`` bound every goal; ``max_knob_speed_dps`` bounds the speed of
            each bending knob between consecutive samples, ``max_knob_accel_dps2`` the change
            of that speed.

        Raises
        ------
        LimitError
            Naming the DoF, the sample time and value, and the limit broken.
        """
        name = f"protocol '{self.protocol}'" if self.protocol else "trajectory"
        missing = [d for d in probe.dofs if d not in self.goal]
        if missing:
            raise LimitError(
                f"{name} has no goal for {', '.join(missing)} of probe '{probe.name}': build it with this probe"
            )
        for dof in probe.dofs:
            g = self.goal[dof]
            unit = probe.unit(dof)
            if not np.all(np.isfinite(g)):
                i = int(np.flatnonzero(~np.isfinite(g))[0])
                raise LimitError(f"{name}: {dof} goal is not finite at t = {self.t_s[i]:.3f} s")
            lo, hi = probe.limits(dof)
            tol = 1e-9 * max(1.0, abs(lo), abs(hi))
            over = np.flatnonzero((g > hi + tol) | (g < lo - tol))
            if over.size:
                i = int(over[0])
                side, lim = ("max", hi) if g[i] > hi else ("min", lo)
                worst = float(g.max()) if side == "max" else float(g.min())
                raise LimitError(
                    f"{name}: {dof} goal {g[i]:.3f} {unit} at t = {self.t_s[i]:.3f} s is beyond the {side} limit "
                    f"{lim:g} {unit} of probe '{probe.name}' (the goal reaches {worst:.3f} {unit}): "
                    "lower amplitude_deg or offset_deg"
                )
        if self.n_samples < 2:
            return
        for dof in probe.bending_axes:
            v = np.abs(self.speed_per_s(dof))
            fast = np.flatnonzero(v > probe.max_knob_speed_dps * (1 + 1e-9))
            if fast.size:
                i = int(fast[0])
                raise LimitError(
                    f"{name}: {dof} knob speed {v[i]:.1f} deg/s at t = {self.t_s[i + 1]:.3f} s exceeds the "
                    f"max_knob_speed_dps {probe.max_knob_speed_dps:g} deg/s of probe '{probe.name}' "
                    f"(peak {v.max():.1f} deg/s): lower the amplitude or the frequency/rate"
                )
            signed = self.speed_per_s(dof)
            if signed.size > 1:
                acc = np.abs(np.diff(signed)) / np.diff(self.t_s[1:])
                hard = np.flatnonzero(acc > probe.max_knob_accel_dps2 * (1 + 1e-9))
                if hard.size:
                    i = int(hard[0])
                    raise LimitError(
                        f"{name}: {dof} knob speed changes from {signed[i]:.1f} to {signed[i + 1]:.1f} deg/s at "
                        f"t = {self.t_s[i + 1]:.3f} s: {acc[i]:.0f} deg/s^2 exceeds the max_knob_accel_dps2 "
                        f"{probe.max_knob_accel_dps2:g} deg/s^2 of probe '{probe.name}': smooth the start or the reversals"
                    )

