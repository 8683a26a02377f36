"""Play an excitation protocol on a backend and log it as a run folder.

Everything that can be checked is checked before the output folder is created or any
motor moves: the protocol, its overrides, the probe, the backend configuration, and every
goal against the probe's limits. Then the run is logged chunk by chunk (see
:mod:`endocal.runs.logger`); whatever happens next (normal end, Ctrl-C, a device failure)
the backend is closed, which on hardware turns torque off, everything already logged is
flushed, and ``run.json`` records how the run ended.
"""

from __future__ import annotations

import functools
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from endocal.backends.base import Backend
from endocal.errors import ConfigError, HardwareError, OutputPathError, StopSignal
from endocal.probe import ProbeConfig
from endocal.runs.format import (
    MOTOR,
    RUN_JSON,
    TRACKER,
    create_run_folder,
    prepare_output,
    run_meta,
    utc_now,
    write_json,
)
from endocal.runs.logger import StreamLogger, finish_run

if TYPE_CHECKING:
    from endocal.protocols import Trajectory

#: Run time per chunk: long chunks keep a fast backend fast; short ones keep realtime pacing tight.
FAST_CHUNK_S = 30.0
REALTIME_CHUNK_S = 0.1


@dataclass
class ExciteResult:
    """What :func:`run_excitation` produced."""

    run_dir: Path
    status: str  # "complete" or "interrupted"
    logged_s: float
    planned_s: float
    motor_rows: int
    tracker_rows: int
    aligned_rows: int
    wall_s: float
    alignment_error: str | None = None
    events: list = field(default_factory=list)

    @property
    def speed_x_realtime(self) -> float:
        return self.logged_s / self.wall_s if self.wall_s > 0 else float("inf")


