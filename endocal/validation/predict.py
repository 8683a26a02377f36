"""Predictions as ``validate`` scores them: continued beyond the fitted range, each record from its estimated start."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np

from endocal.models import HysteresisData
from endocal.models.base import HysteresisModel
from endocal.models.start import RecordStart, estimate_starts


def predict_scored(model: HysteresisModel, data: HysteresisData) -> tuple[np.ndarray, int, list[RecordStart]]:
    """Predicted angle (deg) as ``validate`` scores a model: beyond the fitted range the model
    continues, and each record starts in its estimated state.

    A command beyond the range the model was fitted on is run through the model's own
    branches continued (B-spline end tangents, straight lines, saturated plays), not clamped:
    clamping holds the predicted angle still while the tip keeps bending, so a validation
    run 10 deg wider than the estimation run would be scored on that artefact (on a
    simulated sweep, 3.3 deg instead of the model's 0.8). A record that starts where a longer
    motion left the knob is run from its estimated start (:mod:`endocal.models.start`), as the
    fit runs its own records.

    Parameters
    ----------
    model : HysteresisModel
        A fitted model (left unchanged: a shallow copy is switched to extrapolate).
    data : HysteresisData
        Commands (deg) and whatever else the model's effects read; without the measured
        angle every record starts from rest.

    Returns
    -------
    predicted_deg : (n,) array
        Predicted bending angle, deg.
    n_beyond : int
        Samples whose command lies beyond the model's fitted range ``cmd_range_deg_``.
    starts : list of RecordStart
        The records run from an estimated start.
    """
    m = copy.copy(model)
    m.out_of_range = "extrapolate"
    lo, hi = model.cmd_range_deg_
    pred, starts = estimate_starts(m.predict, columns_read(model, data))
    return pred, int(np.sum((data.cmd_deg < lo) | (data.cmd_deg > hi))), starts


def columns_read(model: HysteresisModel, data: HysteresisData) -> HysteresisData:
    """``data`` with only the extra columns ``model``'s effects read (coupling, load), as views.

    A prediction needs no other column, and :func:`~endocal.models.start.estimate_starts` and
    :func:`~endocal.models.start.with_lead_ins` copy every column they are given (each lead-in
    tried is a record's length and more).
    """
    read = {c for e in getattr(model, "effects_", []) if (c := getattr(e, "column", None))}
    if not set(data.extras) - read:
        return data
    return dataclasses.replace(data, extras={k: v for k, v in data.extras.items() if k in read})


def predict_extrapolated(model: HysteresisModel, data: HysteresisData) -> tuple[np.ndarray, int]:
    """The prediction and samples beyond the fitted range of :func:`predict_scored`."""
    return predict_scored(model, data)[:2]


def predict_errors(model: HysteresisModel, data: HysteresisData) -> np.ndarray:
    """``pred - meas`` (deg) of a fitted model run over ``data`` from its start (continued beyond its fitted range)."""
    return predict_extrapolated(model, data)[0] - data.meas_deg

