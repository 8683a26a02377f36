"""The next experiment: the protocol that would settle what ``validate`` could not.

``validate`` names the effect a model misses when its data can show it. Where they cannot
(the other knob never moved, no condition varied, one range of speeds, no holds, not the
full amplitude) or where they could not settle it (a suspect the residual points at but the
scan did not confirm, a candidate not significant for want of units, a residual that is no
noise although no catalog effect lowers it), it says so in words. :func:`design_next` turns
those words into an ordinary protocol file ``endocal excite`` runs: a ``sequence`` of the
motions that show each effect, inside the probe's limits and the range the model was fitted
on, each sized so that the paired test of the next ``validate`` can reach significance, and
a ``[conditions]`` prompt where only the user can change what is tested.

What tests what: each effect's own ``segment`` (``Effect.segment``, :mod:`endocal.models.effects`)
    built with the builders of :class:`Design`, in the effects' ``segment_order``: the other knob
    moving with this one (``coupling``); one ladder of frequencies shared by the effects that ask
    for it (``rate`` vs ``delay``: the same sine at several frequencies, up and back down, up to the
    speed at which the two hypotheses predict measurably different loops, found by fitting the
    alternative on the estimation data and predicting both on trial sines, :func:`speeds_at_stake`:
    the discrimination design of Box & Hill, Technometrics 9, 1967, in its simplest form); moves
    with holds (``creep``); a long hold (``drift``); the full amplitude (``envelope``); a condition
    of the run, the same motion at the earlier value and at a new one (``load``: a condition
    changed only between records is confounded with them). An effect without a segment gets its
    ``protocol`` in words. A residual that is no noise: the loop at two amplitudes and three speeds
    (``sine-set``), for another base to be compared on. A candidate not significant: more of the
    validation record's kind of motion (``random`` in its band), as long as the power
    calculation asks.

How long (:mod:`endocal.validation.power`)
    A candidate the scan tested is sized at the gain it showed: the half-cycles with which
    the sign-flip test reaches ``alpha / m`` (Holm, ``m`` candidates) with 80 % power. An
    effect no data could test has no gain yet: its segment is sized as if the effect removed
    the same share of every half-cycle's error, so the spread of the per-half-cycle error of
    the model as it stands (its coefficient of variation, at least 1) sets the length.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from endocal.errors import LimitError, ModelError, ProtocolError
from endocal.models import EFFECTS, HysteresisData
from endocal.models.effects import make_effect
from endocal.models.base import HysteresisModel
from endocal.models.data import OTHER_CMD
from endocal.probe import ProbeConfig, load_probe
from endocal.protocols import Protocol, SIGNALS
from endocal.validation.candidates import takes_column
from endocal.validation.data import load_candidates
from endocal.validation.power import POWER, evidence_phrase, units_for_power
from endocal.validation.regimes import turning_points
from endocal.validation.predict import predict_errors
from endocal.validation.scan import MAX_SCAN_SAMPLES, scan_stride
from endocal.validation.structure import effect_labels, scan_ftol, split_fit
from endocal.validation.units import make_units

#: Smallest amplitude (deg) a designed motion sweeps about its centre: a loop narrower than 10 deg
#: peak to peak stays inside the dead band of a tendon drive (the default simulated probe's slack
#: alone is 8.6 knob deg), where no effect but the dead band shows.
MIN_AMPLITUDE_DEG = 5.0
#: Share of the probe's knob speed and acceleration limits a design uses: the limits are what
#: ``excite`` refuses, and a servo asked for its top speed follows it late.
LIMIT_SHARE = 0.8
#: The condition column asked for when the records log none.
CONDITION = "load_condition"


@dataclass(frozen=True)
class PlannedTest:
    """One effect the next experiment tests, and how.

    Attributes
    ----------
    effect : str
        Catalog effect (``load`` with the condition's column: ``load:sheath_wrap_deg``), or
        ``shape`` for a residual no catalog effect lowers.
    status : str
        Why it is in the protocol: ``untestable`` (the data cannot show it), ``untested`` /
        ``unconfirmed`` (pointed at by the residual), ``not significant``, ``speeds``
        (``rate`` vs ``delay`` not told apart at the speeds at stake), ``no holds``, ``not
        the full amplitude``, ``unexplained``.
    why : str
        What ``validate`` said, in words.
    segment : int or None
        1-based segment of the sequence that tests it; None for a condition (the whole run).
    half_cycles : int
        Half-cycles of this axis the test gets.
    sized : str
        How that length was chosen, in words with the numbers.
    gain_pct : float or None
        The validation RMSE gain ``validate`` saw for it (None: the records could not test it).
    needed_half_cycles : int or None
        Half-cycles with which the paired test reaches significance at that gain
        (:class:`~endocal.validation.power.PowerEstimate`); None when no gain was seen or no
        length will (``needed`` says which).
    needed : str
        The same in words: ``about 40 half-cycles would make it significant at this gain``,
        ``no length will: ...``, or that no gain was seen.
    """

    effect: str
    status: str
    why: str
    segment: int | None
    half_cycles: int
    sized: str
    gain_pct: float | None = None
    needed_half_cycles: int | None = None
    needed: str = ""

    def to_dict(self) -> dict:
        return {"effect": self.effect, "status": self.status, "why": self.why, "segment": self.segment,
                "half_cycles": self.half_cycles, "sized": self.sized, "gain_pct": self.gain_pct,
                "needed_half_cycles": self.needed_half_cycles, "needed": self.needed}


@dataclass(frozen=True)
class NextExperiment:
    """The protocol :func:`design_next` wrote, and what it tests.

    Attributes
    ----------
    protocol : Protocol
        A ``sequence`` protocol (see ``protocols/README.md``), its ``[design]`` table saying
        what it is for; ``excite`` runs it (:meth:`to_toml` / :meth:`write`).
    tests : tuple of PlannedTest
        Each effect it tests.
    axis : str
        The model's axis; ``other_axis`` the other bending knob (None on a one-knob probe).
    range_deg : (float, float)
        Knob range every segment stays in: the model's fitted range within the probe's limits.
    probe : str
        The probe's name (its limits were checked).
    notes : tuple of str
        What the design left out and why (a pair of effects the data already settle, ...).
    """

    protocol: Protocol
    tests: tuple[PlannedTest, ...]
    axis: str
    other_axis: str | None
    range_deg: tuple[float, float]
    probe: str
    notes: tuple[str, ...] = ()

    @property
    def suspects(self) -> tuple[str, ...]:
        """The effects it tests, as ``--effects`` writes them."""
        return tuple(dict.fromkeys(t.effect for t in self.tests))

    @property
    def conditions(self) -> dict:
        """Conditions ``excite`` asks for (``--set NAME=VALUE``): name -> instruction."""
        return {k: c["instruction"] for k, c in self.protocol.conditions.items()}

    @property
    def duration_s(self) -> float:
        return self.protocol.duration_s

    def to_toml(self) -> str:
        """The protocol file."""
        head = (f"The next experiment for the model of axis {self.axis} ({', '.join(self.suspects)}), written by "
                "`endocal validate --next`.\nRun it twice (once to fit on, once to validate on): "
                "`endocal excite THIS.toml --out RUN`.")
        return self.protocol.to_toml(head)

    def write(self, path: str | Path) -> Path:
        """Write :meth:`to_toml` to ``path`` whole or not at all (a temporary file renamed into place)."""
        path = Path(path)
        text = self.to_toml()
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent or Path("."))
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                fh.write(text)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return path

    def to_dict(self) -> dict:
        return {"protocol": self.protocol.to_dict(), "tests": [t.to_dict() for t in self.tests], "axis": self.axis,
                "other_axis": self.other_axis, "range_deg": list(self.range_deg), "probe": self.probe,
                "duration_s": self.duration_s, "suspects": list(self.suspects), "conditions": self.conditions,
                "notes": list(self.notes)}


class NothingSuspectedError(ModelError):
    """``validate`` suspects nothing the next experiment could test."""


# ---------------------------------------------------------------------------- what the records show
def _half_cycles(data: HysteresisData) -> tuple[np.ndarray, np.ndarray]:
    """Duration (s) and peak |speed| (deg/s) of each half-cycle (reversal to reversal, within a record)."""
    turns = turning_points(data, 0.05)
    t = data.t_s if data.t_s is not None else np.arange(data.n_samples, dtype=float)
    durations, peaks = [], []
    for a, b in zip(turns[:-1], turns[1:]):
        if np.searchsorted(data.run_starts, a, side="right") != np.searchsorted(data.run_starts, b, side="right"):
            continue  # a record ends between them
        if t[b] > t[a]:
            durations.append(float(t[b] - t[a]))
            v = np.abs(np.diff(data.cmd_deg[a:b + 1]) / np.diff(t[a:b + 1]))
            peaks.append(float(v.max()) if v.size else 0.0)
    return np.asarray(durations), np.asarray(peaks)


def _typical_speed_dps(val: HysteresisData) -> float:
    """The validation record's typical knob speed: the median of its half-cycles' peak speeds (deg/s)."""
    _, peaks = _half_cycles(val)
    return float(np.median(peaks)) if peaks.size else 2.0 * math.pi * 0.05 * 0.5 * float(np.ptp(val.cmd_deg))


def _condition_column(train: HysteresisData, val: HysteresisData, axes: Sequence[str]) -> tuple[str, list[float]]:
    """The column a load condition is logged in, and the values the records hold.

    The one nonzero column both data hold constant (a condition the lab logs, the drives'
    own readings excluded; :func:`~endocal.validation.data.load_candidates`); else
    :data:`CONDITION`, a column the user logs from now on.
    """
    held = sorted(set(load_candidates(train, axes)[1]) & set(load_candidates(val, axes)[1]))
    held = [c for c in held if float(train.extras[c][0]) != 0.0]
    if len(held) != 1:
        return CONDITION, []
    col = held[0]
    values = sorted({round(float(v), 9) for v in np.concatenate([train.extras[col][train.run_starts],
                                                                 val.extras[col][val.run_starts]])})
    return col, values


# ---------------------------------------------------------------------------- speeds at stake
def _trial_data(model: HysteresisModel, cmd_deg: np.ndarray, t_s: np.ndarray, like: HysteresisData,
                run_starts: np.ndarray | None = None) -> HysteresisData:
    """A motion as data the model can predict: the other knob at rest, logged covariates as in ``like``."""
    read = {c for e in getattr(model, "effects_", []) if (c := getattr(e, "column", None))}
    extras = {OTHER_CMD: np.zeros(cmd_deg.size)}
    for c in read:
        if c in like.extras:
            extras[c] = np.full(cmd_deg.size, float(np.median(like.extras[c])))
    starts = {} if run_starts is None else {"run_starts": run_starts}
    return HysteresisData(cmd_deg=cmd_deg, meas_deg=None, t_s=t_s, extras=extras, **starts)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else 0.0


def speeds_at_stake(model: HysteresisModel, alternative: HysteresisModel, centre_deg: float, amplitude_deg: float,
                    speeds_dps: Sequence[float], like: HysteresisData, fs_hz: float = 100.0) -> list[float]:
    """RMS difference (deg) of two fitted models' predictions on a sine at each peak speed.

    Parameters
    ----------
    model, alternative : HysteresisModel
        The model as it stands and the model with the effect at stake, fitted on the same data.
    centre_deg, amplitude_deg : float
        The sine, within the models' fitted range.
    speeds_dps : sequence of float
        Peak knob speeds (deg/s): frequency ``v / (2 pi A)``.
    like : HysteresisData
        Gives the covariates the models read (their medians).

    Returns
    -------
    list of float
        Over the second and third of three cycles (the first carries the start).
    """
    out = []
    for v in speeds_dps:
        f = v / (2.0 * math.pi * amplitude_deg)
        t = np.arange(0.0, 3.0 / f, 1.0 / fs_hz)
        cmd = centre_deg + amplitude_deg * np.sin(2.0 * math.pi * f * t)
        trial = _trial_data(model, cmd, t, like)
        a, b = model.predict(trial), alternative.predict(trial)
        keep = t >= 1.0 / f
        out.append(_rms((a - b)[keep]))
    return out


# ---------------------------------------------------------------------------- the design
@dataclass(frozen=True)
class Planned:
    """What an effect's :meth:`~endocal.models.effects.base.Effect.segment` planned (a builder of
    :class:`Design` makes it).

    Attributes
    ----------
    segment : int or None
        1-based segment of the sequence that tests it; None for a condition of the whole run.
    half_cycles : int
        Half-cycles of this axis the test gets (0 for a condition: counted when the run is built).
    sized : str or None
        How that length was chosen, in words; None: the power calculation's words.
    note : str
        Set when nothing could be designed on this probe: why (the design's notes say it).
    deferred : bool
        Planned with other effects in one shared segment, built after every effect asked.
    effect : str or None
        The label the test is listed under when it is not the effect's name (``load:COLUMN``).
    """

    segment: int | None
    half_cycles: int
    sized: str | None = None
    note: str = ""
    deferred: bool = False
    effect: str | None = None


@dataclass
class Design:
    """The experiment being designed: where and how fast the knob may go, and builders of motions.

    An effect's ``segment(design, n_half_cycles)`` reads the motion envelope (``axis``, ``other``,
    ``lo``/``hi``, ``centre``, ``amplitude``, ``f_typ_hz``, :meth:`cap_hz`, the speed limits),
    adds segments (:meth:`add`) and returns :meth:`planned`; or asks a shared builder:
    :meth:`speeds` (one ladder of frequencies for every effect that asks), :meth:`full_range` (any
    segment sweeping the fitted range), :meth:`condition` (a condition of the run, at the earlier
    value and a new one); or says why it cannot (:meth:`cannot`).
    """

    axis: str
    other: str | None
    lo: float
    hi: float
    other_lo: float
    other_hi: float
    max_speed_dps: float
    max_start_dps: float  # a speed a goal may jump to from rest in one sample
    max_accel_dps2: float
    f_typ_hz: float  # frequency of a sine over the full range at the validation record's typical speed
    fs_hz: float = 100.0
    probe: str = ""
    segments: list = field(default_factory=list)
    tests: list = field(default_factory=list)
    #: the smallest sweep a designed motion makes about its centre (deg)
    min_amplitude_deg: float = MIN_AMPLITUDE_DEG
    #: records and condition columns the builders read (set by design_next)
    train: HysteresisData | None = None
    val: HysteresisData | None = None
    bending_axes: tuple = ()
    conditions: dict = field(default_factory=dict)
    speed_requests: dict = field(default_factory=dict)

    @property
    def centre(self) -> float:
        return 0.5 * (self.lo + self.hi)

    @property
    def amplitude(self) -> float:
        return 0.5 * (self.hi - self.lo) * (1.0 - 1e-9)

    def cap_hz(self, amplitude: float, start: bool = True) -> float:
        """Highest frequency of a sine of ``amplitude`` within the speed (and, ``start``: the start's) limits."""
        v = self.max_start_dps if start else self.max_speed_dps
        return min(v / (2.0 * math.pi * amplitude), math.sqrt(self.max_accel_dps2 / amplitude) / (2.0 * math.pi))

    def add(self, signal: str, **params) -> int:
        """Append a segment of the ``sequence`` (a signal of :data:`~endocal.protocols.SIGNALS` and its
        parameters); returns its 1-based number."""
        self.segments.append({"signal": signal, **params})
        return len(self.segments)

    @staticmethod
    def planned(segment: int | None, half_cycles: int, sized: str | None = None) -> Planned:
        """What a segment tests: its number, the half-cycles it gives, how it was sized (None: the power words)."""
        return Planned(segment, int(half_cycles), sized)

    @staticmethod
    def cannot(note: str) -> Planned:
        """Nothing designed for the effect on this probe, and why (in the design's notes)."""
        return Planned(None, 0, note=note)

    def speeds(self, effect: str, n_half_cycles: int) -> Planned:
        """The same sine at several frequencies, up to the probe's limits, shared by every effect that asks
        (a lag and friction growing with speed part at the speeds at stake: :func:`speeds_at_stake`)."""
        self.speed_requests[effect] = int(n_half_cycles)
        return Planned(None, 0, deferred=True)

    def full_range(self, n_half_cycles: int) -> Planned:
        """The full amplitude of the fitted range: the first segment on this axis that moves (every one
        sweeps the range), else a sine at the typical frequency."""
        on_axis = [i for i, s in enumerate(self.segments, 1) if self.axis in s["axes"] and s["signal"] != "hold"]
        if on_axis:
            k = on_axis[0]
            return Planned(k, next(t.half_cycles for t in self.tests if t.segment == k),
                           f"segment {k} sweeps the full fitted range [{self.lo:.4g}, {self.hi:.4g}] deg, as every "
                           "segment does")
        f = min(self.f_typ_hz, self.cap_hz(self.amplitude))
        cycles = max(1, math.ceil(n_half_cycles / 2))
        k = self.add("sine", axes=[self.axis], amplitude_deg=self.amplitude, offset_deg=self.centre,
                     frequency_hz=round(f, 6), cycles=cycles)
        return Planned(k, 2 * cycles)

    def condition(self, n_half_cycles: int, effect: str = "load") -> Planned:
        """A condition of the whole run, recorded at the records' earlier value and at a new one.

        A condition that changes only between records is confounded with them (their motion, their
        start, the base's misfit on them): the run's motion is recorded twice for fitting, once at
        the value the records hold and once at a new one (``excite --set``, :func:`excite_args`), so
        the same motion at two values shows what the condition does. When no column logs it, the user
        logs one from now on and records the run at two values of it.
        """
        col, recorded = _condition_column(self.train, self.val, self.bending_axes)
        earlier = ", ".join(f"{x:g}" for x in recorded)
        if col == CONDITION:
            instruction = ("change a condition the friction of the tendons depends on (the insertion tube's "
                           "curvature, a tendon's pretension, the lubrication) and give a number that measures it; "
                           "log it as a column of every record from now on (rename the column to say its unit); "
                           "record this run for fitting at two values of it, the same motion at each")
        else:
            instruction = (f"record this run for fitting twice, the same motion at two values of the condition "
                           f"'{col}' measures: at the earlier records' value ({earlier}) and at a value unlike "
                           "theirs (for the sheath's wrap: curve the insertion tube differently); give the value "
                           "each run has")
        self.conditions[col] = {"instruction": instruction, "recorded": recorded}
        if not self.segments:  # the condition alone: the validation record's kind of motion
            f = min(self.f_typ_hz, self.cap_hz(self.amplitude))
            cycles = max(1, math.ceil(n_half_cycles / 2))
            self.add("sine", axes=[self.axis], amplitude_deg=self.amplitude, offset_deg=self.centre,
                     frequency_hz=round(f, 6), cycles=cycles)
        at = f"at {earlier} (the earlier records') and at a new value" if recorded else "at two values"
        return Planned(None, 0, f"the whole run, the same motion {at}: {effect}:{col} is fitted on the same motion "
                                "at two values of the condition, so it cannot stand for a difference of motion "
                                "between the records", effect=f"{effect}:{col}")


def _ladder_hz(plan: Design, f_lo: float, f_hi: float) -> list[float]:
    """Frequencies from ``f_lo`` up to ``f_hi`` and back: at most doubling, and each step's jump of
    speed at the zero crossing where it happens within the acceleration limit (one sample)."""
    step_max = plan.max_start_dps / (2.0 * math.pi * plan.amplitude)
    up = [f_lo]
    while up[-1] < f_hi * (1 - 1e-9):
        up.append(min(up[-1] * 2.0, up[-1] + step_max, f_hi))
    while len(up) < 3:  # several frequencies, however close the ends
        up = list(np.geomspace(f_lo, max(f_hi, 2.0 * f_lo), 3))
    return [round(f, 6) for f in up + up[-2::-1]]


def _at_gain_seen(tested, scan) -> dict:
    """``gain_pct``, ``needed_half_cycles`` and ``needed`` of a :class:`PlannedTest`: what the paired
    test of the scan would need at the gain it saw for the effect (``tested``, a
    :class:`~endocal.validation.suspects.Suspect`, None when it was not tested)."""
    if tested is None:
        return {"gain_pct": None, "needed_half_cycles": None,
                "needed": "no gain seen: these records could not test it (its length is sized from the spread of "
                          "the model's half-cycle errors)"}
    gain = float(tested.gain_pct)
    est = tested.power
    if est is None:  # rolling origin: no per-half-cycle test to size
        return {"gain_pct": gain, "needed_half_cycles": None,
                "needed": "no estimate: the scan cross-validated on the validation data alone (rolling origin)"}
    words = evidence_phrase(est, "half-cycle", gain, scan.min_gain_pct)
    n = est.units_needed if words.startswith("about") else None
    return {"gain_pct": gain, "needed_half_cycles": n, "needed": words}


def _unit_errors(model: HysteresisModel, val: HysteresisData) -> tuple[np.ndarray, np.ndarray]:
    """Squared-error sums (deg^2) and RMSE (deg) of the model on each unit of the validation record."""
    err = predict_errors(model, val)
    units = make_units(val, [err])
    sse = np.array([float(np.sum(err[a:b] ** 2)) for a, b in units.bounds])
    return sse, np.sqrt(sse / np.array([b - a for a, b in units.bounds], dtype=float))


def _default_units(sse: np.ndarray, alpha: float, m: int, power: float) -> tuple[int, float]:
    """Half-cycles for an effect with no gain seen, and the coefficient of variation used (see the module)."""
    cv = float(sse.std(ddof=1) / sse.mean()) if sse.size > 1 and sse.mean() > 0 else 1.0
    cv = max(1.0, cv)
    return int(units_for_power(1.0, cv, alpha, m, power)), cv


def _targets(model: HysteresisModel, result, train: HysteresisData, val: HysteresisData,
             span_deg: float) -> dict[str, tuple[str, str]]:
    """Effect -> (status, why) of everything the next experiment should test."""
    scan = result.scan
    have = {lab.partition(":")[0] for lab in effect_labels(model)}
    out: dict[str, tuple[str, str]] = {}

    def put(effect: str, status: str, why: str) -> None:
        name = effect.partition(":")[0]
        per_column = name in EFFECTS and takes_column(name)  # one term per column: another column is another term
        if (name in have and not per_column) or effect in effect_labels(model):
            return
        out.setdefault(name if per_column else effect, (status, why))

    for effect, why in scan.untestable.items():
        put(effect, "untestable", why)
    for p in result.pointers:
        put(p.effect, p.status, f"{p.evidence}; {p.why}")
    for s in scan.tested:
        if not s.significant and s.gain_pct >= scan.min_gain_pct:
            put(s.effect, "not significant", f"-{s.gain_pct:.0f} % validation RMSE, {s.evidence}")
    suggested = {sp.effect for sp in result.suspects}
    for x in getattr(scan, "lookalikes", ()):  # a suggestion its look-alike is not told from: separate them
        if not x.settled:
            put(x.lookalike, "look-alike", x.words())
    for name, cls in EFFECTS.items():  # what --next considers whatever validate said (rate, delay: the speeds)
        if cls.at_stake is not None and name not in suggested:
            put(name, *cls.at_stake)
    for name, cls in EFFECTS.items():  # what the effect needs to be told from a wider loop, in no record
        if name in have or cls.at_stake is not None:
            continue
        for req in cls.requires:
            if req.to == "test" and req.check(train) is not None and req.check(val) is not None:
                put(name, req.status, f"no record holds {req.words}, where {name} shows itself")
                break
    for name, cls in EFFECTS.items():  # what only the next records can reach (the full amplitude)
        if name in have:
            continue
        for req in cls.requires:
            if req.to == "next" and (why := req.check(val, span_deg=span_deg)) is not None:
                put(name, req.status, f"{why[0]}: {name} is not tested there")
                break
    if result.unexplained and not result.suspects:
        put("shape", "unexplained", result.unexplained)
    return out


def motion_range(model: HysteresisModel, probe: ProbeConfig, axis: str | None = None) -> tuple[float, float]:
    """The knob range (deg) a designed motion may use: the model's fitted range within the probe's limits.

    Raises
    ------
    ModelError
        The model's drive is not a knob commanded in deg (a linear drive in mm: ``excite`` drives
        knobs only); the model's axis is not a knob of ``probe``; or the range does not hold the rest position
        0 every protocol starts and ends at, or is too narrow for a sweep of
        :data:`MIN_AMPLITUDE_DEG` (the message names the range).
    """
    axis = axis or model.axis
    unit = getattr(model, "drive_unit_", "deg")
    if unit != "deg":
        raise ModelError(f"the model's {axis} drive is commanded in {unit} (a linear drive), and --next designs "
                         "protocols for a probe's knobs in deg, the only drives `excite` moves: nothing written; "
                         "`validate --explain` names the experiment each untested effect needs, to record on "
                         "your rig")
    if axis not in probe.bending_axes:
        raise ModelError(f"the model is of axis '{axis}', which probe '{probe.name}' does not have (its knobs: "
                         f"{', '.join(probe.bending_axes)}): give the probe the records were made on (--probe)")
    lo, hi = (float(x) for x in model.cmd_range_deg_)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ModelError("the model records no fitted range (cmd_range_deg_): refit it on recorded data")
    p_lo, p_hi = probe.knob_limits_deg[axis]
    e_lo, e_hi = max(lo, p_lo), min(hi, p_hi)
    where = (f"the model was fitted on commands in [{lo:.4g}, {hi:.4g}] deg (cmd_range_deg_)"
             + (f", within the probe's limits [{e_lo:.4g}, {e_hi:.4g}]" if (e_lo, e_hi) != (lo, hi) else ""))
    if not e_lo <= 0.0 <= e_hi:
        raise ModelError(f"{where}, which does not hold the rest position 0 every protocol starts and ends at: no "
                         "motion can stay inside it; refit on records that start at rest")
    if 0.5 * (e_hi - e_lo) < MIN_AMPLITUDE_DEG:
        raise ModelError(f"{where}: too narrow for a sweep of +-{MIN_AMPLITUDE_DEG:g} deg, the least a designed "
                         "motion needs to leave a tendon drive's dead band; refit on records that sweep the knob "
                         "wider")
    return e_lo, e_hi


def design_next(model: HysteresisModel, result, train: HysteresisData, val: HysteresisData, probe: ProbeConfig, *,
                name: str = "next", model_path: str | None = None, power: float = POWER,
                max_samples: int = MAX_SCAN_SAMPLES) -> NextExperiment:
    """The protocol that would settle what ``validate`` could not, sized from what it saw.

    Parameters
    ----------
    model : HysteresisModel
        The model validated (its fitted range ``cmd_range_deg_`` bounds every motion).
    result : ValidationResult
        :func:`~endocal.validation.offline.validate_offline` of ``model`` on ``val``, estimation
        data ``train``.
    train, val : HysteresisData
        The model's axis in the estimation and the validation data
        (:func:`~endocal.validation.data.axis_data`).
    probe : ProbeConfig
        The probe the protocol is for: its knob limits, speed and acceleration bound the design.
    name : str
        The protocol's name.
    model_path : str, optional
        Recorded in the protocol's ``[design]``.
    power : float
        Probability the designed lengths aim at (:mod:`endocal.validation.power`).
    max_samples : int
        Estimation data is decimated to about this many samples for the fits the design makes
        (the alternative of the speeds at stake), as the scan does.

    Returns
    -------
    NextExperiment

    Raises
    ------
    NothingSuspectedError
        Nothing is suspected: no suspect the data could not settle, no effect they cannot test.
    ModelError
        The model's axis is not a knob of ``probe``, or its fitted range (within the probe's
        limits) does not hold the rest position 0 every protocol starts and ends at, or is
        too narrow for a sweep of :data:`MIN_AMPLITUDE_DEG`.
    """
    scan = result.scan
    axis = model.axis or result.axis
    e_lo, e_hi = motion_range(model, probe, axis)
    lo, hi = (float(x) for x in model.cmd_range_deg_)
    targets = _targets(model, result, train, val, hi - lo)
    if not targets:
        raise NothingSuspectedError(
            "nothing is suspected: no suggestion the data could not settle, no effect the data cannot test, and the "
            "residual points at nothing; no protocol written")
    others = [a for a in probe.bending_axes if a != axis]
    other = others[0] if others else None
    fs = 100.0
    plan = Design(axis, other, e_lo, e_hi, *(probe.knob_limits_deg[other] if other else (0.0, 0.0)),
                  max_speed_dps=LIMIT_SHARE * probe.max_knob_speed_dps,
                  max_start_dps=LIMIT_SHARE * probe.max_knob_accel_dps2 / fs,
                  max_accel_dps2=LIMIT_SHARE * probe.max_knob_accel_dps2, f_typ_hz=0.0, probe=probe.name,
                  train=train, val=val, bending_axes=tuple(probe.bending_axes))
    # the motions are played at the validation record's typical speed (over the full range: a lower frequency)
    plan.f_typ_hz = min(_typical_speed_dps(val) / (2.0 * math.pi * plan.amplitude), plan.cap_hz(plan.amplitude))
    m = max(1, sum(1 for e in EFFECTS if e not in {lab.partition(":")[0] for lab in effect_labels(model)}))
    alpha = scan.alpha
    sse, unit_rmse = _unit_errors(model, val)
    n_default, cv = _default_units(sse, alpha, m, power)
    # the error of the model where it is right: its best tenth of the validation record's units (a record
    # designed for one effect is scored against that, not against a misfit elsewhere)
    best_deg = float(np.percentile(unit_rmse, 10)) if unit_rmse.size else scan.baseline_rmse_heldout_deg
    seen = {s.effect: s for s in scan.tested}
    notes: list[str] = []

    def size(effect: str) -> tuple[int, str]:
        s = seen.get(effect)
        est = getattr(s, "power", None) if s is not None else None
        unseen = (f"{n_default} half-cycles: the paired test reaches {alpha:g}/{m} with {100 * power:.0f} % power "
                  f"if the effect lowers every half-cycle's error by the same share (this model's error varies "
                  f"between half-cycles by a coefficient of variation of {cv:.2g}, taken as at least 1)")
        # a gain under the bar says nothing of the effect where the design looks for it (faster, at
        # the full amplitude): only a gain that clears the bar but lacks units sizes the test
        if est is not None and est.units_needed is not None and s.gain_pct >= scan.min_gain_pct:
            n = max(n_default, int(est.units_needed))
            return n, (f"{n} half-cycles: at the gain seen (-{s.gain_pct:.0f} %, {s.evidence}) the paired test needs "
                       f"{est.units_needed} for {alpha:g}/{m} with {100 * est.power:.0f} % power; at least "
                       + unseen)
        return n_default, unseen

    c, A = plan.centre, plan.amplitude
    # each effect's own segment (Effect.segment), in its segment_order: the shared speed ladder after the
    # dedicated motions, then more of the validation record's motion for candidates short of units, then
    # the segments that reuse the others' (the full amplitude, a condition of the whole run)
    def entry(effect: str):  # the catalogue's class of a target (a variant, deadzone:tip, is its effect's)
        return EFFECTS.get(effect.partition(":")[0])

    order = sorted(targets, key=lambda e: entry(e).segment_order if entry(e) is not None else 50)
    own: set[str] = set()
    phase = {"speeds": False, "short": False}

    def flush(upto: int) -> None:
        if upto > 60 and not phase["speeds"]:
            phase["speeds"] = True
            if plan.speed_requests:
                at_stake = {e: (*targets[e], n, size(e)[1]) for e, n in plan.speed_requests.items()}
                _speed_segment(plan, model, train, val, at_stake, scan, notes, max_samples, best_deg)
        if upto > 80 and not phase["short"]:
            phase["short"] = True
            _short_segment(plan, val, targets, own, size)

    for effect in order:
        status, why = targets[effect]
        n, sized = size(effect)
        if effect == "shape":  # a residual no catalogue effect lowers: the loop at two amplitudes and three speeds
            f = plan.f_typ_hz
            periods = [round(1.0 / f2, 3) for f2 in (f / 2.0, f, min(2.0 * f, plan.cap_hz(A)))]
            cycles = max(1, math.ceil(n / (2 * 2 * len(periods))))
            k = plan.add("sine-set", axes=[axis], amplitudes_deg=[round(A / 2.0, 6), A], periods_s=periods,
                         cycles=cycles, offset_deg=c)
            plan.tests.append(PlannedTest(effect, status, why, k, 2 * 2 * len(periods) * cycles,
                                          f"the loop at two amplitudes and three speeds ({sized})"))
            continue
        cls = entry(effect)
        flush(cls.segment_order)
        try:
            inst = make_effect(effect)
        except ModelError:  # an effect that takes its column (load): the class's segment names it
            inst = cls.__new__(cls)
        got = inst.segment(plan, n)
        if got is None:
            if status != "not significant":  # more of the validation record's motion covers that one
                notes.append(f"{effect}: no segment of its own; record {cls.protocol}")
            continue
        if cls.segment_order <= 80:
            own.add(effect)
        if got.note:
            notes.append(f"{effect}: {got.note}")
        elif not got.deferred:
            plan.tests.append(PlannedTest(got.effect or effect, status, why, got.segment, got.half_cycles,
                                          got.sized if got.sized is not None else sized))
    flush(100)
    if not plan.segments:
        raise NothingSuspectedError(
            "nothing the next experiment can test: " + "; ".join(notes) + "; no protocol written")
    plan.tests = [dataclasses.replace(t, **_at_gain_seen(seen.get(t.effect), scan)) for t in plan.tests]
    return _finish(plan, name, plan.conditions, model, model_path, probe, notes, alpha, power)


def _short_segment(plan: Design, val: HysteresisData, targets: dict, own: set, size) -> None:
    """More of the validation record's kind of motion (``random`` in its band), as long as the power
    calculation asks, for the candidates short of units that have no dedicated segment of their own."""
    short = [(e, st, w) for e, (st, w) in targets.items() if st == "not significant" and e not in own]
    if not short:
        return
    A, c = plan.amplitude, plan.centre
    durations, _ = _half_cycles(val)
    n = max(size(e)[0] for e, _, _ in short)
    med = float(np.median(durations)) if durations.size else 1.0 / (2.0 * plan.f_typ_hz)
    f_hi = min(1.0 / (2.0 * float(np.percentile(durations, 10))) if durations.size else 2 * plan.f_typ_hz,
               plan.cap_hz(A))
    f_lo = min(1.0 / (2.0 * float(np.percentile(durations, 90))) if durations.size else plan.f_typ_hz / 4, f_hi / 2)
    duration = max(math.ceil(n * med), math.ceil(2.0 / f_lo))
    k = plan.add("random", axes=[plan.axis], amplitude_deg=A, offset_deg=c, f_lo_hz=round(f_lo, 6),
                 f_hi_hz=round(f_hi, 6), duration_s=float(duration))
    for e, st, w in short:
        plan.tests.append(PlannedTest(e, st, w, k, int(duration / med), size(e)[1]))


def _speed_segment(plan: Design, model, train, val, at_stake: dict, scan, notes, max_samples, best_deg) -> None:
    """The same sine at several frequencies, up to the probe's limits, for the effects at stake (``rate``,
    ``delay``: ``effect -> (status, why, half-cycles, sized)``) that, fitted on the estimation data,
    change the prediction somewhere within the limits by what the gain bar asks of a record where the
    model is otherwise right (``best_deg``, its best units' RMSE) (:func:`speeds_at_stake`); effects no
    speed within the limits tells apart get a note instead."""
    have = effect_labels(model)
    A, c = plan.amplitude, plan.centre
    _, peaks = _half_cycles(val)
    v_val = float(np.percentile(peaks, 90)) if peaks.size else 2.0 * math.pi * plan.f_typ_hz * A
    v_cap = 2.0 * math.pi * A * plan.cap_hz(A, start=False)
    g = scan.min_gain_pct / 100.0
    need = math.sqrt(1.0 - (1.0 - g) ** 2) * best_deg
    stride = scan_stride(train, max_samples)
    grid = list(np.geomspace(max(v_val, 1.0), v_cap, 10)) if v_cap > v_val else [v_cap]
    tops = {}
    for effect, (status, why, n, sized) in at_stake.items():
        try:
            alt = split_fit(model, have + [effect], train, stride, ftol=scan_ftol(stride))
        except ModelError as exc:
            tops[effect] = (v_cap, sized + f"; {effect} could not be fitted on the estimation data ({exc}), so the "
                            f"segment reaches {v_cap:.3g} deg/s, the most the probe's limits allow")
            continue
        trial = _trial_data(model, val.cmd_deg, val.t_s, val, val.run_starts)
        on_val = _rms(alt.predict(trial) - model.predict(trial))
        diffs = speeds_at_stake(model, alt, c, A, grid, val)
        # the alternative fitted on the estimation data says whether a difference worth a term is possible
        # within the limits; where it is, the ladder climbs to the limits: a lag's shift grows linearly with
        # speed, friction growing with speed exponentially (the capstan), so the fastest rungs tell them
        # apart, and the slower ones give the curve's shape (the alternative, fitted where the two look
        # alike, cannot say where they part)
        top = v_cap if max(diffs) >= need else None
        if top is None:
            notes.append(f"{effect}: fitted on the estimation data, it moves the prediction by at most "
                         f"{max(diffs):.2g} deg on a sine up to {v_cap:.3g} deg/s (the probe's limits), under the "
                         f"{need:.2g} deg a {scan.min_gain_pct:g} % gain needs where the model errs by "
                         f"{best_deg:.2g} deg: the data so far settle it")
            continue
        first = next(v for v, d in zip(grid, diffs) if d >= need)
        tops[effect] = (top, sized + f"; up to {top:.3g} deg/s, the most the probe's limits allow: {effect} fitted on "
                        f"the estimation data moves the prediction by {need:.2g} deg RMS (what a "
                        f"{scan.min_gain_pct:g} % gain needs) from {first:.3g} deg/s on, and by {on_val:.2g} on the "
                        f"validation record (up to {v_val:.3g} deg/s)")
    if not tops:
        return
    top = max(v for v, _ in tops.values())
    n = max(at_stake[e][2] for e in tops)
    f_top = top / (2.0 * math.pi * A)
    v_slow = float(np.percentile(peaks, 10)) if peaks.size else 0.25 * top  # the validation record's slow half-cycles
    freqs = _ladder_hz(plan, min(v_slow / (2.0 * math.pi * A), f_top / 4.0), f_top)
    cycles = max(1, math.ceil(n / (2 * len(freqs))))
    k = plan.add("sine-varying", axes=[plan.axis], amplitude_deg=A, offset_deg=c, frequencies_hz=freqs,
                 cycles=cycles)
    for effect, (_, sized) in tops.items():
        status, why = at_stake[effect][:2]
        plan.tests.append(PlannedTest(effect, status, why, k, 2 * cycles * len(freqs), sized))


def _finish(plan: Design, name, conditions, model, model_path, probe, notes, alpha, power) -> NextExperiment:
    axes = [plan.axis] + ([plan.other] if plan.other and any(plan.other in s["axes"] for s in plan.segments) else [])
    tests = tuple(plan.tests)
    suspects = list(dict.fromkeys(t.effect for t in tests))
    design = {"model": str(model_path) if model_path else "", "axis": plan.axis, "base": model.base_name,
              "effects": effect_labels(model), "fitted_range_deg": [plan.lo, plan.hi], "probe": probe.name,
              "suspects": suspects, "alpha": alpha, "power": power,
              "tests": [{k: v for k, v in t.to_dict().items() if v is not None} for t in tests]}
    where = f"the next experiment for axis {plan.axis}"
    try:
        params = SIGNALS["sequence"].resolve({"axes": axes, "segments": plan.segments}, where)
        proto = Protocol(name, f"Next experiment for {model.base_name} on {plan.axis}: tests {', '.join(suspects)}",
                         "sequence", params, conditions=conditions, design=design)
        traj = proto.trajectory(probe)
        traj.check_limits(probe)
    except (ProtocolError, LimitError) as exc:  # a design beyond what it checked itself: a bug, said plainly
        raise ModelError(f"{where} breaks a limit it was designed within ({exc})") from None
    goal = traj.goal[plan.axis]
    whole = int(turning_points(HysteresisData(cmd_deg=goal, meas_deg=None, t_s=traj.t_s), 0.05).size) + 1
    tests = tuple(t if t.segment is not None else dataclasses.replace(t, half_cycles=whole) for t in tests)
    proto = dataclasses.replace(proto, design={**design, "tests": [{k: v for k, v in t.to_dict().items()
                                                                    if v is not None} for t in tests]})
    return NextExperiment(proto, tests, plan.axis, plan.other, (plan.lo, plan.hi), probe.name, tuple(notes))


# ---------------------------------------------------------------------------- validate --next
def records_probe(tables: Sequence, fallback: str | Path | None = "tee") -> ProbeConfig:
    """The probe the validation records were made on (their ``run.json``), else ``fallback``
    (a preset name or a probe ``.toml``: ``--probe``)."""
    for a in tables:
        if isinstance(getattr(a, "meta", None), dict) and isinstance(a.meta.get("probe"), dict):
            return ProbeConfig.from_dict(a.meta["probe"], where=f"{a.source} (run.json)")
    return load_probe(fallback)


def check_next(model: HysteresisModel, tables: Sequence, probe: str | Path | None = "tee") -> None:
    """Refuse ``--next`` before the validation runs when no motion can stay inside the model's fitted
    range on the records' probe (:func:`motion_range`; raises its ModelError)."""
    motion_range(model, records_probe(tables, probe))


@dataclass(frozen=True)
class NextOutcome:
    """What ``validate --next PATH`` did: the experiment it wrote, or why it wrote none.

    Attributes
    ----------
    path : Path or None
        The protocol file written (None: nothing is suspected, nothing written).
    experiment : NextExperiment or None
        The design: what it tests, each test's half-cycles and what the paired test needs at
        the gain seen (:class:`PlannedTest`).
    reason : str
        Why nothing was written (empty when ``path`` is set).
    excite : tuple of tuple of str
        The two ``endocal excite`` command lines (argument lists) that record it: once to add
        to the estimation data, once (another seed) to validate on; a condition only the
        user can set is ``--set NAME=VALUE``.
    """

    path: Path | None
    experiment: NextExperiment | None
    reason: str = ""
    excite: tuple[tuple[str, ...], ...] = ()

    @property
    def written(self) -> bool:
        return self.path is not None

    def to_dict(self) -> dict:
        """``next`` of ``endocal validate --json --next``: the file, what it is for, each effect's
        half-cycles (planned, and needed at the gain seen), the excite command lines; or
        ``nothing_suspected`` with no file."""
        if self.experiment is None:
            return {"path": None, "written": False, "nothing_suspected": self.reason, "suspects": [], "tests": [],
                    "excite": []}
        nx = self.experiment
        return {"path": str(self.path), "written": True, "nothing_suspected": None, "suspects": list(nx.suspects),
                "tests": [t.to_dict() for t in nx.tests], "probe": nx.probe, "duration_s": nx.duration_s,
                "axis": nx.axis, "range_deg": list(nx.range_deg), "conditions": nx.conditions, "notes": list(nx.notes),
                "excite": [list(a) for a in self.excite]}


def excite_args(path: str | Path, nx: NextExperiment) -> tuple[tuple[str, ...], ...]:
    """The ``endocal excite`` argument lists that record ``nx`` written at ``path``: ``STEM-fit``
    (estimation) and ``STEM-val`` (validation, seed 1), run folders beside the protocol file; with a
    condition, a third, ``STEM-fit-earlier``: the same motion (the same seed) at the value the earlier
    records hold (``VALUE0`` when they log none: a second value of the user's choosing), so the
    estimation data hold the same motion at two values of the condition (:meth:`Design.condition`)."""
    path = Path(path)
    args = ["endocal", "excite", str(path)] + (["--probe", nx.probe] if nx.probe != "tee" else [])
    sets = [a for k in nx.conditions for a in ("--set", f"{k}=VALUE")]
    out = ((*args, "--out", str(path.with_name(f"{path.stem}-fit")), *sets),
           (*args, "--out", str(path.with_name(f"{path.stem}-val")), "--seed", "1", *sets))
    if not nx.conditions:
        return out
    earlier = [a for k, c in nx.protocol.conditions.items()
               for a in ("--set", f"{k}={c['recorded'][0]:g}" if c["recorded"] else f"{k}=VALUE0")]
    return (*out, (*args, "--out", str(path.with_name(f"{path.stem}-fit-earlier")), *earlier))


def write_next(model: HysteresisModel, result, tables: Sequence, train_tables: Sequence | None, planes,
               path: str | Path, *, probe: str | Path | None = "tee", model_path: str | Path | None = None) -> NextOutcome:
    """Design the next experiment for a validation (:func:`design_next`) and write it to ``path``.

    Parameters
    ----------
    model : HysteresisModel
    result : ValidationResult
        Its validation on ``tables``.
    tables, train_tables : sequence of AlignedData
        The validation and estimation records (None: the scan had no estimation data; the
        validation records stand in).
    planes : PlanesCalibration or None
        The planes the model was fitted through.
    path : path
        The protocol file to write (whole or not at all).
    probe : str or path
        The probe when the records name none (``--probe``).
    model_path : path, optional
        Recorded in the protocol's ``[design]``.

    Returns
    -------
    NextOutcome
        With ``path`` None and ``reason`` set when nothing is suspected (nothing written).

    Raises
    ------
    ModelError
        A fitted range no motion fits in (:func:`motion_range`).
    """
    from endocal.validation.data import axis_data

    probe_cfg = records_probe(tables, probe)
    val = axis_data(tables, result.axis, planes)
    train = axis_data(train_tables, result.axis, planes) if train_tables else val
    path = Path(path)
    try:
        nx = design_next(model, result, train, val, probe_cfg, name=path.stem,
                         model_path=None if model_path is None else str(model_path))
    except NothingSuspectedError as exc:
        return NextOutcome(None, None, str(exc))
    nx.write(path)
    return NextOutcome(path, nx, "", excite_args(path, nx))