def _ctrl_c_stops_the_run(func):
    """Make SIGINT (Ctrl-C, ``kill -INT``) stop the run even in a process started with it ignored.

    A shell script's background job (``endocal excite ... &``), and some launchers, start the
    process with SIGINT ignored, and Python then leaves it ignored: the robot would keep moving
    on Ctrl-C. For the run, SIGINT raises ``KeyboardInterrupt`` as usual (torque off, the run
    kept, status ``interrupted``); the ignored disposition is restored afterwards.
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        ignored = (threading.current_thread() is threading.main_thread()
                   and signal.getsignal(signal.SIGINT) is signal.SIG_IGN)
        if not ignored:
            return func(*args, **kwargs)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        try:
            return func(*args, **kwargs)
        finally:
            signal.signal(signal.SIGINT, signal.SIG_IGN)

    return wrapper


@_ctrl_c_stops_the_run
def run_excitation(
    trajectory: Trajectory,
    backend: Backend,
    probe: ProbeConfig,
    out: Path,
    *,
    protocol_info: dict,
    seed: int,
    realtime: bool = False,
    force: bool = False,
    command: str | None = None,
    progress: Callable[[float, float], None] | None = None,
    flush_interval_s: float = 1.0,
    guard=None,
) -> ExciteResult:
    """Play ``trajectory`` on ``backend`` and log the run to ``out``.

    Parameters
    ----------
    trajectory : Trajectory
        Goals for every DoF of ``probe`` on the motor clock (already limit-checked by the caller
        or here).
    backend : Backend
        Simulator or hardware; opened and always closed here.
    probe : ProbeConfig
    out : Path
        Run folder to create.
    protocol_info : dict
        Protocol name, parameters, source and hash, recorded in ``run.json``.
    seed : int
        Seed given to the backend, recorded.
    realtime : bool
        Pace a non-realtime backend (the simulator) to the wall clock.
    force : bool
        Replace an existing ``out``.
    progress : callable, optional
        Called as ``progress(done_s, total_s)`` after each chunk.
    guard : ForceGuard, optional
        Contact-force guard (:class:`endocal.force.guard.ForceGuard`) the backend steps at
        every tick; its stops and releases are the run's ``events`` in ``run.json``.

    Returns
    -------
    ExciteResult
        ``status`` is ``interrupted`` when Ctrl-C stopped the run (the run is still valid);
        ``events`` lists the guard's stops and releases.

    Raises
    ------
    LimitError, OutputExistsError, OutputPathError
        Before anything moves or is written (a backend with a ``check_plan`` method, the
        hardware's, checks the whole run against its own limits here too).
    StopSignal
        SIGTERM or SIGHUP stopped a hardware run: torque is off, the run is kept with status
        ``interrupted`` and ``stopped_by`` naming the signal in ``run.json``.
    """
    out = Path(out)
    trajectory.check_limits(probe)  # refuse before anything moves
    check_plan = getattr(backend, "check_plan", None)
    if check_plan is not None:  # a rig's own limits (tighter than the probe's), before it is opened
        check_plan(trajectory.t_s, trajectory.goal)
    if guard is not None:
        if not hasattr(backend, "attach_guard"):
            raise ConfigError(f"backend '{backend.name}' has no per-tick hook for a force guard")
        if guard.axis not in trajectory.moving_dofs:
            raise ConfigError(f"the force model is for axis '{guard.axis}', but this protocol moves "
                              f"{', '.join(trajectory.moving_dofs) or 'nothing'}: use a model of a driven axis")
        backend.attach_guard(guard)
    prepare_output(out, force)
    meta = run_meta(protocol=protocol_info, probe=probe, backend={"name": backend.name}, seed=seed,
                    realtime=realtime or backend.realtime, command=command,
                    sample_rate_hz=trajectory.sample_rate_hz, planned_duration_s=trajectory.duration_s)
    # Connect first: a rig that fails to open leaves no run folder behind.
    try:
        backend.open()
    except BaseException:
        backend.close()
        raise
    try:
        create_run_folder(out)
    except OutputPathError:
        backend.close()
        raise

    logger = StreamLogger(out, flush_interval_s=flush_interval_s)
    status, error = "running", None
    wall0 = time.monotonic()
    try:
        meta["backend"] = {"name": backend.name, **backend.describe()}
        meta["started_utc"] = utc_now()
        write_json(out / RUN_JSON, meta)
        chunk_s = REALTIME_CHUNK_S if (realtime or backend.realtime) else FAST_CHUNK_S
        n_chunk = max(1, int(round(chunk_s * trajectory.sample_rate_hz)))
        t = trajectory.t_s
        wall0 = time.monotonic()
        for start in range(0, t.size, n_chunk):
            sl = slice(start, start + n_chunk)
            if realtime and not backend.realtime:
                # Pace the simulator: a chunk is released when its first tick is due.
                delay = wall0 + t[sl.start] - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            chunk = backend.execute(t[sl], {dof: g[sl] for dof, g in trajectory.goal.items()})
            for axis, angle in trajectory.desired.items():  # what the compensated goals were meant to reach
                chunk.motor[f"{axis}_desired_deg"] = np.asarray(angle[sl], float)
            for name, value in getattr(trajectory, "conditions", {}).items():  # the user's condition; a backend's own wins
                if name not in chunk.motor:
                    chunk.motor[name] = np.full(len(chunk.motor["t_s"]), float(value))
            if getattr(trajectory, "tip_desired_mm", None) is not None:  # a tip path: where the tip should be (base_home, mm)
                for k, c in enumerate("xyz"):
                    chunk.motor[f"tip_desired_{c}_mm"] = np.asarray(trajectory.tip_desired_mm[sl, k], float)
            logger.append(chunk)
            if progress is not None:
                progress(float(t[min(sl.stop, t.size) - 1]), trajectory.duration_s)
        status = "complete"
    except KeyboardInterrupt:
        status = "interrupted"
    except StopSignal as exc:  # SIGTERM/SIGHUP on hardware: torque is already off, the run so far is kept
        status = "interrupted"
        meta["stopped_by"] = exc.signame
        raise
    except BaseException as exc:
        status, error = "failed", f"{type(exc).__name__}: {exc}"
        raise
    finally:
        try:
            _close_keeping_the_cause(backend)
        finally:
            timing = getattr(backend, "timing", None)  # a real-time loop's: set and achieved rate, overruns
            if timing is not None and "backend" in meta:
                meta["backend"]["timing"] = timing.describe()
            notes = getattr(backend, "close_notes", None)  # what closing could not do (a rig's unanswering device)
            if notes and "backend" in meta:
                meta["backend"]["close_notes"] = list(notes)
            if guard is not None:
                meta["force_guard"] = guard.describe()
                meta["events"] = list(guard.events)
            logger.flush()
            finish_run(out, meta, logger, status, error, time.monotonic() - wall0, probe)
    return ExciteResult(
        run_dir=out,
        status=status,
        logged_s=meta.get("logged_s", 0.0),
        planned_s=trajectory.duration_s,
        motor_rows=logger.rows_written[MOTOR],
        tracker_rows=logger.rows_written[TRACKER],
        aligned_rows=meta.get("counts", {}).get("aligned_rows", 0),
        wall_s=meta.get("wall_s", 0.0),
        alignment_error=meta.get("alignment_error"),
        events=list(meta.get("events", [])),
    )


def _close_keeping_the_cause(backend: Backend) -> None:
    """Close ``backend``; when closing fails while a failure is already on its way out (a bus
    that died mid-run cannot confirm torque off either), say both, the cause first."""
    import sys

    cause = sys.exc_info()[1]
    try:
        backend.close()
    except HardwareError as exc:
        if cause is None or isinstance(cause, KeyboardInterrupt):
            raise
        raise HardwareError(f"{cause}; then {exc}") from cause


def prepare_backend(backend: Backend, protocol, probe: ProbeConfig, *, tip_load_n: float | None = None):
    """Set a backend up for a protocol: its ``[sim]`` table and a known tip load.

    Parameters
    ----------
    backend : Backend
        As built from the command line.
    protocol : Protocol
        Its ``sim`` table (sim-config sections, e.g. an obstacle) is applied on the simulator.
    probe : ProbeConfig
    tip_load_n : float, optional
        A known force hung at the tip (N, >= 0), opposing bending of the protocol's first axis
        towards its positive half-plane (duodenoscope paper, sec. 2.4, calibration weights).
        On the simulator it is hung there ([contact] mode ``weight``); on any backend it is
        recorded for ``endocal fit force``.

    Returns
    -------
    backend : Backend
        The simulator with the settings applied, or ``backend`` unchanged.
    record : dict
        What ``run.json`` records under ``protocol`` (``tip_load``), possibly empty.

    Raises
    ------
    ConfigError
        A negative or non-finite load, a load together with a protocol obstacle, a bad ``[sim]``
        table, or a condition's value the simulator cannot take.

    Notes
    -----
    A condition of the protocol that the simulator models (:data:`endocal.sim.config.CONDITIONS`,
    e.g. ``sheath_wrap_deg``) sets that physics on the simulator, as turning the rig's insertion
    tube would; every backend logs each condition as a column (:func:`run_excitation`).
    """
    from endocal.sim.config import CONDITIONS

    sections = {k: dict(v) for k, v in (getattr(protocol, "sim", None) or {}).items()}
    record: dict = {}
    if hasattr(backend, "with_settings"):
        for name, value in (getattr(protocol, "condition_values", None) or {}).items():
            if name in CONDITIONS:
                section, key = CONDITIONS[name]
                sections.setdefault(section, {})[key] = value
                try:
                    backend.with_settings({section: {key: value}})
                except ConfigError as exc:
                    raise ConfigError(f"protocol '{protocol.name}': condition {name} = {value:g} on the simulator: "
                                      f"{exc}") from None
    if tip_load_n is not None:
        if not np.isfinite(tip_load_n) or tip_load_n < 0:
            raise ConfigError(f"--tip-load-n must be a force of 0 N or more, got {tip_load_n!r}")
        if "contact" in sections:
            raise ConfigError(f"protocol '{protocol.name}' sets up its own contact on the simulator; "
                              "--tip-load-n belongs to force-calibration runs")
        axis = protocol.resolved_axes(probe)[0]
        record["tip_load"] = {"force_n": float(tip_load_n), "axis": axis, "opposes": "+"}
        if tip_load_n > 0:
            sections["contact"] = {"enabled": True, "mode": "weight", "axis": axis, "weight_n": float(tip_load_n)}
    if sections and hasattr(backend, "with_settings"):
        try:
            backend = backend.with_settings(sections)
        except ConfigError as exc:
            raise ConfigError(f"protocol '{protocol.name}' [sim] table: {exc}") from None
    return backend, record
