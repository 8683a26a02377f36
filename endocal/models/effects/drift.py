"""``drift``: slow zero drift of the bending angle over a run.

``y += drift_rate_dps · (t - t_run_start)``: a linear drift (deg/s) restarting with
each run, e.g. the sheath settling or the tracker's base sensor creeping.
"""

from __future__ import annotations

import numpy as np

from endocal.models.data import HysteresisData
from endocal.models.effects.base import OutputEffect
from endocal.models.params import Parameter, fmt_value


def _elapsed_s(data: HysteresisData) -> np.ndarray:
    t = data.require_time("effect 'drift'")
    out = np.empty_like(t)
    for sl in data.run_slices():
        out[sl] = t[sl] - t[sl.start]
    return out


class Drift(OutputEffect):
    """Linear zero drift over each run; parameter ``drift_rate_dps`` (deg/s)."""

    name = "drift"
    depends_on_command = False
    cause = "slow zero drift: sheath settling, temperature, a slipping sensor mount"
    signature = "residual mean that changes steadily over time within a run"
    protocol = "long runs, or the same motion repeated at the start and end of a run"
    units = {"rate_dps": "deg/s"}

    def check(self, data: HysteresisData) -> None:
        data.require_time("effect 'drift'")

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        return [Parameter(f"{self.prefix}_rate_dps", 0.0)]

    def term(self, p: dict, cmd: np.ndarray, data: HysteresisData) -> np.ndarray:
        return p["rate_dps"] * _elapsed_s(data)

    def term_jac(self, p: dict, cmd: np.ndarray, data: HysteresisData):
        e = _elapsed_s(data)
        return p["rate_dps"] * e, e[:, None]

    def describe(self, p: dict, se: dict) -> str:
        return f"drift[{fmt_value(p['rate_dps'], se.get('rate_dps'), 'deg/s')}]*t"
