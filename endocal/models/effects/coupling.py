"""``coupling``: the other bending axis moving this one.

The tendons of one axis pass the bending section off its neutral plane (tendon-hole
offsets), so bending the other axis pulls or slackens them; and a bending plane that
deviates from its nominal direction (duodenoscope paper, sec. 3.2) projects part of the
other axis's bend onto this axis's measured angle (thesis eq. 1), with a different
deviation on each half-plane. Both show as a term in the other axis's position ``x``::

    y += a · x + b · |x|

``a`` (``coupling_linear``) is the part odd in ``x`` (anchor shift, symmetric deviation),
``b`` (``coupling_abs``) the part even in ``x`` (unequal deviations of the two half-planes).
``x`` is the extra column ``other_cmd_deg`` (the other knob's command, deg) unless another
is named: ``coupling:ml_meas_deg`` uses the other axis's measured angle. The term does not
depend on this axis's command, so the inverse subtracts it exactly; it needs the other
axis's logged trajectory and therefore does not stream.
"""

from __future__ import annotations

import numpy as np

from endocal.errors import ModelError
from endocal.models.data import OTHER_CMD, HysteresisData
from endocal.models.effects.base import OutputEffect
from endocal.models.params import Parameter, fmt_value


class Coupling(OutputEffect):
    """Cross-coupling from the other axis (module docstring).

    Parameters
    ----------
    column : str
        Extra column holding the other axis's position (deg); default ``other_cmd_deg``.

    Fitted parameters (prefix ``coupling_``): ``linear`` and ``abs`` (deg of this axis per
    deg of the other).
    """

    name = "coupling"
    depends_on_command = False
    cause = ("cross-coupling: the other axis's tendons and bend pull on this axis's tendons "
             "(tendon-hole offsets), and deviated bending planes project the other bend onto this angle")
    signature = "residual that follows the other axis's position (odd or even in it), not this axis's command"
    protocol = "move the other knob alone, or both knobs at different frequencies"
    units = {"linear": "deg/deg", "abs": "deg/deg"}

    def __init__(self, column: str = OTHER_CMD):
        if not isinstance(column, str) or not column:
            raise ModelError(f"coupling: column must be a column name, got {column!r}")
        self.column = column

    @classmethod
    def from_argument(cls, arg: str) -> Coupling:
        """``coupling:COLUMN`` names the column with the other axis's position."""
        return cls(column=arg.strip())

    @property
    def label(self) -> str:
        return self.name if self.column == OTHER_CMD else f"{self.name}:{self.column}"

    def settings(self) -> dict:
        return {"column": self.column}

    def check(self, data: HysteresisData) -> None:
        try:
            data.column(self.column)
        except ModelError as exc:
            raise ModelError(f"effect '{self.label}' needs the other axis's position: {exc}") from None

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        return [Parameter(f"{self.prefix}_linear", 0.0), Parameter(f"{self.prefix}_abs", 0.0)]

    def _regressors(self, data: HysteresisData) -> np.ndarray:
        x = data.column(self.column)
        return np.column_stack([x, np.abs(x)])

    def term(self, p: dict, cmd: np.ndarray, data: HysteresisData) -> np.ndarray:
        return self._regressors(data) @ np.array([p["linear"], p["abs"]])

    def term_jac(self, p: dict, cmd: np.ndarray, data: HysteresisData):
        X = self._regressors(data)
        return X @ np.array([p["linear"], p["abs"]]), X

    def describe(self, p: dict, se: dict) -> str:
        x = self.column
        parts = []
        if p["linear"] != 0.0:
            parts.append(f"{fmt_value(p['linear'], se.get('linear'))}*{x}")
        if p["abs"] != 0.0:
            parts.append(f"{fmt_value(p['abs'], se.get('abs'))}*|{x}|")
        return "coupling[" + " + ".join(parts) + "]"
