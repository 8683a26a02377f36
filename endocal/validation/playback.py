"""Feedforward compensation on a backend: play desired angles through the inverse model.

This is the thesis's first experiment and the duodenoscope paper's fig. 9b: a protocol now
describes *desired bending angles* of one axis; the inverse hysteresis model (after the
orthogonal compensator, when bending planes are given) turns them into knob commands; the
backend plays them; the tracker measures what the tip reached. The same protocol is also
played *uncompensated* (knob command = desired angle, what a robot without a model does),
so the gain is measured in the same run.

The error is ``reached - desired`` per sample (thesis eq. 2), summarised by
:func:`endocal.validation.metrics.error_metrics`.
"""

from __future__ import annotations

import contextlib
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from endocal.errors import ModelError
from endocal.excite import run_excitation
from endocal.models.base import HysteresisModel
from endocal.planes.from_runs import compensate_trajectory
from endocal.probe import ProbeConfig
from endocal.protocols import Protocol, Trajectory
from endocal.runs.aligned import load_aligned
from endocal.validation.metrics import ErrorMetrics, error_metrics


@dataclass
class PlaybackResult:
    """Desired vs reached angles of one axis, compensated and not.

    Attributes
    ----------
    axis : str
    protocol : str
    metrics, uncompensated : ErrorMetrics
        Error of the compensated and of the uncompensated playback.
    t_s, desired_deg, reached_deg, uncompensated_deg, command_deg : (n,) arrays
        On the compensated run's aligned clock (the uncompensated reach is interpolated
        onto it).
    runs : dict
        ``{"compensated": Path, "uncompensated": Path}`` of the played runs (empty when they
        were played into a temporary folder, removed after reading).
    events : dict
        ``{"compensated": [...], "uncompensated": [...]}``: each run's events (run.json), e.g.
        the force guard's stops.
    """

    axis: str
    protocol: str
    metrics: ErrorMetrics
    uncompensated: ErrorMetrics
    t_s: np.ndarray
    desired_deg: np.ndarray
    reached_deg: np.ndarray
    uncompensated_deg: np.ndarray
    command_deg: np.ndarray
    runs: dict = field(default_factory=dict)
    events: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {
            "axis": self.axis,
            "protocol": self.protocol,
            "metrics": self.metrics.to_dict(),
            "uncompensated": self.uncompensated.to_dict(),
            "improvement_pct": 100.0 * (1 - self.metrics.rmse_deg / self.uncompensated.rmse_deg)
            if self.uncompensated.rmse_deg > 0
            else 0.0,
            "runs": {k: str(v) for k, v in self.runs.items()},
            "events": self.events,
        }


#: Seconds of smooth ramp from rest to the first command, played before the protocol starts.
PREROLL_S = 2.0


def _with_goals(traj: Trajectory, new_goals: dict, preroll_s: float = PREROLL_S) -> Trajectory:
    """A copy of ``traj`` whose DoFs in ``new_goals`` follow them, after a pre-roll of ``preroll_s``.

    The inverse model's first command is generally not zero (the dead band and the initial
    loading of eq. 11 put it elsewhere); a probe at rest cannot jump there, so it is reached
    by a raised-cosine ramp before the protocol's ``t = 0``. Every other DoF holds its first
    value during the pre-roll. The protocol's samples are shifted by ``preroll_s``.
    """
    from dataclasses import replace

    fs = traj.sample_rate_hz
    n_pre = int(round(preroll_s * fs))
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(n_pre) / n_pre)
    goals = {}
    for d, g in traj.goal.items():
        g = np.asarray(new_goals.get(d, g), float)
        goals[d] = np.concatenate([g[0] * ramp, g])
    # what was asked for: the protocol's angles, held at their first value during the pre-roll
    asked = traj.desired or {d: traj.goal[d] for d in new_goals}
    desired = {d: np.concatenate([np.full(n_pre, float(g[0])), g]) for d, g in asked.items()}
    tip = traj.tip_desired_mm
    if tip is not None:
        tip = np.vstack([np.repeat(tip[:1], n_pre, axis=0), tip])
    t = np.concatenate([np.arange(n_pre) / fs, traj.t_s + n_pre / fs])
    segments = tuple(replace(s, start_s=s.start_s + n_pre / fs, stop_s=s.stop_s + n_pre / fs) for s in traj.segments)
    return replace(traj, t_s=t, goal=goals, desired=desired, segments=segments, tip_desired_mm=tip)


