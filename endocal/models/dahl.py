"""``dahl``: Dahl's friction model as a hysteresis base, without return-point memory.

Dahl, "A solid friction model", Aerospace Corp. report TOR-0158(3107-18)-1 (1968), and "Solid
friction damping of mechanical vibrations", AIAA J. 14 (1976) 1675-1682, eq. 1: the friction
force ``F`` follows the displacement ``x`` as::

    dF/dx = sigma0 |1 - F/Fc sgn(dx/dt)|^i sgn(1 - F/Fc sgn(dx/dt))

rate-independent (a function of the path only), stiff (``sigma0``) right after a reversal and
saturating at the Coulomb level ``Fc`` (``i = 1``: along an exponential of length ``Fc/sigma0``;
Dahl fitted ``i`` between 0 and 1 for ductile, above 1 for brittle contacts). As a base the
friction holds the output back from a linear spring's (the positioning form of
:mod:`endocal.models._friction_base`)::

    y = k_lin * v - F(v) + offset

with ``k_lin`` (deg per unit of the drive), ``fc_deg`` (``Fc`` in output deg), ``sigma0`` (deg per
unit of the drive) and ``offset_deg``. ``i`` is a setting, 1 by default (solved exactly,
:mod:`endocal.models._smooth_friction`). Like ``bouc-wen``, and unlike ``linear``, ``bspline`` and
``pi``, a small reversal inside the loop does not return to the branch it left.
"""

from __future__ import annotations

import numpy as np

from endocal.errors import ModelError
from endocal.models._friction_base import SmoothFrictionModel
from endocal.models._smooth_friction import DAHL
from endocal.models.effects.base import Effect
from endocal.models.params import fmt_value


class DahlModel(SmoothFrictionModel):
    """Dahl friction (Dahl 1968; AIAA J. 1976, eq. 1) holding back a linear spring.

    Parameters (prefix ``dahl_``): ``k_lin`` (deg per unit of the drive), ``fc_deg`` (deg),
    ``sigma0`` (deg per unit of the drive), ``offset_deg``.

    Parameters
    ----------
    i : float
        Dahl's exponent (0.1 to 10; default 1, solved exactly; other values by Runge-Kutta).
    effects, fixed, axis, out_of_range
        See :class:`~endocal.models.base.HysteresisModel`.

    Notes
    -----
    The inverse is numerical (bisection per sample), checked on a sweep of the fitted range: with
    ``k_lin = 0`` the friction saturates at ``Fc`` and compensation is refused.
    """

    base_name = "dahl"
    _family = DAHL

    def __init__(self, i: float = 1.0, *, effects=(), fixed=None, axis=None, out_of_range="error"):
        self.i = i
        self.effects = effects
        self.fixed = fixed
        self.axis = axis
        self.out_of_range = out_of_range

    def _resolve_structure(self, effects: list[Effect], v, data) -> dict:
        if isinstance(self.i, bool) or not isinstance(self.i, (int, float)) or not 0.1 <= float(self.i) <= 10.0:
            raise ModelError(f"i (Dahl's exponent) must be a number in 0.1..10, got {self.i!r}")
        return {"exponent": float(self.i)}

    def _base_names(self, structure: dict) -> list[str]:
        return ["k_lin", "fc_deg", "sigma0", "offset_deg"]

    def _bounds(self) -> dict[str, tuple[float, float]]:
        return {"k_lin": (0.0, np.inf), "fc_deg": (1e-9, np.inf), "sigma0": (1e-12, np.inf),
                "offset_deg": (-np.inf, np.inf)}

    def _from_regression(self, rho, sigma, a, b, c) -> dict[str, float]:
        return {"k_lin": a, "fc_deg": b, "sigma0": rho * b, "offset_deg": c}

    def _law(self, structure: dict, p: dict) -> tuple:
        fc = float(p["fc_deg"])
        return (DAHL, float(p["k_lin"]), -fc, float(p["sigma0"]) / fc, 1.0, self._exponent(structure),
                float(p["offset_deg"]))

    def _base_describe(self, structure: dict, p: dict, se: dict, inner: str) -> str:
        u = self.drive_unit_
        parts = [f"k_lin={fmt_value(p['k_lin'], se.get('k_lin'), f'deg/{u}')}",
                 f"Fc={fmt_value(p['fc_deg'], se.get('fc_deg'), 'deg')}",
                 f"sigma0={fmt_value(p['sigma0'], se.get('sigma0'), f'deg/{u}')}",
                 f"i={self._exponent(structure):g} (fixed)"]
        out = f"Dahl({inner}) [k_lin*u - F, dF/du = sigma0|1 - F/Fc sgn(du)|^i sgn(1 - F/Fc sgn(du)); " \
              f"{', '.join(parts)}]"
        if p["offset_deg"] != 0.0:
            out += f" {'+' if p['offset_deg'] >= 0 else '-'} " \
                   f"{fmt_value(abs(p['offset_deg']), se.get('offset_deg'), 'deg')}"
        return out
