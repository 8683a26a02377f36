"""The state a record starts in, estimated from the record (an initial condition).

Every model starts each record in an assumed state: its play operators as if the knob had come
straight from 0 (the duodenoscope paper's eq. 5 start), the B-spline on the mid-line between its
branches. A knob homed and relaxed before an acquisition has that state. A record cut from a
longer one, or started where the last acquisition left the knob, has the state its history left:
until the first reversal wipes it out the model follows the wrong branch, and that stretch
measures the start, not the physics (on the piezo recording, 6.2 before the first reversal
against 0.87 after; a candidate effect that follows time, drift or creep, fits it).

System-identification tools estimate the initial state from the data they score
(MATLAB's ``compare`` does by default). For a rate-independent hysteresis the state at the
start is set by the last turning points (the wiping-out property), so three histories cover the
usual records, each run as a **lead-in** at the record's own typical step, whose prediction is
run but not scored (:func:`lead_in_paths`): the knob came straight from 0 (a homed knob; the
B-spline's mid-line start is not that), the record was cut from a periodic motion, the knob
taken along ``u0 -> far end -> near end -> u0`` (the end it moves towards first is the far one),
or the last acquisition swept the other way to the mirror of this one's far end (one sweep per
acquisition, each direction in turn).
A lead-in is taken when it lowers the record's RMSE by :data:`START_GAIN_MIN` and explains the
stretch before the first reversal (:data:`EXPLAINED_RATIO`); else the record keeps the rest
start. One choice per record, a discrete initial condition, not a parameter fitted on the
validation data.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from endocal.models.data import HysteresisData

#: The lead-in must lower a record's RMSE by this fraction to be taken: a record that starts
#: from rest gains nothing but noise from it, and keeps the start every model assumes.
START_GAIN_MIN = 0.05

#: The estimated start must leave the record's stretch before its first reversal at most this
#: many times the error after it, or take away all but 1/this of its error from rest. A start
#: that leaves it far worse did not find the record's state (a step from rest, the servo
#: catching up with a jump of the command at the first sample: 7.0 against 0.4 deg on a
#: simulated record, 7.9 from rest): both starts are wrong there, and choosing one would only
#: trade one error for another (and pull the fit's delay from 0.15 to 0.17 s).
EXPLAINED_RATIO = 3.0

#: A fit from rest tries each history as a start of its own (:func:`assumed_starts`) when the
#: stretches before the runs' first reversals hold at least this fraction of the samples: there
#: they pull the parameters until the rest fit predicts the wrong start as well as the right one
#: (the paper's PI cut at 47.6 deg on the way down, one cycle, 45 % before its first reversal:
#: 0.48 deg from rest, the added noise 0.29 from the right start, which the rest fit's estimate
#: missed); with 9 % (five cycles) the estimate from the rest fit finds the start.
FIT_HISTORY_FRACTION = 0.1

#: A lead-in is at most this many times its record's length (a record that barely moves and
#: then sweeps far would otherwise get a lead-in of its sweep at its resting step).
MAX_LEAD_RATIO = 4


@dataclass(frozen=True)
class RecordStart:
    """The start estimated for one record (run) of the data.

    Attributes
    ----------
    run : int
        Index of the run in the data.
    path_deg : tuple of float
        The knob's assumed path before the record (its lead-in's turning points), deg.
    n_lead : int
        Samples of the lead-in.
    rmse_rest_deg, rmse_estimated_deg : float
        The record's RMSE from the rest start and from the estimated one.
    """

    run: int
    path_deg: tuple[float, ...]
    n_lead: int
    rmse_rest_deg: float
    rmse_estimated_deg: float

    def to_dict(self) -> dict:
        return {"run": self.run, "path_deg": [round(x, 6) for x in self.path_deg], "n_lead": self.n_lead,
                "rmse_rest_deg": self.rmse_rest_deg, "rmse_estimated_deg": self.rmse_estimated_deg}

    @classmethod
    def from_dict(cls, d: dict) -> RecordStart:
        return cls(int(d["run"]), tuple(float(x) for x in d["path_deg"]), int(d["n_lead"]),
                   float(d["rmse_rest_deg"]), float(d["rmse_estimated_deg"]))

    def describe(self, cmd_unit: str = "deg") -> str:
        """``"as if the knob had come 1.8 -> 0 -> 3.6 -> 1.8 deg before it (RMSE 3.2 deg from the
        model's relaxed start, 0.53 deg from this one)"``; the path in ``cmd_unit`` (mm for a linear drive)."""
        path = " -> ".join(f"{x:.3g}" for x in self.path_deg)
        return (f"as if the knob had come {path} {cmd_unit} before it (RMSE {self.rmse_rest_deg:.3g} deg from the "
                f"model's relaxed start, {self.rmse_estimated_deg:.3g} deg from this one)")


