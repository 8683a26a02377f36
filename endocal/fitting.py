"""Fit a hysteresis model of one axis to runs or aligned tables (what `endocal fit hysteresis` calls)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from endocal.errors import ModelError
from endocal.models import HysteresisData, make_model
from endocal.models.base import HysteresisModel
from endocal.runs.aligned import AlignedData, load_aligned
from endocal.validation.data import axis_data


def hysteresis_data(datas: list[AlignedData], axis: str, planes=None) -> HysteresisData:
    """One axis of several aligned tables as a multi-run :class:`HysteresisData`.

    The conversion is :func:`endocal.validation.data.axis_data` (the same one ``validate``
    and ``report`` use, so a model file's training-data hashes match the records they
    evaluate). With ``planes`` the measured standard-plane angles are mapped into the
    twisted half-planes the knobs actually drive: the orthogonal compensator of duodenoscope
    eqs. 3-4 maps an output in the standard planes to the input along the twisted planes that
    produces it, so the hysteresis model sees one knob against its own plane.

    Raises
    ------
    ModelError
        ``axis`` is missing from a table, or ``planes`` is given for a table without both
        bending axes.
    """
    if planes is None:
        return axis_data(datas, axis)
    runs = []
    for data in datas:
        if len(data.axes) != 2:
            raise ModelError(f"{data.source}: --planes needs both bending axes in the data")
        first, second = data.axes
        comp = planes.compensate(data.meas_deg(first), data.meas_deg(second))
        table = data.table.copy()
        table[f"{axis}_meas_deg"] = np.asarray(comp[0] if axis == first else comp[1], float)
        runs.append(replace(data, table=table))
    return axis_data(runs, axis)


@dataclass
class HysteresisFit:
    """A fitted model and the data it was fitted on."""

    model: HysteresisModel
    sources: list[Path]
    hashes: list[str]
    samples: int


def fit_hysteresis(
    paths: list[Path], axis: str, base: str, effects: list[str] | None = None, planes=None, **settings
) -> HysteresisFit:
    """Fit ``base`` + ``effects`` to ``axis`` of every run folder or aligned table in ``paths``.

    Parameters
    ----------
    paths : list of Path
        Run folders or aligned tables (.parquet / .csv).
    axis : str
        Bending axis to model (must be in every table).
    base : {"linear", "bspline", "pi"}
    effects : list of str
        Effect names (see ``endocal effects``), e.g. ``["envelope"]`` for the paper's modified PI.
    planes : PlanesCalibration, optional
        Bending planes; measured angles are mapped into the twisted planes first.
    **settings
        Passed to the model (e.g. ``n_operators``, ``out_of_range``).
    """
    datas = [load_aligned(p) for p in paths]
    data = hysteresis_data(datas, axis, planes)
    model = make_model(base, effects=effects or (), axis=axis, **settings).fit(data)
    return HysteresisFit(model, [d.source for d in datas], [d.sha256 for d in datas], len(data.cmd_deg))
