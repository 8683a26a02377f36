"""Between two recordings: did a condition change that no effect fitted on one of them can learn?

Under the estimation/validation scheme every candidate effect is fitted on the estimation
record and scored on the validation record. That tests what happens *within* a record. A
condition that changed *between* the records (the insertion tube curved differently, the
tendons were re-tensioned, a sensor was re-mounted) leaves the validation record following
the same model with other parameters, which no candidate fitted on the estimation record
can follow, and the scan then reports nothing while the error is several times the noise.

:func:`record_shift` asks the validation record directly, with the fitted model held fixed
and a few parameters fitted on the validation record itself (in-sample, but two or three
parameters against hundreds of samples):

``zero``
    the output shifted by a constant ``c``: ``y = p + c`` (the base sensor or the knob's
    zero moved between the records);
``friction``
    the loop widened or narrowed by ``w`` knob degrees on each side and its slope scaled:
    ``y = a + g p(u - w d)``, with ``d = ±1`` the direction of the knob's motion (held
    between reversals). More sheath friction, from a tighter curve of the insertion tube
    (capstan ``e^{μΘ}``), widens the loop and costs transmission (``g < 1``); ``a`` takes a
    zero shift that may come with it.

Where one of them explains much more of the validation error than any catalog effect,
:func:`endocal.validation.verdict.shift_pointers` names it (``drift`` for a zero, ``load`` for
friction) with the experiment that would model it: log the condition as a column of every
record and fit ``load:COLUMN`` on records of different conditions. Extra columns whose
validation values lie outside the estimation record's range (:func:`covariate_changes`) are
the condition, when the lab logged it. A loop that is wider where the knob moves faster than in
the estimation record (:func:`moving_speed_dps`) may instead be a lag or a friction that grows
with speed, which a record at one speed cannot pin down; the verdict then names those too.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from endocal.models import HysteresisData
from endocal.models.base import HysteresisModel
from endocal.models.start import with_lead_ins
from endocal.validation.data import load_candidates, speed_dps
from endocal.validation.predict import columns_read, predict_extrapolated, predict_scored
from endocal.validation.regimes import turning_points

#: Largest loop change searched, as a fraction of the validation command's span per side.
MAX_WIDTH_FRAC = 0.2


@dataclass(frozen=True)
class RecordShift:
    """What the validation record asks of the fitted model (see the module docstring).

    Attributes
    ----------
    rmse_deg : float
        The model as fitted, on the validation record.
    zero_deg, zero_rmse_deg : float
        The constant output shift ``c`` and the RMSE with it.
    width_deg, gain, offset_deg, friction_rmse_deg : float
        The loop change ``w`` (knob deg per side, > 0 wider), the slope factor ``g``, the
        offset ``a`` and the RMSE with them.
    """

    rmse_deg: float
    zero_deg: float
    zero_rmse_deg: float
    width_deg: float
    gain: float
    offset_deg: float
    friction_rmse_deg: float

    def to_dict(self) -> dict:
        return asdict(self)


def direction_of_motion(data: HysteresisData, tol_frac: float = 0.02) -> np.ndarray:
    """``+1`` where the command's current branch rises, ``-1`` where it falls (n,).

    Branches run between the reversals of :func:`~endocal.validation.regimes.turning_points`
    (wiggles below ``tol_frac`` of the span ignored), so a knob at rest keeps its direction.
    """
    d = np.ones(data.n_samples)
    starts = set(int(s) for s in data.run_starts)
    cuts = sorted(starts | set(int(r) for r in turning_points(data, tol_frac)) | {data.n_samples})
    for a, b in zip(cuts[:-1], cuts[1:]):
        end = b if b < data.n_samples and b not in starts else b - 1  # the reversal ends its branch
        d[a:b] = 1.0 if data.cmd_deg[end] >= data.cmd_deg[a] else -1.0
    return d


def record_shift(model: HysteresisModel, data: HysteresisData) -> RecordShift:
    """Fit a zero shift and a friction change of ``model`` on the validation ``data`` (module docstring)."""
    y = np.asarray(data.meas_deg, dtype=float)
    p, _, starts = predict_scored(model, data)
    # the shifted commands start where the record's estimate put it (the columns the model reads only)
    led, keep = with_lead_ins(columns_read(model, data), starts)
    rmse = _rms(p - y)
    c = float(np.mean(y - p))
    span = float(np.ptp(data.cmd_deg))
    d = direction_of_motion(led)

    def friction(w: float):
        q = predict_extrapolated(model, led.with_cmd(led.cmd_deg - w * d))[0][keep]
        A = np.column_stack([np.ones_like(q), q])
        coef = np.linalg.lstsq(A, y, rcond=None)[0]
        return _rms(A @ coef - y), coef

    if span > 0:
        w = float(minimize_scalar(lambda w: friction(w)[0], bounds=(-MAX_WIDTH_FRAC * span, MAX_WIDTH_FRAC * span),
                                  method="bounded", options={"xatol": 1e-3 * span}).x)
    else:
        w = 0.0
    r, (a, g) = friction(w)
    if r > rmse:  # the bounded search found nothing better than the model as it stands
        w, r, a, g = 0.0, rmse, 0.0, 1.0
    return RecordShift(rmse_deg=rmse, zero_deg=c, zero_rmse_deg=_rms(p + c - y), width_deg=w, gain=float(g),
                       offset_deg=float(a), friction_rmse_deg=r)


def moving_speed_dps(data: HysteresisData) -> float:
    """Typical knob speed while the knob moves (deg/s): the median |speed| above 10 % of its 95th percentile."""
    v = np.abs(speed_dps(data))
    top = float(np.percentile(v, 95)) if v.size else 0.0
    moving = v[v > 0.1 * top]
    return float(np.median(moving)) if top > 0 and moving.size else 0.0


def covariate_changes(train: HysteresisData, data: HysteresisData) -> list[str]:
    """Extra columns of both records whose values here do not overlap the estimation record's, in words.

    A condition a lab logs (``sheath_wrap_deg``, a fixture's setting) is constant or slow within
    a record; signals that follow the motion (currents, speeds) overlap between records and are
    left out.
    """
    out = []
    for name in sorted(set(train.extras) & set(data.extras)):
        x_est, x_val = np.asarray(train.extras[name], float), np.asarray(data.extras[name], float)
        if not (np.isfinite(x_est).all() and np.isfinite(x_val).all()):
            continue
        lo, hi, v_lo, v_hi = float(x_est.min()), float(x_est.max()), float(x_val.min()), float(x_val.max())
        tol = 1e-9 * max(1.0, abs(lo), abs(hi))
        if v_lo > hi + tol or v_hi < lo - tol:
            out.append(f"'{name}' is {_span(lo, hi)} in the estimation data and {_span(v_lo, v_hi)} here")
    return out


def covariates_held(train: HysteresisData, data: HysteresisData, axes: Sequence[str] = ()) -> list[str]:
    """Conditions the lab logs that did not change between the records, in words: the extra columns
    both hold constant (:func:`~endocal.validation.data.load_candidates`'s constant ones, so not
    the drives' own readings) at the same nonzero value (a column that is 0 throughout is more
    often a signal the rig did not log than a condition). A change of friction was something else."""
    held = set(load_candidates(train, axes)[1]) & set(load_candidates(data, axes)[1])
    out = []
    for name in sorted(held):
        a, b = float(train.extras[name][0]), float(data.extras[name][0])
        if a != 0.0 and abs(a - b) <= 1e-9 * abs(a):
            out.append(f"'{name}' is {a:.4g} in both records")
    return out


def _span(lo: float, hi: float) -> str:
    return f"{lo:.4g}" if f"{lo:.4g}" == f"{hi:.4g}" else f"{lo:.4g}..{hi:.4g}"


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))