def slew_limit(cmd_deg: np.ndarray, t_s: np.ndarray, max_speed_dps: float, max_accel_dps2: float | None = None) -> np.ndarray:
    """Follow ``cmd_deg`` as closely as a knob limited to ``max_speed_dps`` (and ``max_accel_dps2``) can.

    Inverting backlash asks for a jump of the knob across the dead band at every reversal
    (the inverse of a flat branch is a step); no motor can jump, so the command is taken
    across as fast as the knob may go: accelerating at ``max_accel_dps2`` up to
    ``max_speed_dps`` and braking so as to arrive without overshoot (in discrete time: the
    speed from which ``m`` ticks of braking cover a gap ``e``, ``a h^2 m (m + 1) / 2 = |e|``).
    A slow command the knob can follow is returned unchanged (braking assumes the command
    stops, so one moving faster than about ``a h`` is followed with a little lag); the played
    command stays inside the limits that are checked before motion.
    """
    cmd = np.asarray(cmd_deg, float)
    out = cmd.copy()
    dt = np.diff(t_s)
    v = 0.0
    for i in range(1, out.size):
        h = dt[i - 1]
        e = cmd[i] - out[i - 1]
        reach = min(abs(e) / h, max_speed_dps)
        if max_accel_dps2 is not None:  # fastest speed from which braking at a, tick by tick, stops within |e|
            ah = max_accel_dps2 * h
            m = np.floor((np.sqrt(1.0 + 8.0 * abs(e) / (ah * h)) - 1.0) / 2.0)  # whole braking ticks that fit
            rest = abs(e) - ah * h * m * (m + 1) / 2.0
            reach = min(reach, ah * m + rest / ((m + 1) * h))
        want = np.sign(e) * reach
        if max_accel_dps2 is not None:
            want = min(max(want, v - max_accel_dps2 * h), v + max_accel_dps2 * h)
        out[i] = cmd[i] if want == e / h else out[i - 1] + want * h  # exact where it follows
        v = want
    return out


def task_space_trajectory(traj: Trajectory, probe: ProbeConfig, models: dict, planes=None) -> Trajectory:
    """Knob goals that make the tip follow ``traj``'s goals read as desired bending angles.

    Task Space Control as in the thesis (fig. 5): desired standard-plane angles go through
    the orthogonal compensator (duodenoscope eqs. 3-4) when ``planes`` is given, then each
    axis with a model in ``models`` (axis name -> fitted model) through its inverse
    hysteresis model; axes without a model keep the (compensated) angle as the knob goal.
    A pre-roll of :data:`PREROLL_S` brings the knobs from rest to the first command.

    Raises
    ------
    ModelError
        A model for an axis the probe does not have, of a linear drive (its commands in mm, the
        probe's knobs in deg), or none for an axis the protocol moves.
    """
    for axis, model in models.items():
        if axis not in probe.bending_axes:
            raise ModelError(f"a model is for axis {axis!r}, but probe '{probe.name}' has {', '.join(probe.bending_axes)}")
        if model.drive_unit_ != "deg":
            raise ModelError(f"the {axis} model was fitted on a drive commanded in {model.drive_unit_} (a linear stage "
                             f"pulling the tendon), but the knobs of probe '{probe.name}' that a protocol plays are "
                             "commanded in deg: such a model is held against records offline (validate DATA, report), "
                             "not played")
    moving = [a for a in probe.bending_axes if a in traj.moving_dofs]
    if moving and not set(models) & set(moving):
        raise ModelError(f"the model(s) are for axis {', '.join(repr(a) for a in models)}, but this protocol moves "
                         f"{', '.join(moving)}: give the model of a moving axis, or move this one "
                         f"(excite --axes {next(iter(models))})")
    if planes is not None:
        traj = compensate_trajectory(traj, probe, planes)
    first, second = probe.bending_axes
    goals = {}
    for axis, model in models.items():
        other = second if axis == first else first
        cmd = np.asarray(model.inverse(traj.goal[axis], t_s=traj.t_s, extras={"other_cmd_deg": traj.goal[other]}), float)
        # 0.99: stay strictly inside the speed and acceleration limits that check_limits enforces.
        goals[axis] = slew_limit(cmd, traj.t_s, 0.99 * probe.max_knob_speed_dps, 0.99 * probe.max_knob_accel_dps2)
    return _with_goals(traj, goals)


