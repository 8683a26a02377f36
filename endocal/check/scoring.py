"""One check scored against the probe's models: the figures its control charts follow.

Per bending axis, on the part of the check where that knob moves (the other holds at rest):

``<axis>_rmse_deg``
    validation RMSE (deg of bend) of the model's prediction, the model run over the whole check
    from its estimated start as ``validate`` scores it
    (:func:`endocal.validation.predict.predict_scored`);
``<axis>_loop_width_deg``
    mean vertical gap (deg of bend) between the falling and the rising branch of the loop over
    the middle 80 % of the command span: friction in the sheath (capstan, Coulomb) widens it;
``<axis>_dead_band_deg``
    median knob travel (deg of knob) after a reversal before the bend has moved
    :data:`DEAD_BAND_MOVE_DEG` back: tendon slack and stretch lengthen it;
``<axis>_bend_pos_deg``, ``<axis>_bend_neg_deg``
    bend reached towards each side (deg, both positive): the 99th percentile of the bend and of
    its negative, robust to a tracker outlier; slack and stiffening lose bend at the ends.

A worn probe (tendons lengthened, friction grown) moves these the way the field study of
Rozeboom et al. (Endosc Int Open 2016) read wear off hysteresis plots: the tip reaches less, the
loop widens, the knob turns further before the tip follows.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

#: Bend (deg) the tip must move back after a reversal to end the dead band: three times the
#: simulated tracker's bend-angle noise (0.5 mm RMS at ~60 mm: ~0.15 deg after alignment) and a
#: tenth of a degree below what a user sees on a loop plot.
DEAD_BAND_MOVE_DEG = 1.0
#: Command bins across the loop's middle for the loop width.
LOOP_BINS = 16
#: Smoothing window of the bend (s) before reading the dead band: averages tracker noise over
#: a tenth of a second, short beside a reversal (a knob at 13 deg/s turns 1.3 deg in it).
SMOOTH_S = 0.1
#: The figures of one axis, in the order charts and tables show them.
FIGURES = ("rmse_deg", "loop_width_deg", "dead_band_deg", "bend_pos_deg", "bend_neg_deg")


@dataclass(frozen=True)
class AxisScore:
    """The figures of one axis of one check (see the module docstring)."""

    axis: str
    rmse_deg: float
    loop_width_deg: float
    dead_band_deg: float
    bend_pos_deg: float
    bend_neg_deg: float
    n_samples: int

    def figures(self) -> dict[str, float]:
        """``{"<axis>_<figure>": value}`` for every figure of :data:`FIGURES`."""
        return {f"{self.axis}_{f}": float(getattr(self, f)) for f in FIGURES}


def _moving(cmd: np.ndarray) -> np.ndarray:
    """Mask of the samples from the first to the last move of ``cmd`` (the knob's own part of the check)."""
    moving = np.flatnonzero(np.abs(np.diff(cmd)) > 1e-6)
    mask = np.zeros(cmd.size, bool)
    if moving.size:
        mask[moving[0]:moving[-1] + 2] = True
    return mask


def _smooth(y: np.ndarray, n: int) -> np.ndarray:
    if n <= 1:
        return y
    kernel = np.ones(n) / n
    pad = np.pad(y, (n // 2, n - 1 - n // 2), mode="edge")
    return np.convolve(pad, kernel, mode="valid")


def loop_width_deg(cmd: np.ndarray, meas: np.ndarray) -> float:
    """Mean gap (deg of bend) between the falling and rising branches over the middle 80 % of the command.

    Parameters
    ----------
    cmd, meas : (n,) arrays
        Knob command (deg) and measured bend (deg) of one knob's part of the check.
    """
    v = np.gradient(cmd)
    lo, hi = np.percentile(cmd, [0, 100])
    span = hi - lo
    edges = np.linspace(lo + 0.1 * span, hi - 0.1 * span, LOOP_BINS + 1)
    gaps = []
    for a, b in zip(edges[:-1], edges[1:]):
        inside = (cmd >= a) & (cmd < b)
        up, down = meas[inside & (v > 0)], meas[inside & (v < 0)]
        if up.size and down.size:
            gaps.append(down.mean() - up.mean())
    return float(abs(np.mean(gaps))) if gaps else float("nan")


def dead_band_deg(cmd: np.ndarray, meas: np.ndarray, rate_hz: float) -> float:
    """Median knob travel (deg) after each reversal before the bend moves back by :data:`DEAD_BAND_MOVE_DEG`.

    Parameters
    ----------
    cmd, meas : (n,) arrays
        Knob command (deg) and measured bend (deg) of one knob's part of the check.
    rate_hz : float
        Sample rate (for the smoothing window).
    """
    y = _smooth(meas, int(round(SMOOTH_S * rate_hz)))
    v = np.sign(np.diff(cmd))
    nz = np.flatnonzero(v != 0)
    if nz.size < 2:
        return float("nan")
    sv = v[nz]
    rev = nz[1:][sv[1:] != sv[:-1]]  # first sample moving the new way
    travel = []
    for k, i in enumerate(rev):
        end = rev[k + 1] if k + 1 < rev.size else cmd.size
        direction = np.sign(cmd[i + 1] - cmd[i]) if i + 1 < cmd.size else 0
        if direction == 0:
            continue
        start_bend = y[i]
        moved = np.flatnonzero(direction * (y[i:end] - start_bend) >= DEAD_BAND_MOVE_DEG)
        if moved.size:
            travel.append(abs(cmd[i + moved[0]] - cmd[i]))
    return float(np.median(travel)) if travel else float("nan")


def score_axis(model, data, axis: str) -> AxisScore:
    """The figures of one axis.

    Parameters
    ----------
    model : HysteresisModel
        The probe's fitted model of ``axis``.
    data : HysteresisData
        The axis' command and bend over the whole check (:func:`endocal.validation.data.axis_data`).
    axis : str

    Returns
    -------
    AxisScore
    """
    from endocal.validation.predict import predict_scored

    cmd, meas, t = data.cmd_deg, data.meas_deg, data.t_s
    part = _moving(cmd)
    pred, _, _ = predict_scored(model, data)
    err = pred[part] - meas[part]
    rate_hz = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else 100.0
    c, m = cmd[part], meas[part]
    return AxisScore(
        axis=axis,
        rmse_deg=float(np.sqrt(np.mean(err**2))),
        loop_width_deg=loop_width_deg(c, m),
        dead_band_deg=dead_band_deg(c, m, rate_hz),
        bend_pos_deg=float(np.percentile(m, 99)),
        bend_neg_deg=float(-np.percentile(m, 1)),
        n_samples=int(part.sum()),
    )


def score_check(aligned, models: Mapping) -> dict[str, AxisScore]:
    """Score one check run against the probe's models.

    Parameters
    ----------
    aligned : AlignedData
        The check run (:func:`endocal.runs.aligned.load_aligned`).
    models : mapping of axis -> HysteresisModel

    Returns
    -------
    dict of axis -> AxisScore

    Raises
    ------
    ModelError
        The run lacks a model's axis, or that knob never moves in it.
    """
    from endocal.errors import ModelError
    from endocal.validation.data import axis_data

    scores = {}
    for axis, model in models.items():
        d = axis_data(aligned, axis)
        if _moving(d.cmd_deg).sum() < 10:
            raise ModelError(f"{aligned.source}: the {axis} knob never moves in this run: a check moves both knobs "
                             "(endocal check records one)")
        scores[axis] = score_axis(model, d, axis)
    return scores


def check_figures(aligned, models: Mapping) -> dict[str, float]:
    """Every figure of a check as one flat mapping, ``{"ap_rmse_deg": ..., "ml_bend_neg_deg": ...}``."""
    figures = {}
    for s in score_check(aligned, models).values():
        figures.update(s.figures())
    return figures