#: The histories tried for a record's start, by name (:func:`lead_in_paths`).
HISTORIES = ("homed", "periodic", "mirrored")


def lead_in_paths(cmd_deg: np.ndarray) -> dict[str, tuple[float, ...]]:
    """The turning points of each lead-in tried for a record, by history (none for a still record).

    - ``homed``: the knob came straight from 0 (as a homed knob does; the PI's own start, not
      the B-spline's mid-line); not tried for a record that starts at 0.
    - ``periodic``: the record was cut from a periodic motion: the end it moves towards first
      is the far one, so a record moving up from ``u0`` came up from its low end, and down to
      it from its high end (``u0``, high, low, ``u0``).
    - ``mirrored``: the last acquisition swept the other way, one sweep per acquisition as
      labs record a knob's two directions: a record that moves up to ``hi`` from ``u0`` came
      back to ``u0`` from ``-hi`` (the tip still bent the other way); tried only where ``-hi``
      lies beyond the record's own range.
    """
    u = np.asarray(cmd_deg, dtype=float)
    span = float(np.ptp(u))
    if not span > 0.0:
        return {}
    moved = np.flatnonzero(np.abs(u - u[0]) > 0.01 * span)
    if not moved.size:
        return {}
    lo, hi, u0 = float(u.min()), float(u.max()), float(u[0])
    up = u[moved[0]] > u0
    cut = (u0, hi, lo, u0) if up else (u0, lo, hi, u0)
    paths = {"homed": (0.0, u0)} if abs(u0) > 0.01 * span else {}
    paths["periodic"] = tuple(x for i, x in enumerate(cut) if i == 0 or x != cut[i - 1])  # at an end: one leg less
    mirror = -hi if up else -lo
    if (mirror < lo - 0.01 * span) if up else (mirror > hi + 0.01 * span):
        paths["mirrored"] = (u0, mirror, u0)
    return paths


def assumed_starts(data: HysteresisData, history: str) -> list[RecordStart]:
    """Every run that turns back started along one of :data:`HISTORIES` (runs it does not
    apply to keep the rest start). Their RMSEs are NaN until a model scores them (:func:`rescored`)."""
    starts = []
    for r, sl in enumerate(data.run_slices()):
        u = data.cmd_deg[sl]
        path = lead_in_paths(u).get(history) if first_reversal(u) is not None else None
        if path:
            starts.append(RecordStart(r, path, _lead_length(u, path), math.nan, math.nan))
    return starts


def first_stretch_fraction(data: HysteresisData) -> float:
    """The fraction of ``data``'s samples before each run's first reversal (runs that never turn: all)."""
    total = 0
    for sl in data.run_slices():
        k = first_reversal(data.cmd_deg[sl])
        total += (sl.stop - sl.start) if k is None else k
    return total / max(data.n_samples, 1)


def first_reversal(cmd_deg: np.ndarray, tol_frac: float = 0.01) -> int | None:
    """Index of a record's first turning point (the command turns back by ``tol_frac`` of its
    span), or None when it never turns (or holds fewer than 2 samples after it)."""
    u = np.asarray(cmd_deg, dtype=float)
    tol = tol_frac * float(np.ptp(u))
    moved = np.flatnonzero(np.abs(u - u[0]) > tol)
    if not moved.size:
        return None
    sign = 1.0 if u[moved[0]] > u[0] else -1.0
    peak = np.maximum.accumulate(sign * u)
    back = np.flatnonzero(peak - sign * u > tol)
    if not back.size:
        return None
    k = int(np.argmax(sign * u[: back[0]]))
    return k if 2 <= k <= u.size - 2 else None


def with_lead_in(run: HysteresisData, path: tuple[float, ...]) -> HysteresisData:
    """One run with the lead-in along ``path`` before it (``lead_in`` samples set the state only).

    The lead-in steps at the run's median moving step and sample interval; extra columns (the
    other knob, covariates) hold their first value.
    """
    u = run.cmd_deg
    legs = np.abs(np.diff(path))
    n = _lead_length(u, path)
    s = np.linspace(0.0, float(legs.sum()), n, endpoint=False)
    lead = np.interp(s, np.concatenate([[0.0], np.cumsum(legs)]), path)
    t = None
    if run.t_s is not None:
        dt = float(np.median(np.diff(run.t_s))) if run.n_samples > 1 else 1.0
        t = np.concatenate([run.t_s[0] - dt * np.arange(n, 0, -1), run.t_s])
    return HysteresisData(
        cmd_deg=np.concatenate([lead, u]),
        meas_deg=None if run.meas_deg is None else np.concatenate([np.full(n, run.meas_deg[0]), run.meas_deg]),
        t_s=t, extras={k: np.concatenate([np.full(n, v[0]), v]) for k, v in run.extras.items()},
        lead_in=np.array([n]), drive_unit=run.drive_unit,
    )


