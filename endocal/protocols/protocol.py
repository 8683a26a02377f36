"""Excitation protocols: load and validate a TOML file, apply overrides, build the trajectory.

A protocol file names a *signal* (the generator in :mod:`endocal.protocols.signals`) and
sets its parameters; every parameter has a default, so a file sets only what it changes.
The user overrides any parameter at load time; an override or file key naming a
parameter the signal does not have is an error, never silently ignored::

    description = "Damped sine of the duodenoscope paper"
    signal = "damped-sine"

    [params]
    axes = ["axis1"]
    amplitude_deg = 60.0

:meth:`Protocol.trajectory` turns the parameters into goals for every degree of freedom
of a probe on the motor clock (a :class:`Trajectory`); :meth:`Trajectory.check_limits`
refuses goals beyond the probe's limits or faster than its knobs, before anything moves.
The schema is documented in ``protocols/README.md``.
"""

from __future__ import annotations

import hashlib
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

import endocal
from endocal.errors import ConfigError, LimitError, ProtocolError
from endocal.probe import ROTATION, TRANSLATION, ProbeConfig
from endocal.protocols import signals

#: Samples per second of the motor clock unless a protocol says otherwise.
DEFAULT_SAMPLE_RATE_HZ = 100.0

# Top-level keys of a protocol file.
_FILE_KEYS = ("description", "signal", "params", "sim")


# --------------------------------------------------------------------------- parameters


@dataclass(frozen=True)
class Param:
    """One protocol parameter: name (with its unit), default, type and range.

    ``kind`` is ``float``, ``int``, ``floats`` (a list of numbers), ``axes`` (a list of
    axis names), ``choice`` (one of ``choices``) or ``seed`` (an int >= 0, or unset).
    ``lo`` bounds numbers from below (``lo_open``: strictly); ``length`` fixes a list length.
    """

    name: str
    default: Any
    kind: str
    doc: str
    lo: float | None = None
    lo_open: bool = False
    length: int | None = None
    choices: tuple[str, ...] = ()

    def coerce(self, value: Any, where: str) -> Any:
        """Check ``value`` and return it normalised (floats as float, lists as lists).

        Raises
        ------
        ProtocolError
            Naming the parameter, ``where`` it was set, and what it must be.
        """

        def bad(what: str) -> ProtocolError:
            return ProtocolError(f"{where}: parameter '{self.name}' must be {what}, got {value!r}")

        def number(x: Any, what: str) -> float:
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                raise bad(what)
            if self.lo is not None and (x <= self.lo if self.lo_open else x < self.lo):
                raise bad(what)
            return float(x)

        bound = "" if self.lo is None else (f" > {self.lo:g}" if self.lo_open else f" >= {self.lo:g}")
        if self.kind == "float":
            return number(value, f"a number{bound}")
        if self.kind == "int":
            if isinstance(value, bool) or not isinstance(value, int):
                raise bad(f"an integer{bound}")
            number(value, f"an integer{bound}")
            return int(value)
        if self.kind == "seed":
            if value is None:
                return None
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise bad("an integer >= 0")
            return int(value)
        if self.kind == "choice":
            if value not in self.choices:
                raise bad("one of " + ", ".join(repr(c) for c in self.choices))
            return str(value)
        if self.kind == "floats":
            n = f"{self.length} numbers" if self.length else "a non-empty list of numbers"
            if not isinstance(value, (list, tuple)) or not value or (self.length and len(value) != self.length):
                raise bad(f"{n}{bound}")
            return [number(x, f"{n}{bound}") for x in value]
        if self.kind == "axes":
            if isinstance(value, str):
                value = [value]
            n = f"a list of {self.length} axis names" if self.length else "a non-empty list of axis names"
            if (
                not isinstance(value, (list, tuple))
                or not value
                or not all(isinstance(a, str) and a for a in value)
                or (self.length and len(value) != self.length)
            ):
                raise bad(n + " (e.g. ['axis1', 'axis2'])")
            if len(set(value)) != len(value):
                raise bad("a list of different axes")
            return list(value)
        raise AssertionError(f"unknown parameter kind {self.kind!r}")  # a bug in the spec below, not user input


def _p(name, default, kind, doc, **kw) -> Param:
    return Param(name=name, default=default, kind=kind, doc=doc, **kw)


SAMPLE_RATE = _p("sample_rate_hz", DEFAULT_SAMPLE_RATE_HZ, "float", "Motor clock, samples per second.", lo=0, lo_open=True)
OFFSET = _p("offset_deg", 0.0, "float", "Level the signal oscillates about, deg; reached from 0 by a ramp of ramp_s.")
RAMP = _p("ramp_s", 2.0, "float", "Raised-cosine ramp from 0 to the offset and back, s.", lo=0)
REST = _p("rest_s", 2.0, "float", "Hold between consecutive blocks and axes, s.", lo=0)


def _axes(default: list[str], length: int | None = None, doc: str | None = None) -> Param:
    text = doc or "Axes driven, one after the other (the others hold at 0): names or axis1/axis2."
    return _p("axes", default, "axes", text, length=length)