def validate_on_backend(
    model: HysteresisModel,
    protocol: Protocol,
    backend_factory,
    probe: ProbeConfig,
    *,
    planes=None,
    seed: int = 0,
    out_dir: Path | None = None,
    progress=None,
    guard_factory=None,
) -> PlaybackResult:
    """Play ``protocol`` as desired angles of the model's axis, compensated and uncompensated.

    Parameters
    ----------
    model : HysteresisModel
        A fitted model of one axis (``model.axis`` names it).
    protocol : Protocol
        Its goal on the model's axis is read as the desired bending angle, degrees.
    backend_factory : callable
        ``backend_factory() -> Backend``; called once per playback so each run starts
        from rest (the simulator's state, the rig's homing).
    probe : ProbeConfig
    planes : PlanesCalibration, optional
        Orthogonal compensator applied before the hysteresis inverse.
    seed : int
        Seed of the protocol and backend.
    out_dir : Path, optional
        Where the two runs are kept (``compensated/``, ``uncompensated/``); when omitted they
        are played into a temporary folder, removed once read.
    guard_factory : callable, optional
        ``guard_factory() -> ForceGuard``: a fresh contact-force guard for each playback.

    Raises
    ------
    ModelError
        The model has no axis, or an axis the probe lacks.
    LimitError
        The compensated commands leave the knob limits (before anything moves).
    """
    axis = model.axis
    if axis not in probe.bending_axes:
        raise ModelError(
            f"the model is for axis {axis!r}, but probe '{probe.name}' has {', '.join(probe.bending_axes)}: "
            "use --probe to pick the probe the model was fitted on"
        )
    proto = protocol.with_overrides({"axes": [axis]}) if "axes" in protocol.params else protocol
    desired_traj = proto.trajectory(probe, seed=seed)
    comp_traj = task_space_trajectory(desired_traj, probe, {axis: model}, planes)
    command = comp_traj.goal[axis][comp_traj.t_s >= PREROLL_S - 1e-9]  # the protocol's samples, after the pre-roll
    uncomp_traj = _with_goals(desired_traj, {})
    comp_traj.check_limits(probe)  # both refused before anything moves
    uncomp_traj.check_limits(probe)

    with contextlib.ExitStack() as scratch:
        root = Path(out_dir) if out_dir is not None else Path(
            scratch.enter_context(tempfile.TemporaryDirectory(prefix="endocal-validate-")))
        runs = {"compensated": root / "compensated", "uncompensated": root / "uncompensated"}
        reached, events = {}, {}
        for name, traj in (("compensated", comp_traj), ("uncompensated", uncomp_traj)):
            run_excitation(
                traj,
                backend_factory(),
                probe,
                runs[name],
                protocol_info={**proto.to_dict(), "playback": name, "model_axis": axis},
                seed=seed,
                force=True,
                progress=progress,
                guard=guard_factory() if guard_factory is not None else None,
            )
            data = load_aligned(runs[name])
            keep = data.t_s >= PREROLL_S - 1e-9  # metrics over the protocol only, on its own clock
            reached[name] = (data.t_s[keep] - PREROLL_S, data.meas_deg(axis)[keep])
            events[name] = data.meta.get("events", [])

    t, reach = reached["compensated"]
    desired = np.interp(t, desired_traj.t_s, desired_traj.goal[axis])
    reach_uncomp = np.interp(t, *reached["uncompensated"])
    cmd = np.interp(t, desired_traj.t_s, command)
    return PlaybackResult(
        axis=axis,
        protocol=proto.name,
        metrics=error_metrics(desired, reach, seed=seed),
        uncompensated=error_metrics(desired, reach_uncomp, seed=seed),
        t_s=t,
        desired_deg=desired,
        reached_deg=reach,
        uncompensated_deg=reach_uncomp,
        command_deg=cmd,
        runs=runs if out_dir is not None else {},
        events=events,
    )
