"""``load:COLUMN``: friction that scales with a logged covariate (e.g. sheath curvature).

Capstan friction of a tendon in its sheath grows with the wrap angle of the sheath
(``T_out = T_in e^{μΘ}``): when the insertion tube curves more, the hysteresis widens.
Any extra numeric column ``x`` of the data (``sheath_wrap_deg``, a shape sensor, a
force) can be named; the extra backlash is a play on the command whose half width
follows the covariate linearly::

    w_k = c · (x_k - x_lo)   if c >= 0,     c · (x_k - x_hi)   if c < 0      (w_k >= 0)
    v_k = clip(v_{k-1}, u_k - w_k, u_k + w_k)

``c`` (``load_<COLUMN>_gain``, deg of play per unit of ``x``) is fitted; ``x_lo``, ``x_hi``
(``load_<COLUMN>_lo``, ``_hi``) are the covariate's range in the fitted data, held fixed:
the base model carries the width at the least-friction end, the term what the covariate
adds. The inverse is exact for a logged covariate (the batch inverse needs the column);
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
    units = {"gain": "deg/unit", "lo": "", "hi": ""}

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
        return [Parameter(f"{self.prefix}_gain", 0.0), Parameter(f"{self.prefix}_lo", c["lo"]),
                Parameter(f"{self.prefix}_hi", c["hi"])]

    def start_candidates(self, data: HysteresisData, u: np.ndarray) -> list[dict]:
        """Start values tried before the fit (the best is kept): extra play up to 5 % of the command span."""
        x = data.column(self.column)
        scale = float(np.ptp(u)) / float(np.ptp(x))
        return [{"gain": f * scale} for f in (-0.05, -0.01, 0.01, 0.05)]

    def _width(self, p: dict, data: HysteresisData) -> tuple[np.ndarray, np.ndarray]:
        x = data.column(self.column)
        g = float(p["gain"])
        dx = x - (p["lo"] if g >= 0.0 else p["hi"])
        return np.maximum(g * dx, 0.0), dx

    def apply(self, p: dict, u: np.ndarray, data: HysteresisData) -> np.ndarray:
        v, _, _ = self.apply_jac(p, u, data, np.zeros((len(u), 0)))
        return v

    def apply_jac(self, p: dict, u: np.ndarray, data: HysteresisData, M: np.ndarray):
        w, dx = self._width(p, data)
        q = M.shape[1]
        zeros = np.zeros((w.size, 2))  # lo and hi are held fixed: no derivative needed
        g = float(p["gain"])
        # dw/dgain = dx where the play is open (at gain 0: on the side a positive gain would open)
        active = (w > 0) | ((g == 0.0) & (dx > 0))
        Wg = np.column_stack([np.zeros((w.size, q)), np.where(active, dx, 0.0), zeros])
        v, J = varplay_forward_jac(np.ascontiguousarray(u, dtype=float), w, Wg, np.ascontiguousarray(M, dtype=float),
                                   data.run_starts)
        return v, J[:, q:], J[:, :q]

    def invert(self, p: dict, v: np.ndarray, data: HysteresisData) -> np.ndarray:
        w, _ = self._width(p, data)
        return varplay_inverse(np.ascontiguousarray(v, dtype=float), w, data.run_starts)

    def wrap(self, inner: str) -> str:
        return f"loadplay({inner})"

    def describe(self, p: dict, se: dict) -> str:
        return (f"loadplay = load[gain={fmt_value(p['gain'], se.get('gain'), 'deg')} per unit of {self.column} "
                f"above {p['lo']:.4g}]" if p["gain"] >= 0 else
                f"loadplay = load[gain={fmt_value(p['gain'], se.get('gain'), 'deg')} per unit of {self.column} "
                f"below {p['hi']:.4g}]")

    def is_zero(self, p: dict) -> bool:
        return p["gain"] == 0.0
