"""Shared machinery of the direction-dependent models (``linear``, ``bspline``).

Both describe the loop by an ascending branch ``φ_up(u)`` (followed while the command
increases) and a descending branch ``φ_down(u)``, joined at every reversal by a
backlash transition of slope ``s`` from the reversal point to the other branch
(thesis, section 2.3; Lee et al.). Written as a generalised play::

    y_k = clip(y_{k-1} + s (u_k - u_{k-1}),  min(φ_up, φ_down)(u_k),  max(φ_up, φ_down)(u_k))

which is continuous at reversals and needs no explicit direction flag. Each run
starts on the mid-line of the two branches. The step map is non-decreasing in
``u_k`` (branches increasing, ``s >= 0``), so the inverse is found sample by sample
by bisection (numerical inverse).
"""

from __future__ import annotations

from abc import abstractmethod
from typing import ClassVar

import numpy as np

from endocal.models._kernels import (
    gplay_forward,
    gplay_forward_jac,
    gplay_inverse,
    gplay_inverse_step,
    gplay_midline_inverse,
)
from endocal.models.base import HysteresisModel
from endocal.models.effects.base import Effect


def direction_masks(v: np.ndarray, run_starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Samples where the input increases / decreases (first sample of each run excluded)."""
    dv = np.diff(v, prepend=v[0])
    dv[run_starts] = 0.0
    return dv > 0, dv < 0


class _GPlayStepper:
    """One-sample numerical inverse of a generalised play, holding ``(u_prev, y_prev)``."""

    def __init__(self, slope, t_up, c_up, t_dn, c_dn, deg, v_range):
        self.args = (float(slope), np.ascontiguousarray(t_up), np.ascontiguousarray(c_up),
                     np.ascontiguousarray(t_dn), np.ascontiguousarray(c_dn), int(deg))
        self.v_min, self.v_max = float(v_range[0]), float(v_range[1])
        self.reset()

    def reset(self) -> None:
        self.started = False
        self.u = 0.0
        self.y = 0.0

    def prime(self, v_history: np.ndarray, y_history: np.ndarray) -> None:
        """Continue from the last forward state (command and output) of a history."""
        self.u, self.y, self.started = float(v_history[-1]), float(y_history[-1]), True

    def step(self, y: float) -> float:
        s, t_up, c_up, t_dn, c_dn, deg = self.args
        if not self.started:
            self.u, self.y = gplay_midline_inverse(y, t_up, c_up, t_dn, c_dn, deg, self.v_min, self.v_max)
            self.started = True
        else:
            self.u, self.y = gplay_inverse_step(y, self.u, self.y, s, t_up, c_up, t_dn, c_dn, deg,
                                                self.v_min, self.v_max)
        return self.u


class DirectionalModel(HysteresisModel):
    """Base of :class:`LinearModel` and :class:`BSplineModel` (not used directly)."""

    inverse_kind: ClassVar[str] = "numerical (bisection per sample)"

    @abstractmethod
    def _branches(self, structure: dict, p: dict):
        """``(t_up, c_up, t_down, c_down, degree)``: both branches as B-splines (extrapolated)."""

    @abstractmethod
    def _eval_branches(self, structure: dict, p: dict, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ascending and descending branch values at ``v`` (n,), each (n,)."""

    def _base_forward(self, structure: dict, p: dict, v: np.ndarray, run_starts: np.ndarray) -> np.ndarray:
        v = np.ascontiguousarray(v, dtype=float)
        up, down = self._eval_branches(structure, p, v)
        return gplay_forward(v, up, down, p["transition_slope"], run_starts)

    @abstractmethod
    def _branch_jac(self, structure: dict, p: dict, v: np.ndarray):
        """Branches at ``v``, their derivatives by the branch parameters and by ``v``.

        ``(up, down, J_up, J_down, dup_dv, ddown_dv)``; the columns of ``J_up``/``J_down``
        follow :meth:`_base_names` without ``transition_slope`` (the last name).
        """

    def _base_forward_jac(self, structure: dict, p: dict, v: np.ndarray, run_starts: np.ndarray, M: np.ndarray):
        v = np.ascontiguousarray(v, dtype=float)
        up, down, J_up, J_dn, d_up, d_dn = self._branch_jac(structure, p, v)
        return gplay_forward_jac(v, up, down, np.ascontiguousarray(J_up, dtype=float),
                                 np.ascontiguousarray(J_dn, dtype=float), d_up, d_dn, float(p["transition_slope"]),
                                 np.ascontiguousarray(M, dtype=float), run_starts)

    def _base_inverse(self, structure: dict, p: dict, y: np.ndarray, run_starts: np.ndarray, v_range) -> np.ndarray:
        t_up, c_up, t_dn, c_dn, deg = self._branches(structure, p)
        return gplay_inverse(np.ascontiguousarray(y, dtype=float), p["transition_slope"], t_up, c_up, t_dn, c_dn,
                             deg, float(v_range[0]), float(v_range[1]), run_starts)

    def _base_stepper(self, structure: dict, p: dict, v_range):
        t_up, c_up, t_dn, c_dn, deg = self._branches(structure, p)
        return _GPlayStepper(p["transition_slope"], t_up, c_up, t_dn, c_dn, deg, v_range)

    def _gauge(self, effects: list[Effect]) -> dict[str, float]:
        # The branches absorb any affine map of their input: an effect's own gauge fixes what would
        # trade off against it (the envelope's middle slope and zero: f only carries the shape).
        for e in effects:
            if g := e.gauge("affine"):
                return g
        return {}

