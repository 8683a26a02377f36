"""Fit a hysteresis model of one axis to runs or aligned tables (what `endocal fit hysteresis` calls)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from endocal.errors import ModelError
from endocal.models import make_model
from endocal.models.base import HysteresisModel
from endocal.models.start import RecordStart
from endocal.runs.aligned import load_aligned
from endocal.validation.data import axis_data, glitch_note
from endocal.validation.residuals import cut_start


@dataclass
class HysteresisFit:
    """A fitted model and the data it was fitted on."""

    model: HysteresisModel
    sources: list[Path]
    hashes: list[str]
    samples: int
    duration_s: float = 0.0  # summed over the records: with ``samples``, the rate a user can check
    cut_start: str = ""  # how records that did not start at rest were fitted (validation.residuals.cut_start)
    glitches: str = ""  # samples left out as glitches (validation.data.glitch_note)

    @property
    def rate_hz(self) -> float:
        """Mean sample rate over the records (0 when they span no time)."""
        return self.samples / self.duration_s if self.duration_s > 0 else 0.0


def fit_hysteresis(
    paths: list[Path], axis: str, base: str, effects: list[str] | None = None, planes=None,
    start_from: HysteresisModel | None = None, **settings
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
    start_from : HysteresisModel, optional
        A fitted model of this axis and base whose parameters start the fit (every effect it
        shares with the new model starts from its fitted values and skips its start search):
        the refit ``validate`` prints starts from the model it validated, as its scan did, so
        the refit is the fit the scan scored (from scratch, a fit can end in another local
        minimum).
    **settings
        Passed to the model (e.g. ``n_operators``, ``out_of_range``).

    Raises
    ------
    ModelError
        ``start_from`` of another axis or base model, or of a drive in another unit (deg, mm).
    """
    if start_from is not None:
        if start_from.base_name != base or (start_from.axis and start_from.axis != axis):
            raise ModelError(f"--start-from: that model is a {start_from.base_name} model of axis "
                             f"{start_from.axis or '(none)'}, this fit a {base} model of axis {axis}; start from a "
                             "model of the same axis and base model, or drop --start-from")
    datas = [load_aligned(p) for p in paths]
    dropped: list = []
    data = axis_data(datas, axis, planes, dropped)
    if start_from is not None:
        try:
            start_from.check_drive_unit(data, f"the records to fit ({', '.join(str(d.source) for d in datas)})")
        except ModelError as exc:
            raise ModelError(f"--start-from: {exc}") from None
    model = make_model(base, effects=effects or (), axis=axis, **settings)
    model = model.fit_from(start_from, data) if start_from is not None else model.fit(data)
    span = sum(float(np.ptp(d.table["t_s"])) for d in datas)
    starts = [RecordStart.from_dict(s) for s in model.fit_report_.estimated_starts]
    cut = cut_start(data, model.predict(data) - data.meas_deg, "fitted record", starts)
    return HysteresisFit(model, [d.source for d in datas], [d.sha256 for d in datas], len(data.cmd_deg), span, cut,
                         glitch_note(dropped, axis))
