"""Fit a hysteresis model of one axis to runs or aligned tables (what `endocal fit hysteresis` calls)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from endocal.errors import ModelError
from endocal.models import HysteresisData, make_model
from endocal.models.base import HysteresisModel
from endocal.runs.aligned import AlignedData, load_aligned


def hysteresis_data(datas: list[AlignedData], axis: str, planes=None) -> HysteresisData:
    """One axis of several aligned tables as a multi-run :class:`HysteresisData`.

    The other bending axis's command is passed as ``other_cmd_deg`` (for ``coupling``) and
    every numeric extra column is kept (for ``load:COLUMN``). With ``planes`` the measured
    standard-plane angles are mapped into the twisted half-planes the knobs actually drive
    (the orthogonal compensator of duodenoscope eqs. 3-4 maps an output in the standard
    planes to the input along the twisted planes that produces it), so the hysteresis model
    sees one knob against its own plane.

    Raises
    ------
    RunFormatError
        ``axis`` is missing from one of the tables.
    ModelError
        Tables disagree on their extra columns.
    """
    cmd, meas, t, starts, extras = [], [], [], [], {}
    offset = 0
    common = None
    for data in datas:
        data.cmd_deg(axis)  # raises RunFormatError naming the source when the axis is absent
        cols = set(data.extras)
        common = cols if common is None else common & cols
    for data in datas:
        m = data.meas_deg(axis)
        others = [a for a in data.axes if a != axis]
        if planes is not None:
            if len(data.axes) != 2:
                raise ModelError(f"{data.source}: --planes needs both bending axes in the data")
            first, second = data.axes
            comp = planes.compensate(data.meas_deg(first), data.meas_deg(second))
            m = np.asarray(comp[0] if axis == first else comp[1], float)
        cmd.append(data.cmd_deg(axis))
        meas.append(m)
        t.append(data.t_s - data.t_s[0] + (t[-1][-1] + 1.0 if t else 0.0))  # runs back to back, 1 s apart
        starts.append(offset)
        offset += len(data.t_s)
        other = data.cmd_deg(others[0]) if others else np.zeros(len(data.t_s))
        extras.setdefault("other_cmd_deg", []).append(other)
        for col in sorted(common or ()):
            extras.setdefault(col, []).append(data.table[col].to_numpy(float))
    return HysteresisData(
        np.concatenate(cmd),
        np.concatenate(meas),
        t_s=np.concatenate(t),
        extras={k: np.concatenate(v) for k, v in extras.items()},
        run_starts=np.asarray(starts, dtype=np.int64),
    )


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
