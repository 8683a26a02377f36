"""Shared machinery of the smooth friction bases without return-point memory (``bouc-wen``, ``dahl``).

Both write the output as a linear spring in parallel with one friction state (kernels:
:mod:`endocal.models._smooth_friction`)::

    y = k_lin * v - k_hys * w(v) + offset,   w in [-1, 1], dw/dv from the base's law

the positioning form of a friction law (the output lags the input by what friction holds back, as
a piezo stage's ``y = d u - h`` in Rakotondrabe, IEEE T-ASE 8, 2011, eq. 1): ``k_lin`` (deg per unit
of the drive) is the slope far from reversals, ``k_hys`` (deg) half the height of the saturated loop,
and ``rho`` (per unit of the drive) how fast the state saturates after a reversal. Right after a
reversal from saturation the slope is ``k_lin - k_hys * dw/dv``: the tip holds when that is zero, then
picks up along an exponential. A small reversal inside the loop does not return to the branch it
left.

The inverse is numerical (bisection per sample on the step map, which is increasing when ``k_lin``
exceeds ``k_hys`` times the state's steepest slope: the tip never moves against the knob). It is
checked on a sweep of the fitted range before it is used: where the tip would move back (or stand
still over a stretch) while the knob moves on, a command cannot be recovered from the angle, and
compensation is refused in one line.
"""

from __future__ import annotations

from abc import abstractmethod
from typing import ClassVar

import numpy as np
from scipy.optimize import lsq_linear

from endocal.errors import CompensationRefusedError, ModelError
from endocal.models._smooth_friction import (
    first_input,
    friction_inverse,
    friction_states,
    inverse_step,
    scaled_friction_inverse,
    scaled_friction_states,
)
from endocal.models.base import HysteresisModel
from endocal.models.data import HysteresisData
from endocal.models.effects.base import Effect
from endocal.models.params import Parameter

