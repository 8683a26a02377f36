"""``load:COLUMN``: friction that scales with a logged covariate (e.g. sheath curvature).

Capstan friction of a tendon in its sheath grows with the wrap angle of the sheath
(``T_out = T_in e^{μΘ}``): when the insertion tube curves more, the hysteresis widens.
Any extra numeric column ``x`` of the data (``sheath_wrap_deg``, a shape sensor, a
force) can be named; the extra backlash is a play on the command whose half width
follows the covariate linearly::

    w_k = max(c_up · (x_k - x_lo) + c_down · (x_hi - x_k), 0)
    v_k = clip(v_{k-1}, u_k - w_k, u_k + w_k)

``c_up`` (``load_<COLUMN>_up``) and ``c_down`` (``load_<COLUMN>_down``), both >= 0 (deg of
play per unit of ``x``), are fitted: friction growing with the covariate, or falling
with it. ``x_lo``, ``x_hi`` (``load_<COLUMN>_lo``, ``_hi``) are the covariate's range in the
fitted data, held fixed: the base model carries the width at the least-friction end,
the term what the covariate adds. (Two one-signed gains rather than one signed gain keep
the model smooth where the sign would change, so the fit does not stall at zero.) The inverse is exact for a logged covariate (the batch inverse needs the column);
the future covariate is unknown to a control loop, so the effect does not stream.
"""

from __future__ import annotations

import numpy as np

from endocal.errors import ModelError
from endocal.models._kernels import varplay_forward_jac, varplay_inverse
from endocal.models.data import HysteresisData
from endocal.models.effects.base import InputEffect
from endocal.models.params import Parameter, fmt_value


class Load(InputEffect):
    """Covariate-scaled friction play (module docstring).

    Parameters
    ----------
    column : str
        The extra column of the data holding the covariate.
    """

    name = "load"
    order = 25
    cause = ("friction that scales with a logged load: sheath curvature (capstan, e^{mu*wrap}), "
             "tube shape or contact, widening the hysteresis when it grows")
    signature = ("loop width (residual at reversals, with the sign of the motion) that changes with the "
                 "covariate; residual correlated with the covariate times the direction of motion")
    protocol = "the same motion repeated while the covariate changes (e.g. different sheath curvatures)"
    units = {"up": "deg/unit", "down": "deg/unit", "lo": "", "hi": ""}

    def __init__(self, column: str | None = None):
        if not isinstance(column, str) or not column.strip():
            raise ModelError("load needs a column name: write load:COLUMN (e.g. load:sheath_wrap_deg)")
        self.column = column.strip()

    @classmethod
    def from_argument(cls, arg: str) -> Load:
        """``load:COLUMN``."""
        return cls(column=arg)

    @property
    def prefix(self) -> str:
        return f"load_{self.column}"

    @property
    def label(self) -> str:
        return f"load:{self.column}"

    def settings(self) -> dict:
        return {"column": self.column}

    def check(self, data: HysteresisData) -> None:
        try:
            x = data.column(self.column)
        except ModelError as exc:
            raise ModelError(f"effect '{self.label}': {exc}") from None
        if np.ptp(x) == 0.0:
            raise ModelError(f"effect '{self.label}': column '{self.column}' is constant ({x[0]:g}) in the data, "
                             "so friction scaling with it cannot be identified; log a covariate that varies")

    def constants(self, data: HysteresisData) -> dict[str, float]:
        """Parameters set from the data and held fixed: the covariate's range."""
        x = data.column(self.column)
        return {"lo": float(x.min()), "hi": float(x.max())}

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        c = self.constants(data)
        return [Parameter(f"{self.prefix}_up", 0.0, 0.0, np.inf), Parameter(f"{self.prefix}_down", 0.0, 0.0, np.inf),
                Parameter(f"{self.prefix}_lo", c["lo"]), Parameter(f"{self.prefix}_hi", c["hi"])]

    def start_candidates(self, data: HysteresisData, u: np.ndarray) -> list[dict]:
        """Start values tried before the fit (the best is kept): extra play up to 5 % of the command span."""
        x = data.column(self.column)
        scale = float(np.ptp(u)) / float(np.ptp(x))
        return [{"up": 0.0, "down": 0.0}] + [{side: f * scale, other: 0.0} for side, other in (("up", "down"), ("down", "up"))
                                             for f in (0.01, 0.05)]

    def _width(self, p: dict, data: HysteresisData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x = data.column(self.column)
        above, below = x - p["lo"], p["hi"] - x
        return np.maximum(p["up"] * above + p["down"] * below, 0.0), above, below

    def apply(self, p: dict, u: np.ndarray, data: HysteresisData) -> np.ndarray:
        v, _, _ = self.apply_jac(p, u, data, np.zeros((len(u), 0)))
        return v

    def apply_jac(self, p: dict, u: np.ndarray, data: HysteresisData, M: np.ndarray):
        w, above, below = self._width(p, data)
        q = M.shape[1]
        zeros = np.zeros((w.size, 2))  # lo and hi are held fixed: no derivative needed
        raw = p["up"] * above + p["down"] * below
        active = raw >= 0.0  # the width is clipped at zero only for covariates beyond the fitted range
        Wg = np.column_stack([np.zeros((w.size, q)), np.where(active, above, 0.0), np.where(active, below, 0.0), zeros])
        v, J = varplay_forward_jac(np.ascontiguousarray(u, dtype=float), w, Wg, np.ascontiguousarray(M, dtype=float),
                                   data.run_starts)
        return v, J[:, q:], J[:, :q]

    def invert(self, p: dict, v: np.ndarray, data: HysteresisData) -> np.ndarray:
        w, _, _ = self._width(p, data)
        return varplay_inverse(np.ascontiguousarray(v, dtype=float), w, data.run_starts)

    def wrap(self, inner: str) -> str:
        return f"loadplay({inner})"

    def describe(self, p: dict, se: dict) -> str:
        x = self.column
        return (f"loadplay = load[up={fmt_value(p['up'], se.get('up'), 'deg')}*({x}-{p['lo']:.4g}), "
                f"down={fmt_value(p['down'], se.get('down'), 'deg')}*({p['hi']:.4g}-{x})]")

    def is_zero(self, p: dict) -> bool:
        return p["up"] == 0.0 and p["down"] == 0.0