def _amp(default: float, doc: str = "Peak of the signal about the offset, deg.") -> Param:
    return _p("amplitude_deg", default, "float", doc, lo=0, lo_open=True)


def _pos(name: str, default: float, doc: str) -> Param:
    return _p(name, default, "float", doc, lo=0, lo_open=True)


def _count(name: str, default: int, doc: str) -> Param:
    return _p(name, default, "int", doc, lo=1)


# --------------------------------------------------------------------------- trajectory


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
    """

    t_s: np.ndarray
    goal: dict[str, np.ndarray]
    sample_rate_hz: float
    protocol: str = ""
    segments: tuple[Segment, ...] = ()
    desired: dict[str, np.ndarray] = field(default_factory=dict)

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
            each bending knob between consecutive samples.

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


class _Timeline:
    """Places per-axis signal pieces one after another in time."""

    def __init__(self) -> None:
        self.now_s = 0.0
        self.pieces: list[tuple[str, float, float, Callable[[np.ndarray], np.ndarray]]] = []
        self.segments: list[Segment] = []

    def play(self, fns: dict[str, Callable[[np.ndarray], np.ndarray]], duration_s: float, label: str | None = None) -> None:
        """From now, for ``duration_s``: each axis in ``fns`` follows ``fn(time since now)``."""
        start, stop = self.now_s, self.now_s + duration_s
        for axis, fn in fns.items():
            self.pieces.append((axis, start, stop, fn))
        if label is not None:
            self.segments.append(Segment(label, tuple(fns), start, stop))
        self.now_s = stop

    def rest(self, duration_s: float) -> None:
        """Everything at 0 for ``duration_s``."""
        self.now_s += duration_s

    def render(self, dofs: tuple[str, ...], sample_rate_hz: float, protocol: str) -> Trajectory:
        fs = sample_rate_hz
        n = int(math.ceil(self.now_s * fs - 1e-9)) + 1
        t_s = np.arange(n) / fs
        goal = {d: np.zeros(n) for d in dofs}
        for axis, start, stop, fn in self.pieces:
            # Closed interval: a later piece overwrites the shared boundary sample, where both agree.
            i0 = max(int(math.ceil(start * fs - 1e-9)), 0)
            i1 = min(int(math.floor(stop * fs + 1e-9)), n - 1)
            if i1 >= i0:
                goal[axis][i0 : i1 + 1] = fn(t_s[i0 : i1 + 1] - start)
        return Trajectory(t_s=t_s, goal=goal, sample_rate_hz=fs, protocol=protocol, segments=tuple(self.segments))


def _const(level: float) -> Callable[[np.ndarray], np.ndarray]:
    return lambda t: np.full(np.shape(t), float(level))


def _shifted(fn: Callable[[np.ndarray], np.ndarray], offset: float) -> Callable[[np.ndarray], np.ndarray]:
    return fn if offset == 0.0 else (lambda t: offset + fn(t))


def _each_axis(tl: _Timeline, p: dict, axes: list[str], body: Callable[[str, float], None]) -> None:
    """Drive ``axes`` one after the other: ramp to the offset, ``body(axis, offset)``, ramp back, rest."""
    offset, ramp_s = p.get("offset_deg", 0.0), p.get("ramp_s", 0.0)
    for i, axis in enumerate(axes):
        if i:
            tl.rest(p["rest_s"])
        if offset:
            tl.play({axis: lambda t, o=offset: signals.ramp(t, 0.0, o, ramp_s)}, ramp_s, f"{axis} to offset {offset:g} deg")
        body(axis, offset)
        if offset:
            tl.play({axis: lambda t, o=offset: signals.ramp(t, o, 0.0, ramp_s)}, ramp_s, f"{axis} back to 0")


# --------------------------------------------------------------------------- signals


@dataclass(frozen=True)
class SignalSpec:
    """A kind of excitation: its parameters, a cross-check, and how it fills a timeline."""

    name: str
    doc: str
    params: tuple[Param, ...]
    build: Callable[[_Timeline, dict, list[str], int], None]
    check: Callable[[dict], str | None] = lambda p: None

    def param(self, name: str) -> Param:
        return next(q for q in self.params if q.name == name)


def _nyquist(p: dict, *names: str) -> str | None:
    for name in names:
        values = p[name] if isinstance(p[name], list) else [p[name]]
        if max(values) >= p["sample_rate_hz"] / 2:
            return f"'{name}' {p[name]} must stay below half the sample rate ({p['sample_rate_hz'] / 2:g} Hz)"
    return None


def _offset_ramp(p: dict) -> str | None:
    if p.get("offset_deg", 0.0) != 0.0 and p.get("ramp_s", 0.0) <= 0:
        return "a non-zero 'offset_deg' needs 'ramp_s' > 0 to reach it without a jump"
    return None


def _checks(*fns: Callable[[dict], str | None]) -> Callable[[dict], str | None]:
    def check(p: dict) -> str | None:
        for fn in fns:
            msg = fn(p)
            if msg:
                return msg
        return None

    return check


# sine ------------------------------------------------------------------------------------------


def _build_sine(tl: _Timeline, p: dict, axes: list[str], seed: int) -> None:
    A, f, n = p["amplitude_deg"], p["frequency_hz"], p["cycles"]

    def body(axis, offset):
        fn = _shifted(lambda t: signals.sine(t, A, f), offset)
        tl.play({axis: fn}, n / f, f"{axis} sine {A:g} deg {f:g} Hz x{n}")

    _each_axis(tl, p, axes, body)


SINE = SignalSpec(
    "sine",
    "Plain sine A sin(2 pi f t), whole cycles, each axis in turn (the paper's 0.05 Hz accuracy test).",
    (_axes(["axis1"]), _amp(45.0), _pos("frequency_hz", 0.05, "Frequency, Hz."),
     _count("cycles", 3, "Whole periods per axis."), OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_sine,
    _checks(lambda p: _nyquist(p, "frequency_hz"), _offset_ramp),
)


# sine-set --------------------------------------------------------------------------------------


def _build_sine_set(tl: _Timeline, p: dict, axes: list[str], seed: int) -> None:
    n = p["cycles"]

    def body(axis, offset):
        first = True
        for A in p["amplitudes_deg"]:
            for T in p["periods_s"]:
                if not first:
                    tl.play({axis: _const(offset)}, p["rest_s"])
                first = False
                fn = _shifted(lambda t, A=A, T=T: signals.sine(t, A, 1.0 / T), offset)
                tl.play({axis: fn}, n * T, f"{axis} sine {A:g} deg period {T:g} s x{n}")

    _each_axis(tl, p, axes, body)


SINE_SET = SignalSpec(
    "sine-set",
    "Thesis calibration: sines at every period x amplitude, each axis in turn (the other holds at 0).",
    (_axes(["axis1", "axis2"]),
     _p("amplitudes_deg", [30.0, 60.0], "floats", "Amplitudes, deg; all periods are played at each.", lo=0, lo_open=True),
     _p("periods_s", [40.0, 20.0, 10.0, 5.0], "floats", "Periods, s, in playing order.", lo=0, lo_open=True),
     _count("cycles", 2, "Whole periods per (amplitude, period) block."), OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_sine_set,
    _checks(lambda p: None if 1.0 / min(p["periods_s"]) < p["sample_rate_hz"] / 2
            else f"'periods_s' must stay above two samples ({2 / p['sample_rate_hz']:g} s)", _offset_ramp),
)


# sine-varying ----------------------------------------------------------------------------------


def _build_sine_varying(tl: _Timeline, p: dict, axes: list[str], seed: int) -> None:
    A, fs_hz, n = p["amplitude_deg"], p["frequencies_hz"], p["cycles"]
    total = sum(n / f for f in fs_hz)

    def body(axis, offset):
        fn = _shifted(lambda t: signals.stepped_frequency_sine(t, A, fs_hz, n), offset)
        tl.play({axis: fn}, total, f"{axis} sine {A:g} deg at {', '.join(f'{f:g}' for f in fs_hz)} Hz x{n} each")

    _each_axis(tl, p, axes, body)


SINE_VARYING = SignalSpec(
    "sine-varying",
    "Thesis validation: one sine whose frequency changes every few whole periods, phase-continuous.",
    (_axes(["axis1", "axis2"]), _amp(45.0),
     _p("frequencies_hz", [0.04, 0.125], "floats", "Frequencies in playing order, Hz.", lo=0, lo_open=True),
     _count("cycles", 2, "Whole periods at each frequency."), OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_sine_varying,
    _checks(lambda p: _nyquist(p, "frequencies_hz"), _offset_ramp),
)


# damped-sine -----------------------------------------------------------------------------------


def _build_damped_sine(tl: _Timeline, p: dict, axes: list[str], seed: int) -> None:
    A, f, T = p["amplitude_deg"], p["frequency_hz"], p["period_s"]

    def body(axis, offset):
        fn = _shifted(lambda t: signals.damped_sine(t, A, f, T), offset)
        tl.play({axis: fn}, 7.0 * T, f"{axis} damped sine {A:g} deg {f:g} Hz T={T:g} s")

    _each_axis(tl, p, axes, body)


def _damped_ends_at_zero(p: dict) -> str | None:
    # The decay only reaches exp(-1) at 7T, so the sine itself must be at a zero crossing there.
    half_cycles = 14.0 * p["frequency_hz"] * p["period_s"]
    if abs(half_cycles - round(half_cycles)) > 1e-9:
        return (
            f"the damped sine ends at 7 * period_s = {7 * p['period_s']:g} s at exp(-1) of its amplitude, so "
            f"7 * period_s * frequency_hz must be a multiple of 0.5 to end at 0 (it is {half_cycles / 2:g})"
        )
    return None


DAMPED_SINE = SignalSpec(
    "damped-sine",
    "Duodenoscope paper identification input: A sin(2 pi f t) for 2T, then decaying as exp(-(t-2T)/(5T)) to 7T.",
    (_axes(["axis1"]), _amp(60.0, "A, peak of the undamped part, deg."),
     _pos("frequency_hz", 0.05, "f, Hz (paper: 0.05)."), _pos("period_s", 20.0, "T, s (paper: 20); lasts 7T."),
     OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_damped_sine,
    _checks(lambda p: _nyquist(p, "frequency_hz"), _damped_ends_at_zero, _offset_ramp),
)


# triangle --------------------------------------------------------------------------------------


def _build_triangle(tl: _Timeline, p: dict, axes: list[str], seed: int) -> None:
    A, T, n = p["amplitude_deg"], p["period_s"], p["cycles"]

    def body(axis, offset):
        fn = _shifted(lambda t: signals.triangle(t, A, T), offset)
        tl.play({axis: fn}, n * T, f"{axis} triangle {A:g} deg period {T:g} s x{n}")

    _each_axis(tl, p, axes, body)


TRIANGLE = SignalSpec(
    "triangle",
    "Triangle wave 0 -> +A -> -A -> 0, constant knob speed 4A/T between reversals.",
    (_axes(["axis1"]), _amp(45.0), _pos("period_s", 20.0, "Period, s."), _count("cycles", 3, "Whole periods."),
     OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_triangle,
    _checks(lambda p: None if p["period_s"] * p["sample_rate_hz"] >= 4
            else "'period_s' must hold at least 4 samples", _offset_ramp),
)


# chirp -----------------------------------------------------------------------------------------


def _build_chirp(tl: _Timeline, p: dict, axes: list[str], seed: int) -> None:
    A, f0, f1, D, method, fade = p["amplitude_deg"], p["f0_hz"], p["f1_hz"], p["duration_s"], p["method"], p["fade_s"]

    def body(axis, offset):
        fn = _shifted(lambda t: signals.chirp(t, A, f0, f1, D, method, fade), offset)
        tl.play({axis: fn}, D, f"{axis} {method} chirp {A:g} deg {f0:g}->{f1:g} Hz")

    _each_axis(tl, p, axes, body)


def _chirp_check(p: dict) -> str | None:
    if p["method"] == "log" and p["f0_hz"] <= 0:
        return "a logarithmic chirp needs 'f0_hz' > 0"
    if p["fade_s"] > p["duration_s"]:
        return "'fade_s' must not exceed 'duration_s'"
    return _nyquist(p, "f0_hz", "f1_hz")


CHIRP = SignalSpec(
    "chirp",
    "Swept sine from f0 to f1 (linear or logarithmic in frequency), faded out to 0 at the end.",
    (_axes(["axis1"]), _amp(45.0), _p("f0_hz", 0.02, "float", "Start frequency, Hz.", lo=0),
     _pos("f1_hz", 0.3, "End frequency, Hz."), _pos("duration_s", 120.0, "Sweep length, s."),
     _p("method", "linear", "choice", "How the frequency moves: 'linear' or 'log'.", choices=("linear", "log")),
     _p("fade_s", 5.0, "float", "Raised-cosine fade-out at the end, s.", lo=0),
     OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_chirp,
    _checks(_chirp_check, _offset_ramp),
)


# random ----------------------------------------------------------------------------------------


def _build_random(tl: _Timeline, p: dict, axes: list[str], seed: int) -> None:
    A, lo, hi, D = p["amplitude_deg"], p["f_lo_hz"], p["f_hi_hz"], p["duration_s"]
    base_seed = p["seed"] if p["seed"] is not None else seed

    def body(axis, offset):
        # Each axis gets its own draw (seed, axis index) so two axes are not copies of each other.
        gen = signals.BandLimitedRandom(A, lo, hi, D, [base_seed, axes.index(axis)])
        tl.play({axis: _shifted(gen, offset)}, D, f"{axis} random {A:g} deg {lo:g}-{hi:g} Hz seed {base_seed}")

    _each_axis(tl, p, axes, body)


def _random_check(p: dict) -> str | None:
    if p["f_lo_hz"] >= p["f_hi_hz"]:
        return "'f_lo_hz' must be below 'f_hi_hz'"
    k_lo = math.ceil(max(p["f_lo_hz"] * p["duration_s"], 1.0) - 1e-9)
    if k_lo > math.floor(p["f_hi_hz"] * p["duration_s"] + 1e-9):
        return (
            f"no multiple of 1/duration_s = {1 / p['duration_s']:g} Hz lies in [{p['f_lo_hz']:g}, {p['f_hi_hz']:g}] Hz: "
            "widen the band or lengthen 'duration_s'"
        )
    return _nyquist(p, "f_hi_hz")


RANDOM = SignalSpec(
    "random",
    "Band-limited non-periodic random signal (seeded multisine over the band), starting and ending at 0.",
    (_axes(["axis1"]), _amp(45.0, "Peak magnitude, deg."), _p("f_lo_hz", 0.01, "float", "Lower band edge, Hz.", lo=0),
     _pos("f_hi_hz", 0.2, "Upper band edge, Hz."), _pos("duration_s", 120.0, "Length, s."),
     _p("seed", None, "seed", "Seed of the random phases; unset: the run's seed."),
     OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_random,
    _checks(_random_check, _offset_ramp),
)


# staircase -------------------------------------------------------------------------------------


def _build_staircase(tl: _Timeline, p: dict, axes: list[str], seed: int) -> None:
    A, steps, hold, rate = p["amplitude_deg"], p["steps"], p["hold_s"], p["step_rate_dps"]
    levels = signals.staircase_levels(A, steps)
    move_s = signals.ramp_duration_s(A / steps, rate)

    def body(axis, offset):
        prev = 0.0
        for k, level in enumerate(levels):
            a, b = offset + prev, offset + float(level)
            tl.play({axis: lambda t, a=a, b=b: signals.ramp(t, a, b, move_s)}, move_s)
            tl.play({axis: _const(b)}, hold, f"{axis} hold {level:g} deg (step {k + 1})")
            prev = float(level)

    _each_axis(tl, p, axes, body)


STAIRCASE = SignalSpec(
    "staircase",
    "Step-and-hold staircase 0 -> +A -> -A -> 0 with long holds (creep) and rate-limited steps.",
    (_axes(["axis1"]), _amp(60.0, "Top step, deg."), _count("steps", 3, "Steps between 0 and the top."),
     _pos("hold_s", 8.0, "Hold at every level, s."),
     _pos("step_rate_dps", 20.0, "Peak knob speed during a step, deg/s."), OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_staircase,
    _offset_ramp,
)


# planes ----------------------------------------------------------------------------------------


def _build_planes(tl: _Timeline, p: dict, axes: list[str], seed: int) -> None:
    A, rate, reps, hold = p["amplitude_deg"], p["sweep_rate_dps"], p["repetitions"], p["hold_s"]
    move_s = signals.ramp_duration_s(A, rate)
    first = True
    for axis in axes:
        for rep in range(reps):
            for sign, tag in ((1.0, "+"), (-1.0, "-")):
                if not first:
                    tl.rest(p["rest_s"])
                first = False
                start = tl.now_s
                tl.play({axis: lambda t, s=sign: signals.ramp(t, 0.0, s * A, move_s)}, move_s)
                tl.play({axis: _const(sign * A)}, hold)
                tl.play({axis: lambda t, s=sign: signals.ramp(t, s * A, 0.0, move_s)}, move_s)
                tl.segments.append(Segment(f"{axis}{tag} sweep {rep + 1}", (axis,), start, tl.now_s))


PLANES = SignalSpec(
    "planes",
    "Bending-plane calibration: slow single-knob sweeps 0 -> +max -> 0, 0 -> -max -> 0 per knob, repeated.",
    (_axes(["axis1", "axis2"], doc="Knobs swept, one after the other (the others hold at 0)."),
     _amp(80.0, "Extreme knob angle of each sweep, deg."),
     _pos("sweep_rate_dps", 10.0, "Peak knob speed of a sweep, deg/s."),
     _count("repetitions", 3, "Sweeps of each half-plane."),
     _p("hold_s", 1.0, "float", "Hold at the extreme, s.", lo=0),
     _p("rest_s", 1.0, "float", "Hold at 0 between sweeps, s.", lo=0), SAMPLE_RATE),
    _build_planes,
)


# circle / lissajous ----------------------------------------------------------------------------


def _build_circle(tl: _Timeline, p: dict, axes: list[str], seed: int) -> None:
    R, f, n, spiral, offset = p["amplitude_deg"], p["frequency_hz"], p["cycles"], p["spiral_s"], p["offset_deg"]
    a1, a2 = axes
    ramp_s = p["ramp_s"]
    if offset:
        tl.play({a: lambda t: signals.ramp(t, 0.0, offset, ramp_s) for a in axes}, ramp_s, f"to offset {offset:g} deg")
    total = 2 * spiral + n / f
    tl.play(
        {a1: _shifted(lambda t: signals.circle(t, R, f, n, spiral)[0], offset),
         a2: _shifted(lambda t: signals.circle(t, R, f, n, spiral)[1], offset)},
        total, f"{a1}/{a2} circle radius {R:g} deg {f:g} Hz x{n}",
    )
    if offset:
        tl.play({a: lambda t: signals.ramp(t, offset, 0.0, ramp_s) for a in axes}, ramp_s, "back to 0")


CIRCLE = SignalSpec(
    "circle",
    "Circle in the plane of two knobs (both move at once: coupling), spiralling in from and out to 0.",
    (_axes(["axis1", "axis2"], 2, "The two axes drawing the circle: first gets r sin, second r cos."),
     _amp(45.0, "Radius, deg."), _pos("frequency_hz", 0.05, "Turns per second, Hz."),
     _count("cycles", 3, "Full turns at the full radius."),
     _p("spiral_s", 5.0, "float", "Spiral in from 0 (and out to 0), s.", lo=0),
     _p("offset_deg", 0.0, "float", "Centre of the circle on both axes, deg."), RAMP, SAMPLE_RATE),
    _build_circle,
    _checks(lambda p: _nyquist(p, "frequency_hz"), _offset_ramp),
)


def _build_lissajous(tl: _Timeline, p: dict, axes: list[str], seed: int) -> None:
    A, fr, ph, D, fade, offset = (p["amplitude_deg"], p["frequencies_hz"], p["phase_deg"], p["duration_s"],
                                  p["fade_s"], p["offset_deg"])
    a1, a2 = axes
    ramp_s = p["ramp_s"]
    if offset:
        tl.play({a: lambda t: signals.ramp(t, 0.0, offset, ramp_s) for a in axes}, ramp_s, f"to offset {offset:g} deg")
    tl.play(
        {a1: _shifted(lambda t: signals.lissajous(t, A, fr, ph, D, fade)[0], offset),
         a2: _shifted(lambda t: signals.lissajous(t, A, fr, ph, D, fade)[1], offset)},
        D, f"{a1}/{a2} lissajous {A:g} deg {fr[0]:g}:{fr[1]:g} Hz",
    )
    if offset:
        tl.play({a: lambda t: signals.ramp(t, offset, 0.0, ramp_s) for a in axes}, ramp_s, "back to 0")


LISSAJOUS = SignalSpec(
    "lissajous",
    "Lissajous figure over two knobs (different frequencies: every combination of positions and directions).",
    (_axes(["axis1", "axis2"], 2, "The two axes of the figure."), _amp(45.0, "Peak of each axis, deg."),
     _p("frequencies_hz", [0.05, 0.075], "floats", "Frequency of the first and second axis, Hz.", lo=0, lo_open=True, length=2),
     _p("phase_deg", 90.0, "float", "Phase lead of the second axis, deg."),
     _pos("duration_s", 120.0, "Length, s."), _p("fade_s", 5.0, "float", "Fade in and out, s.", lo=0),
     _p("offset_deg", 0.0, "float", "Centre of the figure on both axes, deg."), RAMP, SAMPLE_RATE),
    _build_lissajous,
    _checks(lambda p: _nyquist(p, "frequencies_hz"),
            lambda p: "'fade_s' must be at most half of 'duration_s'" if 2 * p["fade_s"] > p["duration_s"] else None,
            _offset_ramp),
)


# hold ------------------------------------------------------------------------------------------


def _build_hold(tl: _Timeline, p: dict, axes: list[str], seed: int) -> None:
    offset, ramp_s, D = p["offset_deg"], p["ramp_s"], p["duration_s"]
    if offset:
        tl.play({a: lambda t: signals.ramp(t, 0.0, offset, ramp_s) for a in axes}, ramp_s, f"to {offset:g} deg")
    tl.play({a: _const(offset) for a in axes}, D, f"hold {offset:g} deg")
    if offset:
        tl.play({a: lambda t: signals.ramp(t, offset, 0.0, ramp_s) for a in axes}, ramp_s, "back to 0")


HOLD = SignalSpec(
    "hold",
    "Hold the axes still (at 0: home; or at an offset, reached and left by ramps): drift, noise floor.",
    (_axes(["axis1", "axis2"], doc="Axes held (all at once)."),
     _p("offset_deg", 0.0, "float", "Level held on every listed axis, deg."),
     _pos("duration_s", 30.0, "Hold length, s."), RAMP, SAMPLE_RATE),
    _build_hold,
    _offset_ramp,
)


#: Every signal kind a protocol file can name in ``signal = "..."``.
SIGNALS: dict[str, SignalSpec] = {
    s.name: s
    for s in (SINE, SINE_SET, SINE_VARYING, DAMPED_SINE, TRIANGLE, CHIRP, RANDOM, STAIRCASE, PLANES, CIRCLE,
              LISSAJOUS, HOLD)
}


# --------------------------------------------------------------------------- protocol


def _resolve_params(spec: SignalSpec, given: dict, where: str, base: dict | None = None) -> dict:
    """Defaults (or ``base``), then ``given`` on top; every value checked."""
    known = [q.name for q in spec.params]
    unknown = [k for k in given if k not in known]
    if unknown:
        raise ProtocolError(
            f"{where}: unknown parameter(s) {', '.join(repr(k) for k in unknown)} for signal '{spec.name}'; "
            f"it has {', '.join(known)}"
        )
    params = dict(base) if base is not None else {q.name: q.default for q in spec.params}
    for k, v in given.items():
        params[k] = spec.param(k).coerce(v, where)
    params = {q.name: (list(params[q.name]) if isinstance(params[q.name], list) else params[q.name]) for q in spec.params}
    msg = spec.check(params)
    if msg:
        raise ProtocolError(f"{where}: {msg}")
    return params


@dataclass(frozen=True)
class Protocol:
    """A validated excitation protocol.

    Attributes
    ----------
    name : str
        File stem (``damped-sine``) or the name given to :meth:`from_dict`.
    description : str
        One line.
    signal : str
        Kind of signal, a key of :data:`SIGNALS`.
    params : dict
        Every parameter of the signal, resolved: defaults, then the file, then overrides.
    source_path : Path or None
        The TOML file it was read from.
    sha256 : str or None
        SHA-256 of the file's bytes (overrides are recorded in ``params``/``overrides``).
    overrides : dict
        The parameters the user changed at load time.
    sim : dict
        The file's optional ``[sim]`` table: simulator settings this protocol needs (e.g.
        ``[sim.contact]``, an obstacle), in the layout of a sim config TOML. The simulator
        backend applies them over ``--sim-config``; other backends only record them.
    """

    name: str
    description: str
    signal: str
    params: dict
    source_path: Path | None = None
    sha256: str | None = None
    overrides: dict = field(default_factory=dict)
    sim: dict = field(default_factory=dict)

    @property
    def spec(self) -> SignalSpec:
        return SIGNALS[self.signal]

    def with_overrides(self, overrides: dict | None) -> Protocol:
        """A copy with some parameters changed (validated like the file's)."""
        if not overrides:
            return self
        where = f"override for protocol '{self.name}'"
        params = _resolve_params(self.spec, dict(overrides), where, base=self.params)
        return Protocol(self.name, self.description, self.signal, params, self.source_path, self.sha256,
                        {**self.overrides, **dict(overrides)}, self.sim)

    def resolved_axes(self, probe: ProbeConfig) -> list[str]:
        """The protocol's ``axes`` as the probe's DoF names.

        Raises
        ------
        ProtocolError
            An axis the probe does not have, one named twice, or ``translation`` (protocol
            amplitudes are in degrees).
        """
        out: list[str] = []
        for ref in self.params["axes"]:
            try:
                dof = probe.resolve_axis(ref)
            except ConfigError as exc:
                raise ProtocolError(f"protocol '{self.name}': {exc}") from None
            if dof == TRANSLATION:
                raise ProtocolError(
                    f"protocol '{self.name}': axis 'translation' moves in mm but protocol amplitudes are in deg; "
                    f"drive a bending knob ({', '.join(probe.bending_axes)}) or '{ROTATION}'"
                )
            if dof in out:
                raise ProtocolError(f"protocol '{self.name}': axis '{ref}' is {dof}, which is already listed in axes")
            out.append(dof)
        return out

    def _timeline(self, axes: list[str], seed: int) -> _Timeline:
        tl = _Timeline()
        try:
            self.spec.build(tl, self.params, axes, seed)
        except ValueError as exc:  # a generator refusing its arguments; the spec checks should have caught it
            raise ProtocolError(f"protocol '{self.name}': {exc}") from None
        return tl

    def trajectory(self, probe: ProbeConfig, seed: int | None = None) -> Trajectory:
        """Goals for every DoF of ``probe`` on the motor clock.

        Parameters
        ----------
        probe : ProbeConfig
            Resolves ``axis1``/``axis2`` and names the DoFs; DoFs not driven hold at 0.
        seed : int, optional
            The run's seed. Used by random signals whose ``seed`` parameter is unset (a
            seed set in the file or as an override wins); otherwise 0.

        Returns
        -------
        Trajectory
            Not yet checked against the probe's limits: call :meth:`Trajectory.check_limits`
            before playing it.
        """
        axes = self.resolved_axes(probe)
        tl = self._timeline(axes, 0 if seed is None else int(seed))
        return tl.render(probe.dofs, self.params["sample_rate_hz"], self.name)

    @property
    def duration_s(self) -> float:
        """Length of the trajectory (the same on every probe), s."""
        tl = self._timeline(list(self.params["axes"]), 0)
        fs = self.params["sample_rate_hz"]
        return (int(math.ceil(tl.now_s * fs - 1e-9))) / fs

    def to_dict(self) -> dict:
        """Plain, JSON-ready description (what ``run.json`` records)."""
        return {
            "name": self.name,
            "description": self.description,
            "signal": self.signal,
            "params": {k: (list(v) if isinstance(v, list) else v) for k, v in self.params.items()},
            "overrides": dict(self.overrides),
            "source": str(self.source_path) if self.source_path else None,
            "sha256": self.sha256,
            **({"sim": self.sim} if self.sim else {}),
        }

    @classmethod
    def from_dict(cls, d: dict, where: str = "protocol") -> Protocol:
        """Rebuild a protocol from :meth:`to_dict` output (e.g. read back from ``run.json``).

        Raises
        ------
        ProtocolError
            Missing keys, unknown signal, or invalid parameters.
        """
        try:
            name, signal, params = str(d["name"]), d["signal"], d["params"]
        except (KeyError, TypeError):
            raise ProtocolError(f"{where}: needs 'name', 'signal' and 'params'") from None
        spec = _spec(signal, where)
        if not isinstance(params, dict):
            raise ProtocolError(f"{where}: 'params' must be a table")
        src = d.get("source")
        return cls(name, str(d.get("description", "")), signal, _resolve_params(spec, params, where),
                   Path(src) if src else None, d.get("sha256"), dict(d.get("overrides") or {}), dict(d.get("sim") or {}))


def _spec(signal: Any, where: str) -> SignalSpec:
    if signal not in SIGNALS:
        raise ProtocolError(f"{where}: field 'signal' must be one of {', '.join(SIGNALS)}, got {signal!r}")
    return SIGNALS[signal]


# --------------------------------------------------------------------------- files


def shipped_protocols_dir() -> Path:
    """The protocols shipped with endocal.

    The repository's top-level ``protocols/`` in a source or editable install, else
    ``endocal/_protocols`` inside an installed wheel.
    """
    pkg = Path(endocal.__file__).resolve().parent
    source = pkg.parent / "protocols"
    return source if source.is_dir() else pkg / "_protocols"


def protocol_dirs() -> list[Path]:
    """Where protocol names are looked up, first match wins: ``./protocols``, then the shipped ones."""
    dirs = []
    local = Path.cwd() / "protocols"
    if local.is_dir():
        dirs.append(local)
    shipped = shipped_protocols_dir()
    if shipped.is_dir() and all(shipped.resolve() != d.resolve() for d in dirs):
        dirs.append(shipped)
    return dirs


def _known_files() -> dict[str, Path]:
    found: dict[str, Path] = {}
    for d in protocol_dirs():
        for path in sorted(d.glob("*.toml")):
            found.setdefault(path.stem, path)
    return found


def _looks_like_path(name: str) -> bool:
    return name.endswith(".toml") or "/" in name or "\\" in name


def read_protocol_file(path: str | Path) -> Protocol:
    """Read and validate one protocol TOML file.

    Raises
    ------
    ProtocolError
        Missing file, malformed TOML (with the line), missing or invalid fields (named).
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ProtocolError(f"protocol file {path} does not exist") from None
    except IsADirectoryError:
        raise ProtocolError(f"protocol file {path} is a folder, not a .toml file") from None
    except OSError as exc:
        raise ProtocolError(f"cannot read protocol file {path}: {exc.strerror}") from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ProtocolError(f"protocol file {path} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ProtocolError(f"protocol file {path} is malformed TOML: {exc}") from None
    where = f"protocol file {path}"
    unknown = [k for k in data if k not in _FILE_KEYS]
    if unknown:
        raise ProtocolError(f"{where}: unknown field(s) {', '.join(map(repr, unknown))}; a protocol has {', '.join(_FILE_KEYS)}")
    for key in ("description", "signal"):
        if key not in data:
            raise ProtocolError(f"{where}: missing field '{key}'")
    if not isinstance(data["description"], str) or not data["description"].strip():
        raise ProtocolError(f"{where}: field 'description' must be a non-empty string")
    spec = _spec(data["signal"], where)
    params = data.get("params", {})
    if not isinstance(params, dict):
        raise ProtocolError(f"{where}: 'params' must be a table (a section headed params)")
    sim = data.get("sim", {})
    if not isinstance(sim, dict):
        raise ProtocolError(f"{where}: 'sim' must be a table of sim config sections (e.g. a section headed sim.contact)")
    return Protocol(
        name=path.stem,
        description=" ".join(data["description"].split()),
        signal=spec.name,
        params=_resolve_params(spec, params, where),
        source_path=path.resolve(),
        sha256=hashlib.sha256(raw).hexdigest(),
        sim=sim,
    )


def load_protocol(name_or_path: str | Path, overrides: dict | None = None) -> Protocol:
    """A protocol by name (``./protocols`` first, then the shipped ones) or from a ``.toml`` path.

    Parameters
    ----------
    name_or_path : str or Path
        ``damped-sine``, or ``my/protocol.toml``.
    overrides : dict, optional
        Parameter values replacing the file's, e.g. ``{"amplitude_deg": 40, "axes": ["ml"]}``.

    Returns
    -------
    Protocol

    Raises
    ------
    ProtocolError
        Unknown name (listing the known ones), bad file, or an override the protocol
        does not have or cannot take.
    """
    key = str(name_or_path)
    if isinstance(name_or_path, Path) or _looks_like_path(key):
        proto = read_protocol_file(Path(key))
    else:
        files = _known_files()
        if key not in files:
            where = " and ".join(str(d) for d in protocol_dirs()) or "no protocols folder"
            raise ProtocolError(
                f"unknown protocol '{key}': known protocols are {', '.join(sorted(files)) or 'none'} "
                f"(from {where}); or give the path of a .toml file"
            )
        proto = read_protocol_file(files[key])
    return proto.with_overrides(overrides)


def list_protocols() -> list[tuple[str, str, Path]]:
    """Every protocol found by name, sorted: ``(name, description, path)``.

    Raises
    ------
    ProtocolError
        A protocol file in the search folders is invalid (named), rather than hiding it.
    """
    return [(name, read_protocol_file(path).description, path) for name, path in sorted(_known_files().items())]


def parse_overrides(pairs: list[str]) -> dict:
    """``["amplitude_deg=40", "axes=['ml']", "method=log"]`` -> ``{"amplitude_deg": 40.0, ...}``.

    Values are read as TOML values (numbers, lists, booleans, quoted strings); anything
    that is not a TOML value is taken as a plain string.

    Raises
    ------
    ProtocolError
        A pair without ``=`` or with an empty key.
    """
    overrides: dict = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key:
            raise ProtocolError(f"--set expects key=value, got '{pair}'")
        try:
            overrides[key] = tomllib.loads(f"v = {value}")["v"]
        except tomllib.TOMLDecodeError:
            overrides[key] = value
    return overrides
