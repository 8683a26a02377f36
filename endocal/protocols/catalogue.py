"""The signal catalogue: every kind of excitation a protocol file can name, with its parameters.

Each :class:`SignalSpec` lists its parameters (:mod:`endocal.protocols.params`), cross-checks
them, and places the pure generators of :mod:`endocal.protocols.signals` on a timeline, axis
after axis, from rest to rest. :data:`SIGNALS` is the catalogue; ``protocols/README.md``
documents every entry (a test keeps the two in step).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from endocal.errors import ProtocolError
from endocal.protocols import signals
from endocal.protocols.params import (
    OFFSET,
    RAMP,
    REST,
    SAMPLE_RATE,
    Param,
    amplitude_param,
    axes_param,
    count_param,
    param,
    positive_param,
)
from endocal.protocols.trajectory import Segment, Trajectory, check_samples


class Timeline:
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
        """The goal of every degree of freedom sampled at ``sample_rate_hz``.

        Raises
        ------
        ProtocolError
            More than :data:`~endocal.protocols.trajectory.MAX_SAMPLES` samples
            (:func:`~endocal.protocols.trajectory.check_samples`).
        """
        fs = sample_rate_hz
        check_samples(self.now_s, fs, f"protocol '{protocol}'", "its duration, periods, cycles and sample_rate_hz")
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


def _each_axis(tl: Timeline, p: dict, axes: list[str], body: Callable[[str, float], None]) -> None:
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
    build: Callable[[Timeline, dict, list[str], int], None]
    check: Callable[[dict], str | None] = lambda p: None

    def param(self, name: str) -> Param:
        return next(q for q in self.params if q.name == name)

    def resolve(self, given: dict, where: str, base: dict | None = None) -> dict:
        """Every parameter of this signal: defaults (or ``base``), then ``given`` on top, each value checked.

        Raises
        ------
        ProtocolError
            A parameter the signal does not have, a value it cannot take, or parameters that
            contradict each other (the signal's cross-check), naming ``where``.
        """
        known = [q.name for q in self.params]
        unknown = [k for k in given if k not in known]
        if unknown:
            raise ProtocolError(
                f"{where}: unknown parameter(s) {', '.join(repr(k) for k in unknown)} for signal '{self.name}'; "
                f"it has {', '.join(known)}"
            )
        params = dict(base) if base is not None else {q.name: q.default for q in self.params}
        for k, v in given.items():
            params[k] = self.param(k).coerce(v, where)
        params = {q.name: (list(params[q.name]) if isinstance(params[q.name], list) else params[q.name])
                  for q in self.params}
        msg = self.check(params)
        if msg:
            raise ProtocolError(f"{where}: {msg}")
        return params


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


def _build_sine(tl: Timeline, p: dict, axes: list[str], seed: int) -> None:
    A, f, n = p["amplitude_deg"], p["frequency_hz"], p["cycles"]

    def body(axis, offset):
        fn = _shifted(lambda t: signals.sine(t, A, f), offset)
        tl.play({axis: fn}, n / f, f"{axis} sine {A:g} deg {f:g} Hz x{n}")

    _each_axis(tl, p, axes, body)


SINE = SignalSpec(
    "sine",
    "Plain sine A sin(2 pi f t), whole cycles, each axis in turn (the paper's 0.05 Hz accuracy test).",
    (axes_param(["axis1"]), amplitude_param(45.0), positive_param("frequency_hz", 0.05, "Frequency, Hz."),
     count_param("cycles", 3, "Whole periods per axis."), OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_sine,
    _checks(lambda p: _nyquist(p, "frequency_hz"), _offset_ramp),
)


# sine-set --------------------------------------------------------------------------------------


def _build_sine_set(tl: Timeline, p: dict, axes: list[str], seed: int) -> None:
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
    (axes_param(["axis1", "axis2"]),
     param("amplitudes_deg", [30.0, 60.0], "floats", "Amplitudes, deg; all periods are played at each.", lo=0, lo_open=True),
     param("periods_s", [40.0, 20.0, 10.0, 5.0], "floats", "Periods, s, in playing order.", lo=0, lo_open=True),
     count_param("cycles", 2, "Whole periods per (amplitude, period) block."), OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_sine_set,
    _checks(lambda p: None if 1.0 / min(p["periods_s"]) < p["sample_rate_hz"] / 2
            else f"'periods_s' must stay above two samples ({2 / p['sample_rate_hz']:g} s)", _offset_ramp),
)


# sine-varying ----------------------------------------------------------------------------------


def _build_sine_varying(tl: Timeline, p: dict, axes: list[str], seed: int) -> None:
    A, fs_hz, n = p["amplitude_deg"], p["frequencies_hz"], p["cycles"]
    total = sum(n / f for f in fs_hz)

    def body(axis, offset):
        fn = _shifted(lambda t: signals.stepped_frequency_sine(t, A, fs_hz, n), offset)
        tl.play({axis: fn}, total, f"{axis} sine {A:g} deg at {', '.join(f'{f:g}' for f in fs_hz)} Hz x{n} each")

    _each_axis(tl, p, axes, body)


SINE_VARYING = SignalSpec(
    "sine-varying",
    "Thesis validation: one sine whose frequency changes every few whole periods, phase-continuous.",
    (axes_param(["axis1", "axis2"]), amplitude_param(45.0),
     param("frequencies_hz", [0.04, 0.125], "floats", "Frequencies in playing order, Hz.", lo=0, lo_open=True),
     count_param("cycles", 2, "Whole periods at each frequency."), OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_sine_varying,
    _checks(lambda p: _nyquist(p, "frequencies_hz"), _offset_ramp),
)


# damped-sine -----------------------------------------------------------------------------------


def _build_damped_sine(tl: Timeline, p: dict, axes: list[str], seed: int) -> None:
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
    (axes_param(["axis1"]), amplitude_param(60.0, "A, peak of the undamped part, deg."),
     positive_param("frequency_hz", 0.05, "f, Hz (paper: 0.05)."), positive_param("period_s", 20.0, "T, s (paper: 20); lasts 7T."),
     OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_damped_sine,
    _checks(lambda p: _nyquist(p, "frequency_hz"), _damped_ends_at_zero, _offset_ramp),
)


# triangle --------------------------------------------------------------------------------------


def _build_triangle(tl: Timeline, p: dict, axes: list[str], seed: int) -> None:
    A, T, n = p["amplitude_deg"], p["period_s"], p["cycles"]

    def body(axis, offset):
        fn = _shifted(lambda t: signals.triangle(t, A, T), offset)
        tl.play({axis: fn}, n * T, f"{axis} triangle {A:g} deg period {T:g} s x{n}")

    _each_axis(tl, p, axes, body)


TRIANGLE = SignalSpec(
    "triangle",
    "Triangle wave 0 -> +A -> -A -> 0, constant knob speed 4A/T between reversals.",
    (axes_param(["axis1"]), amplitude_param(45.0), positive_param("period_s", 20.0, "Period, s."), count_param("cycles", 3, "Whole periods."),
     OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_triangle,
    _checks(lambda p: None if p["period_s"] * p["sample_rate_hz"] >= 4
            else "'period_s' must hold at least 4 samples", _offset_ramp),
)


# chirp -----------------------------------------------------------------------------------------


def _build_chirp(tl: Timeline, p: dict, axes: list[str], seed: int) -> None:
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
    (axes_param(["axis1"]), amplitude_param(45.0), param("f0_hz", 0.02, "float", "Start frequency, Hz.", lo=0),
     positive_param("f1_hz", 0.3, "End frequency, Hz."), positive_param("duration_s", 120.0, "Sweep length, s."),
     param("method", "linear", "choice", "How the frequency moves: 'linear' or 'log'.", choices=("linear", "log")),
     param("fade_s", 5.0, "float", "Raised-cosine fade-out at the end, s.", lo=0),
     OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_chirp,
    _checks(_chirp_check, _offset_ramp),
)


# random ----------------------------------------------------------------------------------------


def _build_random(tl: Timeline, p: dict, axes: list[str], seed: int) -> None:
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
    (axes_param(["axis1"]), amplitude_param(45.0, "Peak magnitude, deg."), param("f_lo_hz", 0.01, "float", "Lower band edge, Hz.", lo=0),
     positive_param("f_hi_hz", 0.2, "Upper band edge, Hz."), positive_param("duration_s", 120.0, "Length, s."),
     param("seed", None, "seed", "Seed of the random phases; unset: the run's seed."),
     OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_random,
    _checks(_random_check, _offset_ramp),
)


# staircase -------------------------------------------------------------------------------------


def _build_staircase(tl: Timeline, p: dict, axes: list[str], seed: int) -> None:
    A, steps, hold, rate = p["amplitude_deg"], p["steps"], p["hold_s"], p["step_rate_dps"]
    levels = np.tile(signals.staircase_levels(A, steps), p["cycles"])
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
    (axes_param(["axis1"]), amplitude_param(60.0, "Top step, deg."), count_param("steps", 3, "Steps between 0 and the top."),
     positive_param("hold_s", 8.0, "Hold at every level, s."),
     positive_param("step_rate_dps", 20.0, "Peak knob speed during a step, deg/s."),
     count_param("cycles", 1, "Times the whole staircase is played (each ends at 0)."), OFFSET, RAMP, REST, SAMPLE_RATE),
    _build_staircase,
    _offset_ramp,
)


# planes ----------------------------------------------------------------------------------------


def _build_planes(tl: Timeline, p: dict, axes: list[str], seed: int) -> None:
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
    (axes_param(["axis1", "axis2"], doc="Knobs swept, one after the other (the others hold at 0)."),
     amplitude_param(80.0, "Extreme knob angle of each sweep, deg."),
     positive_param("sweep_rate_dps", 10.0, "Peak knob speed of a sweep, deg/s."),
     count_param("repetitions", 3, "Sweeps of each half-plane."),
     param("hold_s", 1.0, "float", "Hold at the extreme, s.", lo=0),
     param("rest_s", 1.0, "float", "Hold at 0 between sweeps, s.", lo=0), SAMPLE_RATE),
    _build_planes,
)


# circle / lissajous ----------------------------------------------------------------------------


def _both_axes(tl: Timeline, p: dict, axes: list[str], pair: Callable[[np.ndarray], tuple], duration_s: float,
               label: str) -> None:
    """Both ``axes`` at once: ramp to the common offset, follow ``pair(t) -> (first, second)``, ramp back."""
    a1, a2 = axes
    offset, ramp_s = p["offset_deg"], p["ramp_s"]
    if offset:
        tl.play({a: lambda t: signals.ramp(t, 0.0, offset, ramp_s) for a in axes}, ramp_s, f"to offset {offset:g} deg")
    tl.play({a1: _shifted(lambda t: pair(t)[0], offset), a2: _shifted(lambda t: pair(t)[1], offset)}, duration_s, label)
    if offset:
        tl.play({a: lambda t: signals.ramp(t, offset, 0.0, ramp_s) for a in axes}, ramp_s, "back to 0")


def _build_circle(tl: Timeline, p: dict, axes: list[str], seed: int) -> None:
    R, f, n, spiral = p["amplitude_deg"], p["frequency_hz"], p["cycles"], p["spiral_s"]
    _both_axes(tl, p, axes, lambda t: signals.circle(t, R, f, n, spiral), 2 * spiral + n / f,
               f"{axes[0]}/{axes[1]} circle radius {R:g} deg {f:g} Hz x{n}")

CIRCLE = SignalSpec(
    "circle",
    "Circle in the plane of two knobs (both move at once: coupling), spiralling in from and out to 0.",
    (axes_param(["axis1", "axis2"], 2, "The two axes drawing the circle: first gets r sin, second r cos."),
     amplitude_param(45.0, "Radius, deg."), positive_param("frequency_hz", 0.05, "Turns per second, Hz."),
     count_param("cycles", 3, "Full turns at the full radius."),
     param("spiral_s", 5.0, "float", "Spiral in from 0 (and out to 0), s.", lo=0),
     param("offset_deg", 0.0, "float", "Centre of the circle on both axes, deg."), RAMP, SAMPLE_RATE),
    _build_circle,
    _checks(lambda p: _nyquist(p, "frequency_hz"), _offset_ramp),
)


def _build_lissajous(tl: Timeline, p: dict, axes: list[str], seed: int) -> None:
    A, fr, ph, D, fade = p["amplitude_deg"], p["frequencies_hz"], p["phase_deg"], p["duration_s"], p["fade_s"]
    _both_axes(tl, p, axes, lambda t: signals.lissajous(t, A, fr, ph, D, fade), D,
               f"{axes[0]}/{axes[1]} lissajous {A:g} deg {fr[0]:g}:{fr[1]:g} Hz")

LISSAJOUS = SignalSpec(
    "lissajous",
    "Lissajous figure over two knobs (different frequencies: every combination of positions and directions).",
    (axes_param(["axis1", "axis2"], 2, "The two axes of the figure."), amplitude_param(45.0, "Peak of each axis, deg."),
     param("frequencies_hz", [0.05, 0.075], "floats", "Frequency of the first and second axis, Hz.", lo=0, lo_open=True, length=2),
     param("phase_deg", 90.0, "float", "Phase lead of the second axis, deg."),
     positive_param("duration_s", 120.0, "Length, s."), param("fade_s", 5.0, "float", "Fade in and out, s.", lo=0),
     param("offset_deg", 0.0, "float", "Centre of the figure on both axes, deg."), RAMP, SAMPLE_RATE),
    _build_lissajous,
    _checks(lambda p: _nyquist(p, "frequencies_hz"),
            lambda p: "'fade_s' must be at most half of 'duration_s'" if 2 * p["fade_s"] > p["duration_s"] else None,
            _offset_ramp),
)


# hold ------------------------------------------------------------------------------------------


def _build_hold(tl: Timeline, p: dict, axes: list[str], seed: int) -> None:
    offset, ramp_s, D = p["offset_deg"], p["ramp_s"], p["duration_s"]
    if offset:
        tl.play({a: lambda t: signals.ramp(t, 0.0, offset, ramp_s) for a in axes}, ramp_s, f"to {offset:g} deg")
    tl.play({a: _const(offset) for a in axes}, D, f"hold {offset:g} deg")
    if offset:
        tl.play({a: lambda t: signals.ramp(t, offset, 0.0, ramp_s) for a in axes}, ramp_s, "back to 0")


HOLD = SignalSpec(
    "hold",
    "Hold the axes still (at 0: home; or at an offset, reached and left by ramps): drift, noise floor.",
    (axes_param(["axis1", "axis2"], doc="Axes held (all at once)."),
     param("offset_deg", 0.0, "float", "Level held on every listed axis, deg."),
     positive_param("duration_s", 30.0, "Hold length, s."), RAMP, SAMPLE_RATE),
    _build_hold,
    _offset_ramp,
)


# sequence --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SegmentsParam(Param):
    """The ``segments`` of a ``sequence``: a list of tables, each a signal (``signal = "..."``) and its
    parameters, resolved like a protocol file's (defaults, then what the table sets, every value
    checked). A segment's ``sample_rate_hz`` is the sequence's; a sequence does not nest."""

    def coerce(self, value, where: str) -> list[dict]:
        if not isinstance(value, (list, tuple)) or not value:
            raise ProtocolError(f"{where}: parameter '{self.name}' must be a non-empty list of tables, each with a "
                                f"'signal' (e.g. a section headed [[params.segments]]), got {value!r}")
        out = []
        for i, seg in enumerate(value, 1):
            at = f"{where}, segment {i}"
            if not isinstance(seg, dict) or not isinstance(seg.get("signal"), str):
                raise ProtocolError(f"{at}: a segment is a table naming its 'signal', got {seg!r}")
            name = seg["signal"]
            if name == SEQUENCE_NAME or name not in SIGNALS:
                kinds = ", ".join(k for k in SIGNALS if k != SEQUENCE_NAME)
                raise ProtocolError(f"{at}: 'signal' must be one of {kinds}, got {name!r}")
            given = {k: v for k, v in seg.items() if k != "signal"}
            if "sample_rate_hz" in given:
                raise ProtocolError(f"{at}: a segment plays on the sequence's motor clock: set 'sample_rate_hz' "
                                    "in the sequence's [params], not in a segment")
            params = SIGNALS[name].resolve(given, at)
            del params["sample_rate_hz"]
            out.append({"signal": name, **params})
        return out


SEQUENCE_NAME = "sequence"


def _segment_params(seg: dict, sample_rate_hz: float) -> dict:
    return {**{k: v for k, v in seg.items() if k != "signal"}, "sample_rate_hz": sample_rate_hz}


def _build_sequence(tl: Timeline, p: dict, axes: list[str], seed: int) -> None:
    dof = dict(zip(p["axes"], axes))  # each segment spells its axes as the sequence's list does
    for i, seg in enumerate(p["segments"]):
        if i:
            tl.rest(p["rest_s"])
        params = _segment_params(seg, p["sample_rate_hz"])
        SIGNALS[seg["signal"]].build(tl, params, [dof[a] for a in params["axes"]], seed)


def _sequence_check(p: dict) -> str | None:
    for i, seg in enumerate(p["segments"], 1):
        stray = [a for a in seg["axes"] if a not in p["axes"]]
        if stray:
            return (f"segment {i} ({seg['signal']}) drives {', '.join(map(repr, stray))}, which the sequence's "
                    f"'axes' {p['axes']} do not list: list every axis a segment drives there, spelled the same way")
        msg = SIGNALS[seg["signal"]].check(_segment_params(seg, p["sample_rate_hz"]))
        if msg:
            return f"segment {i} ({seg['signal']}): {msg}"
    return None


SEQUENCE = SignalSpec(
    SEQUENCE_NAME,
    "Several signals one after the other (each from rest to rest, rest_s apart): one run for several tests.",
    (axes_param(["axis1", "axis2"], doc="Every axis a segment drives, spelled as the segments spell them."),
     SegmentsParam("segments", [{"signal": "sine", **{k: v for k, v in SINE.resolve({}, "sine").items()
                                                      if k != "sample_rate_hz"}}], "segments",
                   "The signals in playing order: tables with 'signal' and that signal's parameters."),
     REST, SAMPLE_RATE),
    _build_sequence,
    _sequence_check,
)


#: Every signal kind a protocol file can name in ``signal = "..."``.
SIGNALS: dict[str, SignalSpec] = {
    s.name: s
    for s in (SINE, SINE_SET, SINE_VARYING, DAMPED_SINE, TRIANGLE, CHIRP, RANDOM, STAIRCASE, PLANES, CIRCLE,
              LISSAJOUS, HOLD, SEQUENCE)
}


