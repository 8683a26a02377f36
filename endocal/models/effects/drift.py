"""``drift``: slow zero drift of the bending angle over a run.

``y += drift_rate_dps · (t - t_run_start)``: a linear drift (deg/s) restarting with
each run, e.g. the sheath settling or the tracker's base sensor creeping.
"""

from __future__ import annotations

import numpy as np

from endocal.models.data import HysteresisData
from endocal.models.effects.base import OutputEffect
from endocal.models.effects.requirements import TIME_STAMPS
from endocal.models.params import Parameter, fmt_value


#: ``--next`` tests a drift by holding the knob still this long (s): a drift of 1 deg/min moves the
#: zero by 1 deg, three times a tracker's noise.
DRIFT_HOLD_S = 60.0


class Drift(OutputEffect):
    """Linear zero drift over each run; parameter ``drift_rate_dps`` (deg/s)."""

    name = "drift"
    depends_on_command = False
    cause = "slow zero drift: sheath settling, temperature, a slipping sensor mount"
    signature = "residual mean that changes steadily over time within a run"
    protocol = "long runs, or the same motion repeated at the start and end of a run"
    units = {"rate_dps": "deg/s"}
    open_bounds = ("rate_dps",)  # either sign, any size: implausible() says when it is too fast to be a drift
    needs = ("t_s",)
    requires = (TIME_STAMPS,)
    residual = ("time",)
    lookalikes = {"creep": 'creep relaxes after each motion and stops, drift keeps going at a constant rate: run `staircase` (creep restarts at every step) and `hold` (drift keeps going with the knob still)'}
    sim_section = "drift"
    null = {"rate_dps": 0.0}

    def segment(self, design, n_half_cycles: int):
        """A long hold: the knob still, a drift keeps going where creep stops."""
        k = design.add("hold", axes=[design.axis], offset_deg=design.centre, duration_s=DRIFT_HOLD_S)
        return design.planned(k, 1, f"a hold of {DRIFT_HOLD_S:g} s: the knob still, a drift keeps going where creep "
                              "stops")

    def check(self, data: HysteresisData) -> None:
        data.require_time("effect 'drift'")

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        return [Parameter(f"{self.prefix}_rate_dps", 0.0)]

    def implausible(self, p: dict, data: HysteresisData) -> str:
        """A drift is slow against the motion it rides on. One at more than 5 % of the bend's mean
        speed moves the zero by a tenth of the range in every knob cycle: no settling sheath or
        creeping mount does that. Fitted on records that all start alike (cycles cut from one
        recording), such a term follows the time since each record began and fails on a longer
        one. The speed is the command's (the measured angle's differences are mostly tracker
        noise at 100 Hz) in bend units: times the bend range over the command range."""
        if data.meas_deg is None or data.t_s is None:
            return ""
        speeds = []
        for sl in data.run_slices():
            du, dt = np.diff(data.cmd_deg[sl]), np.diff(data.t_s[sl])
            if dt.size and dt.sum() > 0:
                speeds.append(np.abs(du).sum() / dt.sum())
        cmd_span, bend_span = float(np.ptp(data.cmd_deg)), float(np.ptp(data.meas_deg))
        if not speeds or cmd_span <= 0.0:
            return ""
        bend_speed = float(np.mean(speeds)) * bend_span / cmd_span
        rate = abs(p["rate_dps"])
        if rate <= 0.05 * bend_speed:
            return ""
        return (f"{self.prefix}_rate_dps = {p['rate_dps']:.3g} is {100 * rate / bend_speed:.0f} % of the bend's mean speed "
                f"({bend_speed:.3g} deg/s): no slow drift moves that fast; it likely fits how the records start")

    def term(self, p: dict, cmd: np.ndarray, data: HysteresisData) -> np.ndarray:
        return p["rate_dps"] * data.elapsed_s("effect 'drift'")

    def term_jac(self, p: dict, cmd: np.ndarray, data: HysteresisData):
        e = data.elapsed_s("effect 'drift'")
        return p["rate_dps"] * e, e[:, None]

    def describe(self, p: dict, se: dict) -> str:
        return f"drift[{fmt_value(p['rate_dps'], se.get('rate_dps'), 'deg/s')}]*t"