#: ``rho * half span`` tried for the start (the state saturates within 1/rho of the drive after a reversal)
_RHO_SPANS = (0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
#: the inverse's round trip on a sweep must give the sweep's command back within this share of the fitted span
INVERSE_TOL = 1e-6
#: samples the start search regresses on at most (every k-th)
_START_SAMPLES = 5000


class _Stepper:
    """One-sample numerical inverse holding ``(v_prev, w_prev)``."""

    def __init__(self, model, law, v_range):
        self.model = model
        self.law = law
        self.v_lo, self.v_hi = float(v_range[0]), float(v_range[1])
        self.reset()

    def reset(self) -> None:
        self.started = False
        self.v = 0.0
        self.w = 0.0

    def prime(self, v_history: np.ndarray, y_history: np.ndarray) -> None:
        """Continue from the state after the inputs ``v_history`` (its outputs ``y_history`` are not needed)."""
        family, k_lin, k_hys, rho, sigma, expo, _ = self.law
        v = np.ascontiguousarray(v_history, dtype=float)
        w = friction_states(family, v, rho, sigma, expo, np.zeros(1, np.int64))
        self.v, self.w, self.started = float(v[-1]), float(w[-1]), True

    def step(self, y: float) -> float:
        family, k_lin, k_hys, rho, sigma, expo, offset = self.law
        y = float(y) - offset
        if not self.started:
            self.v, miss = first_input(y, k_lin, self.v_lo, self.v_hi)
            self.w, self.started = 0.0, True
        else:
            self.v, self.w, miss = inverse_step(family, y, self.v, self.w, k_lin, k_hys, rho, sigma, expo,
                                                self.v_lo, self.v_hi)
        if miss > INVERSE_TOL * max(1.0, abs(y)):
            raise CompensationRefusedError(self.model._unreachable(miss))
        return self.v


class SmoothFrictionModel(HysteresisModel):
    """Base of :class:`~endocal.models.boucwen.BoucWenModel` and :class:`~endocal.models.dahl.DahlModel`."""

    inverse_kind: ClassVar[str] = "numerical (bisection per sample; checked on a sweep)"
    #: a small reversal inside the loop does not return to the branch it left
    return_point_memory: ClassVar[bool] = False
    #: one friction state whose bound an effect may scale (``rate:friction``)
    friction_state: ClassVar[bool] = True
    #: kernel family code (:mod:`endocal.models._smooth_friction`)
    _family: ClassVar[int] = 0

    @abstractmethod
    def _law(self, structure: dict, p: dict) -> tuple:
        """``(family, k_lin, c_w, rho, sigma, exponent, offset)`` of the kernels from the parameters, ``c_w = -k_hys``
        the state's coefficient in the output."""

    @abstractmethod
    def _from_regression(self, rho: float, sigma: float, a: float, b: float, c: float) -> dict[str, float]:
        """Base parameters (short names) from a start: ``y = a v - b w + c`` with the state of ``rho``, ``sigma``."""

    @abstractmethod
    def _bounds(self) -> dict[str, tuple[float, float]]:
        """Bounds of each base parameter (short names)."""

    _sigmas: ClassVar[tuple[float, ...]] = (1.0,)

    def _exponent(self, structure: dict) -> float:
        return float(structure["exponent"])

    # ------------------------------------------------------------------ fit
    def _base_initial(self, structure: dict, v: np.ndarray, data: HysteresisData) -> list[Parameter]:
        """A grid of ``rho`` (and ``sigma``), each with the linear coefficients by bounded least squares
        (``y = a v - b w + c``, ``a, b >= 0``)."""
        v = np.ascontiguousarray(v, dtype=float)
        half = 0.5 * float(np.ptp(v))
        if not half > 0:
            raise ModelError(f"the command reaching the {self.base_name} model is constant: nothing to fit")
        stride = max(1, v.size // _START_SAMPLES)
        y = data.meas_deg[::stride]
        expo = self._exponent(structure)
        best = None
        for f in _RHO_SPANS:
            rho = f / half
            for sigma in self._sigmas:
                w = friction_states(self._family, v, rho, sigma, expo, data.run_starts)[::stride]
                A = np.column_stack([v[::stride], -w, np.ones(w.size)])
                sol = lsq_linear(A, y, bounds=([0.0, 0.0, -np.inf], [np.inf, np.inf, np.inf]), method="bvls")
                cost = float(np.sum((A @ sol.x - y) ** 2))
                if best is None or cost < best[0]:
                    best = (cost, rho, sigma, sol.x)
        _, rho, sigma, (a, b, c) = best
        if not b > 1e-6 * max(float(np.ptp(y)), 1e-12):
            # no positive loop at any rho (a pinched or reversed loop, or an input effect's start that hides
            # it): at k_hys = 0 the state's law has no gradient, so start from half the gap between the
            # directions of motion, saturated within a tenth of the span, and let the fit take it from there
            du = np.diff(v, prepend=v[0])
            s = np.sign(du)
            idx = np.where(s != 0, np.arange(s.size), 0)
            s = s[np.maximum.accumulate(idx)]
            A = np.column_stack([v, -s, np.ones(v.size)])[::stride]
            sol = lsq_linear(A, y, bounds=([0.0, 0.0, -np.inf], [np.inf, np.inf, np.inf]), method="bvls")
            a, b, c = (float(x) for x in sol.x)
            b = max(b, 0.02 * float(np.ptp(y)))
            rho, sigma = 10.0 / (2.0 * half), 1.0
        start = self._from_regression(rho, sigma, float(a), float(b), float(c))
        bounds = self._bounds()
        return [Parameter(k, start[k], *bounds[k]) for k in self._base_names(structure)]

    # ------------------------------------------------------------------ forward / inverse
    def _base_forward(self, structure: dict, p: dict, v: np.ndarray, run_starts: np.ndarray,
                      factor: np.ndarray | None = None) -> np.ndarray:
        """``factor`` (n,): the friction's bound at each sample, times its own, where effects scale it
        (``rate:friction``, ``load:friction:COLUMN``; :meth:`HysteresisModel._friction_factor`)."""
        family, k_lin, k_hys, rho, sigma, expo, offset = self._law(structure, p)
        v = np.ascontiguousarray(v, dtype=float)
        if factor is None:
            return k_lin * v + k_hys * friction_states(family, v, rho, sigma, expo, run_starts) + offset
        f = np.ascontiguousarray(factor, dtype=float)
        return k_lin * v + k_hys * f * scaled_friction_states(family, v, rho, sigma, expo, run_starts, f) + offset

    def _unreachable(self, miss: float) -> str:
        return (f"the {self.base_name} base cannot be inverted: a desired angle lies {miss:.3g} deg beyond what any "
                f"command reaches from the model's state (its tip stands still or moves back while the knob moves on): "
                f"compensation refused; use a base with an exact inverse (--model pi) for compensation")

    def check_inverse(self) -> None:
        """Refuse compensation when the base's inverse does not converge on a sweep of the fitted range.

        The sweep (0 -> top -> bottom -> 0 and a damped return, 400 samples per leg) is run forward
        through the base and back through its inverse; the commands must come back within
        ``INVERSE_TOL`` of the fitted span.

        Raises
        ------
        CompensationRefusedError
            One line naming the base: compensation refused.
        """
        self._require_fitted()
        base_p, _ = self._grouped(self.params_)
        memo = getattr(self, "_inverse_checked", None)
        key = tuple(sorted(base_p.items()))
        if memo == key:
            return
        lo, hi = self._v_range()
        c_lo, c_hi = self.cmd_range_deg_
        if not (np.isfinite(c_lo) and np.isfinite(c_hi) and c_hi > c_lo):
            c_lo, c_hi = lo, hi
        mid, half = 0.5 * (c_lo + c_hi), 0.5 * (c_hi - c_lo)
        legs = [np.linspace(mid, c_hi, 400), np.linspace(c_hi, c_lo, 800), np.linspace(c_lo, mid + 0.5 * half, 600),
                np.linspace(mid + 0.5 * half, mid - 0.25 * half, 300), np.linspace(mid - 0.25 * half, mid, 100)]
        v = np.concatenate(legs)
        starts = np.zeros(1, np.int64)
        family, k_lin, k_hys, rho, sigma, expo, offset = self._law(self.structure_, base_p)
        y = k_lin * v + k_hys * friction_states(family, v, rho, sigma, expo, starts)
        back, _ = friction_inverse(family, y, k_lin, k_hys, rho, sigma, expo, lo, hi, starts)
        err = float(np.max(np.abs(back - v)))
        if not err <= INVERSE_TOL * max(half, 1e-9):
            raise CompensationRefusedError(f"the {self.base_name} base's inverse does not converge on a sweep of its fitted range "
                             f"(the command comes back {err:.3g} {self.drive_unit_} off: after a reversal its tip stands "
                             "still or moves back while the knob moves on, so the command cannot be told from the "
                             "angle): compensation refused; use a base with an exact inverse (--model pi) for "
                             "compensation")
        self._inverse_checked = key

    def _base_inverse(self, structure: dict, p: dict, y: np.ndarray, run_starts: np.ndarray, v_range,
                      factor: np.ndarray | None = None) -> np.ndarray:
        """``factor``: the friction's bound at each sample times its own, known ahead (a logged condition,
        ``load:friction:COLUMN``)."""
        self.check_inverse()
        family, k_lin, k_hys, rho, sigma, expo, offset = self._law(structure, p)
        y = np.ascontiguousarray(y, dtype=float) - offset
        f = np.ones(y.size) if factor is None else np.ascontiguousarray(factor, dtype=float)
        v, worst = scaled_friction_inverse(family, y, k_lin, k_hys, rho, sigma, expo, float(v_range[0]),
                                           float(v_range[1]), run_starts, f)
        if worst > INVERSE_TOL * max(1.0, float(np.max(np.abs(y))) if y.size else 1.0):
            raise CompensationRefusedError(self._unreachable(worst))
        return v

    def _base_stepper(self, structure: dict, p: dict, v_range):
        self.check_inverse()
        return _Stepper(self, self._law(structure, p), v_range)

    def _gauge(self, effects: list[Effect]) -> dict[str, float]:
        # the state's law is invariant to no scaling of its input (rho sets the scale), but an affine map
        # of it trades off against k_lin, k_hys, rho and the offset: an effect's own gauge fixes what would
        # (the envelope's middle slope and zero), as for branches that absorb any affine map
        for e in effects:
            if g := e.gauge("affine"):
                return g
        return {}
