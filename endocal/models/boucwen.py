"""``bouc-wen``: the normalised Bouc-Wen hysteresis, a smooth friction element without return-point memory.

Ismail, Ikhouane & Rodellar, "The hysteresis Bouc-Wen model, a survey", Arch. Comput. Methods
Eng. 16 (2009) 161-188: the model (eq. 1, after Bouc 1967 and Wen 1976)::

    Phi(x)(t) = alpha k x(t) + (1 - alpha) D k z(t),
    dz/dt = D^-1 (A dx/dt - beta |dx/dt| |z|^(n-1) z - gamma dx/dt |z|^n)

over-parameterised: every input-output behaviour is reached by the normalised form (section 4,
eq. 13; Ikhouane & Rodellar 2007)::

    Phi(x)(t) = kappa_x x(t) + kappa_w w(t),
    dw/dt = rho (dx/dt - sigma |dx/dt| |w|^(n-1) w + (sigma - 1) dx/dt |w|^n),   w in [-1, 1]

with ``rho > 0``, ``sigma >= 1/2``, ``n >= 1`` (the class where ``w`` stays bounded and the loop is
physically consistent, survey section 5). Here ``kappa_x`` is ``k_lin`` (deg per unit of the drive) and
``kappa_w = -k_hys_deg`` (deg): the tip lags the knob by what the friction state holds back (the
positioning form ``y = d u - h`` of piezo stages), plus an ``offset_deg``. ``n`` (the sharpness of the transition
to the saturated branch) is a setting, 1 by default: then every branch is an exponential in the
input, solved exactly (:mod:`endocal.models._smooth_friction`).

This is the friction law a public ROS compensation peer fits. Unlike ``linear``, ``bspline`` and
``pi``, it has no return-point memory: a small reversal inside the loop does not return to the
branch it left (the survey's section 7 on minor loops).
"""

from __future__ import annotations


import numpy as np

from endocal.errors import ModelError
from endocal.models._friction_base import SmoothFrictionModel
from endocal.models._smooth_friction import BOUC_WEN
from endocal.models.effects.base import Effect
from endocal.models.params import fmt_value


class BoucWenModel(SmoothFrictionModel):
    """Normalised Bouc-Wen hysteresis (Ismail, Ikhouane & Rodellar 2009, eq. 13).

    Parameters (prefix ``bouc-wen_``): ``k_lin`` (deg per unit of the drive), ``k_hys_deg`` (deg),
    ``rho`` (per unit of the drive), ``sigma`` (>= 1/2, dimensionless), ``offset_deg``.

    Parameters
    ----------
    n : float
        The Bouc-Wen exponent (1 to 10; default 1, solved exactly; other values by Runge-Kutta).
    effects, fixed, axis, out_of_range
        See :class:`~endocal.models.base.HysteresisModel`.

    Notes
    -----
    The inverse is numerical (bisection per sample on the non-decreasing step map), checked on a
    sweep of the fitted range: with ``k_lin = 0`` the friction state saturates and compensation is
    refused.
    """

    base_name = "bouc-wen"
    _family = BOUC_WEN
    _sigmas = (0.5, 1.0, 2.0, 5.0)

    def __init__(self, n: float = 1.0, *, effects=(), fixed=None, axis=None, out_of_range="error"):
        self.n = n
        self.effects = effects
        self.fixed = fixed
        self.axis = axis
        self.out_of_range = out_of_range

    def _resolve_structure(self, effects: list[Effect], v, data) -> dict:
        if isinstance(self.n, bool) or not isinstance(self.n, (int, float)) or not 1.0 <= float(self.n) <= 10.0:
            raise ModelError(f"n (the Bouc-Wen exponent) must be a number in 1..10, got {self.n!r}")
        return {"exponent": float(self.n)}

    def _base_names(self, structure: dict) -> list[str]:
        return ["k_lin", "k_hys_deg", "rho", "sigma", "offset_deg"]

    def _bounds(self) -> dict[str, tuple[float, float]]:
        return {"k_lin": (0.0, np.inf), "k_hys_deg": (0.0, np.inf), "rho": (1e-9, np.inf), "sigma": (0.5, np.inf),
                "offset_deg": (-np.inf, np.inf)}

    def _from_regression(self, rho, sigma, a, b, c) -> dict[str, float]:
        return {"k_lin": a, "k_hys_deg": b, "rho": rho, "sigma": sigma, "offset_deg": c}

    def _law(self, structure: dict, p: dict) -> tuple:
        return (BOUC_WEN, float(p["k_lin"]), -float(p["k_hys_deg"]), float(p["rho"]), float(p["sigma"]),
                self._exponent(structure), float(p["offset_deg"]))

    def _base_describe(self, structure: dict, p: dict, se: dict, inner: str) -> str:
        u = self.drive_unit_
        n = self._exponent(structure)
        parts = [f"k_lin={fmt_value(p['k_lin'], se.get('k_lin'), f'deg/{u}')}",
                 f"k_hys={fmt_value(p['k_hys_deg'], se.get('k_hys_deg'), 'deg')}",
                 f"rho={fmt_value(p['rho'], se.get('rho'), f'1/{u}')}",
                 f"sigma={fmt_value(p['sigma'], se.get('sigma'))}", f"n={n:g} (fixed)"]
        out = f"BoucWen({inner}) [k_lin*u - k_hys*w, dw = rho(du - sigma|du||w|^(n-1)w + (sigma-1)du|w|^n); " \
              f"{', '.join(parts)}]"
        if p["offset_deg"] != 0.0:
            out += f" {'+' if p['offset_deg'] >= 0 else '-'} " \
                   f"{fmt_value(abs(p['offset_deg']), se.get('offset_deg'), 'deg')}"
        return out
