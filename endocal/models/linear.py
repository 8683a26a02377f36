"""``linear``: direction-dependent piecewise-linear hysteresis in the spirit of Lee et al.

Thesis (Design and Hysteresis Compensation of a Robot-assisted System for TEE),
section 2.3, after Lee et al.: a straight ascending branch ``a_up·u + b_up``, a straight
descending branch ``a_down·u + b_down`` and, at each reversal, a backlash transition of
slope ``s`` from the reversal point until the other branch is met (see
:mod:`endocal.models._directional`). Straight branches cannot follow the loop's
curvature near its tips, which is where this model falls short (the thesis found
it worse than B-splines at reversals).
"""

from __future__ import annotations

import numpy as np

from endocal.errors import ModelError
from endocal.models._directional import DirectionalModel, direction_masks
from endocal.models.data import HysteresisData
from endocal.models.effects.base import Effect
from endocal.models.params import Parameter, fmt_value


class LinearModel(DirectionalModel):
    """Piecewise-linear, direction-dependent hysteresis model (Lee et al. style).

    Parameters (prefix ``linear_``): ``up_slope``, ``up_offset_deg`` (ascending
    branch), ``down_slope``, ``down_offset_deg`` (descending branch),
    ``transition_slope`` (deg of bending per deg of knob right after a reversal; 0 is
    pure backlash).

    Parameters
    ----------
    effects, fixed, axis, out_of_range
        See :class:`~endocal.models.base.HysteresisModel`.

    Notes
    -----
    The inverse is numerical (bisection per sample on the monotone step map).
    """

    base_name = "linear"

    def __init__(self, *, effects=(), fixed=None, axis=None, out_of_range="error"):
        self.effects = effects
        self.fixed = fixed
        self.axis = axis
        self.out_of_range = out_of_range

    def _resolve_structure(self, effects: list[Effect], v, data) -> dict:
        return {}

    def _base_names(self, structure: dict) -> list[str]:
        return ["up_slope", "up_offset_deg", "down_slope", "down_offset_deg", "transition_slope"]

    def _base_initial(self, structure: dict, v: np.ndarray, data: HysteresisData) -> list[Parameter]:
        inc, dec = direction_masks(v, data.run_starts)
        y = data.meas_deg
        if inc.sum() < 2 or dec.sum() < 2:
            raise ModelError("backlash cannot be identified: the command never reverses")
        a_up, b_up = np.polyfit(v[inc], y[inc], 1)
        a_dn, b_dn = np.polyfit(v[dec], y[dec], 1)
        a_up, a_dn = max(a_up, 1e-6), max(a_dn, 1e-6)
        return [
            Parameter("up_slope", float(a_up), 0.0, np.inf),
            Parameter("up_offset_deg", float(b_up)),
            Parameter("down_slope", float(a_dn), 0.0, np.inf),
            Parameter("down_offset_deg", float(b_dn)),
            Parameter("transition_slope", 0.2 * float(min(a_up, a_dn)), 0.0, np.inf),
        ]

    def _eval_branches(self, structure: dict, p: dict, v: np.ndarray):
        return p["up_slope"] * v + p["up_offset_deg"], p["down_slope"] * v + p["down_offset_deg"]

    def _branch_jac(self, structure: dict, p: dict, v: np.ndarray):
        one, zero = np.ones_like(v), np.zeros_like(v)
        up, down = self._eval_branches(structure, p, v)
        J_up = np.column_stack([v, one, zero, zero])
        J_dn = np.column_stack([zero, zero, v, one])
        return up, down, J_up, J_dn, p["up_slope"] * one, p["down_slope"] * one

    def _branches(self, structure: dict, p: dict):
        # a straight line as a degree-1 B-spline on [0, 1], extrapolated both ways
        t = np.array([0.0, 0.0, 1.0, 1.0])
        c_up = np.array([p["up_offset_deg"], p["up_slope"] + p["up_offset_deg"]])
        c_dn = np.array([p["down_offset_deg"], p["down_slope"] + p["down_offset_deg"]])
        return t, c_up, t.copy(), c_dn, 1

    def _base_describe(self, structure: dict, p: dict, se: dict, inner: str) -> str:
        def line(key):
            return (f"{fmt_value(p[key + '_slope'], se.get(key + '_slope'))}*u "
                    f"{'+' if p[key + '_offset_deg'] >= 0 else '-'} "
                    f"{fmt_value(abs(p[key + '_offset_deg']), se.get(key + '_offset_deg'), 'deg')}")

        return (f"Linear({inner}) [up: {line('up')}, down: {line('down')}, "
                f"transition={fmt_value(p['transition_slope'], se.get('transition_slope'))}]")