def _lead_length(u: np.ndarray, path: tuple[float, ...]) -> int:
    """Samples of the lead-in along ``path`` at the median moving step of ``u``."""
    steps = np.abs(np.diff(u))
    moving = steps[steps > 1e-3 * float(np.ptp(u))]
    step = float(np.median(moving)) if moving.size else float(np.ptp(u)) / max(u.size - 1, 1)
    return min(max(int(math.ceil(float(np.abs(np.diff(path)).sum()) / step)), 1), MAX_LEAD_RATIO * u.size)


def with_lead_ins(data: HysteresisData, starts: list[RecordStart]) -> tuple[HysteresisData, np.ndarray]:
    """``data`` (without lead-ins) with the lead-ins of ``starts`` before their runs, and the
    indices of its own samples."""
    if not starts:
        return data, np.arange(data.n_samples)  # no lead-in to add: not a copy of every column
    by_run = {s.run: s for s in starts}
    parts, keep, offset = [], [], 0
    for r, sl in enumerate(data.run_slices()):
        run = _run_view(data, sl)
        if r in by_run:
            run = with_lead_in(run, by_run[r].path_deg)
        n_lead = int(run.lead_in[0])
        parts.append(run)
        keep.append(offset + n_lead + np.arange(sl.stop - sl.start))
        offset += run.n_samples
    return HysteresisData.from_runs(parts), np.concatenate(keep)


def estimate_starts(predict: Callable[[HysteresisData], np.ndarray], data: HysteresisData,
                    pred_rest: np.ndarray | None = None) -> tuple[np.ndarray, list[RecordStart]]:
    """Each run's start, rest or lead-in, whichever predicts it better (module docstring).

    Parameters
    ----------
    predict : callable
        The model's prediction (deg) of a :class:`HysteresisData`.
    data : HysteresisData
        With the measured angle.
    pred_rest : (n,) array, optional
        ``predict(data)`` when the caller has it.

    Returns
    -------
    pred_deg : (n,) array
        The prediction from the chosen starts.
    starts : list of RecordStart
        The runs whose start was estimated (an empty list: every run starts from rest).
    """
    pred = np.array(predict(data) if pred_rest is None else pred_rest, dtype=float)
    if data.meas_deg is None:
        return pred, []
    starts = []
    for r, sl in enumerate(data.run_slices()):
        own = _run_view(data, sl)
        k = first_reversal(own.cmd_deg)
        if k is None:
            continue
        y = data.meas_deg[sl]
        rest = best = _rms(pred[sl] - y)
        for path in lead_in_paths(own.cmd_deg).values():
            run = with_lead_in(own, path)
            n = int(run.lead_in[0])
            alt = np.asarray(predict(run), dtype=float)[n:]
            est = _rms(alt - y)
            first, after, first_rest = _rms(alt[:k] - y[:k]), _rms(alt[k:] - y[k:]), _rms(pred[sl][:k] - y[:k])
            explained = first <= max(EXPLAINED_RATIO * after, first_rest / EXPLAINED_RATIO)
            if est < (1.0 - START_GAIN_MIN) * rest and est < best and explained:
                best, pred[sl] = est, alt
                chosen = RecordStart(r, path, n, rest, est)
            del run, alt  # before the next lead-in's copy of the record is made
        if best < rest:
            starts.append(chosen)
    return pred, starts


def rescored(starts: list[RecordStart], data: HysteresisData, pred_rest: np.ndarray,
             resid_deg: np.ndarray) -> list[RecordStart]:
    """``starts`` with their RMSEs those of a model refitted from them: ``pred_rest`` its
    prediction from rest, ``resid_deg`` its residual from the starts."""
    runs = data.run_slices()
    return [replace(s, rmse_rest_deg=_rms(pred_rest[runs[s.run]] - data.meas_deg[runs[s.run]]),
                    rmse_estimated_deg=_rms(resid_deg[runs[s.run]])) for s in starts]


def _run_view(data: HysteresisData, sl: slice) -> HysteresisData:
    """Run ``sl`` of ``data`` as a record of its own, its columns views (``take`` would copy every column)."""
    return HysteresisData(cmd_deg=data.cmd_deg[sl], meas_deg=None if data.meas_deg is None else data.meas_deg[sl],
                          t_s=None if data.t_s is None else data.t_s[sl],
                          extras={k: v[sl] for k, v in data.extras.items()}, drive_unit=data.drive_unit)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))
