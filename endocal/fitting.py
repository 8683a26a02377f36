"""Fit a hysteresis model of one axis to runs or aligned tables (what `endocal fit hysteresis` calls)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from endocal.models import make_model
from endocal.models.base import HysteresisModel
from endocal.runs.aligned import load_aligned
from endocal.validation.data import axis_data


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
    data = axis_data(datas, axis, planes)
    model = make_model(base, effects=effects or (), axis=axis, **settings).fit(data)
    return HysteresisFit(model, [d.source for d in datas], [d.sha256 for d in datas], len(data.cmd_deg))
