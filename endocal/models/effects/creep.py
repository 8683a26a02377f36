"""``creep``: viscoelastic relaxation that keeps moving the tip after the knob stops.

The sheath and the bending section's cover are viscoelastic (a standard linear
solid): a share ``a`` of the bend follows the quasi-static bend ``y_qs`` (the base
model's output) only through a first-order lag of time constant ``τ``::

    y = (1 - a) y_qs + a ŷ,     dŷ/dt = (y_qs - ŷ) / τ

i.e. the term ``-a (y_qs - ŷ)`` on the quasi-static output. Discretised exactly for an
input held over each sample: ``ŷ_k = ŷ_{k-1} + (1 - e^{-Δt_k/τ}) (y_qs,k - ŷ_{k-1})``,
``ŷ`` starting at rest on ``y_qs`` at each run's start. Parameters ``creep_fraction``
(``a``, 0..0.95) and ``creep_tau_s``. It acts on the base's output, so it is an
:class:`OutputFilter`: a third kind of effect besides input transforms and additive
terms. The inverse is exact and causal (solve each sample for ``y_qs``), so it streams
given the sample period.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from endocal.errors import ModelError
from endocal.models.data import HysteresisData, half_cycles
from endocal.models.effects.base import OutputFilter
from endocal.models.effects.requirements import TIME_STAMPS, holds_after_moves
from endocal.models.params import Parameter

_MAX_FRACTION = 0.95


@njit(cache=True)
def creep_forward_jac(y, t, a, tau, J, run_starts):
    """Creep filter of ``y`` and the filtered Jacobian.

    ``J`` (n, m) is the Jacobian of ``y`` w.r.t. m upstream parameters; returns ``out`` (n,),
    ``Jout`` (n, m) = the filter applied to every column, and ``own`` (n, 2) w.r.t. (a, tau).
    """
    n = y.shape[0]
    m = J.shape[1]
    out = np.empty(n)
    Jout = np.empty((n, m))
    own = np.zeros((n, 2))
    sj = np.zeros(m)
    n_runs = run_starts.shape[0]
    for r in range(n_runs):
        lo = run_starts[r]
        hi = run_starts[r + 1] if r + 1 < n_runs else n
        s = y[lo]
        ds_tau = 0.0
        for j in range(m):
            sj[j] = J[lo, j]
        for k in range(lo, hi):
            if k > lo:
                dt = t[k] - t[k - 1]
                e = math.exp(-dt / tau)
                alpha = 1.0 - e
                dalpha = -e * dt / (tau * tau)
                ds_tau = (1.0 - alpha) * ds_tau + dalpha * (y[k] - s)
                s = s + alpha * (y[k] - s)
                for j in range(m):
                    sj[j] = sj[j] + alpha * (J[k, j] - sj[j])
            out[k] = (1.0 - a) * y[k] + a * s
            for j in range(m):
                Jout[k, j] = (1.0 - a) * J[k, j] + a * sj[j]
            own[k, 0] = s - y[k]
            own[k, 1] = a * ds_tau
    return out, Jout, own


@njit(cache=True)
def creep_inverse(yo, t, a, tau, run_starts):
    """Base output whose creep-filtered output is ``yo`` (exact, sample by sample)."""
    n = yo.shape[0]
    y = np.empty(n)
    n_runs = run_starts.shape[0]
    for r in range(n_runs):
        lo = run_starts[r]
        hi = run_starts[r + 1] if r + 1 < n_runs else n
        y[lo] = yo[lo]
        s = yo[lo]
        for k in range(lo + 1, hi):
            alpha = 1.0 - math.exp(-(t[k] - t[k - 1]) / tau)
            # yo = (1-a) y + a (s + alpha (y - s))
            y[k] = (yo[k] - a * (1.0 - alpha) * s) / (1.0 - a + a * alpha)
            s = s + alpha * (y[k] - s)
    return y


#: :meth:`Creep.implausible`: the shortest time constant, as a share of the records' median half-cycle, that
#: can be creep. A relaxation of a tenth of a half-cycle has ended (to e^-10) long before the reversal: it
#: smooths and lags each motion, which a lag of the bend behind the knob (`delay`, `rate`) also does, and no
#: longer moves the tip after the knob stops. The sheath's creep takes seconds (the simulator's 2 s).
MIN_TAU_SHARE = 0.1

#: Hold after each move of ``--next``'s creep segment (s): 5 s holds 2.5 time constants of the
#: simulator's 2 s (92 % of the relaxation); a relaxation slower than that shows as its start.
HOLD_S = 5.0


class Creep(OutputFilter):
    """Viscoelastic creep of the bend (module docstring).

    Fitted parameters (prefix ``creep_``): ``fraction`` (share of the bend that relaxes,
    0..0.95) and ``tau_s`` (relaxation time constant, s).
    """

    name = "creep"
    order = 10  # the bend relaxes before the tracker reads it (coupling)
    streamable = True
    stateful = True
    needs_period = True
    cause = "viscoelastic sheath and cover (standard linear solid): part of the bend relaxes slowly"
    signature = ("residual that decays exponentially during holds after each move (the tip keeps moving "
                 "after the knob stops), with the sign of the last move")
    protocol = "steps with holds of several seconds (staircase)"
    units = {"fraction": "", "tau_s": "s"}
    needs = ("t_s",)
    requires = (TIME_STAMPS, holds_after_moves(
        "it shows as the tip still moving after the knob stops: run `staircase`",
        # fitted and scored on motion alone its slow memory takes up smoother reversals, a lag or how the
        # records start, and its refits failed on other records of the same plant (red-team runs)
        caution="no record holds the knob still after a move, where creep shows itself (the tip still moving after "
                "the knob stops): fitted on motion alone it may stand for smoother reversals, a lag or how the "
                "records start; record a `staircase` to confirm it"))
    residual = ("regime:hold",)
    lookalikes = {"drift": 'creep relaxes after each motion and stops, drift keeps going at a constant rate: run `staircase` (creep restarts at every step) and `hold` (drift keeps going with the knob still)'}
    sim_section = "creep"

    def segment(self, design, n_half_cycles: int):
        """Moves with a hold after each (a staircase of one step, repeated): the tip still moving after the knob stops."""
        A = design.amplitude
        speed = min(2.0 * math.pi * design.f_typ_hz * A, design.max_start_dps)
        cycles = max(1, math.ceil(n_half_cycles / 2))
        k = design.add("staircase", axes=[design.axis], amplitude_deg=A, offset_deg=design.centre, steps=1,
                       hold_s=HOLD_S, step_rate_dps=round(speed, 3), cycles=cycles)
        return design.planned(k, 2 * cycles)

    def check(self, data: HysteresisData) -> None:
        data.require_time("effect 'creep'")

    def _tau_bounds(self, data: HysteresisData) -> tuple[float, float]:
        t = data.require_time("effect 'creep'")
        dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
        spans = [t[sl.stop - 1] - t[sl.start] for sl in data.run_slices()]
        return max(0.5 * dt, 1e-3), max(float(max(spans)), 2.0 * dt)

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        lo, hi = self._tau_bounds(data)
        return [Parameter(f"{self.prefix}_fraction", 0.05, 0.0, _MAX_FRACTION),
                Parameter(f"{self.prefix}_tau_s", min(max(1.0, lo), hi), lo, hi)]

    def start_candidates(self, data: HysteresisData, u: np.ndarray) -> list[dict]:
        """Start values tried before the fit (the best is kept)."""
        lo, hi = self._tau_bounds(data)
        # the time constant is the nonlinear one; the fraction scales the term and is found from any start
        return [{"fraction": 0.1, "tau_s": tau} for tau in (0.3, 1.0, 3.0, 10.0) if lo <= tau <= hi]

    def _run(self, p, y, data, J):
        t = data.require_time("effect 'creep'")
        return creep_forward_jac(np.ascontiguousarray(y, dtype=float), t, float(p["fraction"]), float(p["tau_s"]),
                                 np.ascontiguousarray(J, dtype=float), data.run_starts)

    def apply(self, p: dict, y: np.ndarray, data: HysteresisData) -> np.ndarray:
        return self._run(p, y, data, np.zeros((len(y), 0)))[0]

    def apply_jac(self, p: dict, y: np.ndarray, data: HysteresisData, J: np.ndarray):
        """Filtered output, the filtered upstream Jacobian (n, m) and the own columns (n, 2)."""
        return self._run(p, y, data, J)

    def invert(self, p: dict, y: np.ndarray, data: HysteresisData) -> np.ndarray:
        t = data.require_time("effect 'creep'")
        return creep_inverse(np.ascontiguousarray(y, dtype=float), t, float(p["fraction"]), float(p["tau_s"]),
                             data.run_starts)

    def stream_state(self, p: dict, dt_s: float | None = None) -> np.ndarray:
        if dt_s is None or not dt_s > 0:
            raise ModelError("effect 'creep' streams only with a fixed sample period: give dt_s (s) to the compensator")
        # [started, slow state, alpha]
        return np.array([0.0, 0.0, 1.0 - math.exp(-dt_s / float(p["tau_s"]))])

    def invert_step(self, p: dict, y: float, state: np.ndarray) -> float:
        a = float(p["fraction"])
        if state[0] == 0.0:
            state[0], state[1] = 1.0, y
            return y
        alpha, s = state[2], state[1]
        yb = (y - a * (1.0 - alpha) * s) / (1.0 - a + a * alpha)
        state[1] = s + alpha * (yb - s)
        return yb

    def implausible(self, p: dict, data: HysteresisData) -> str:
        """A creep relaxes after the motion that caused it. One whose time constant is under
        :data:`MIN_TAU_SHARE` of the records' median half-cycle (the time between the command's
        reversals, holds included) has relaxed within each motion: it is a lag of the bend behind
        the knob, here taken up by a filter on the output (a real piezo stack's 1 Hz cycles, fitted on
        motion alone: 0.037 s against half-cycles of 0.5 s)."""
        if data.t_s is None:
            return ""
        half = np.diff(data.t_s[half_cycles(data, 0.05)], axis=1).ravel()
        if half.size < 2:
            return ""
        half_s = float(np.median(half))
        tau = float(p["tau_s"])
        if not (half_s > 0 and tau < MIN_TAU_SHARE * half_s):
            return ""
        return (f"{self.prefix}_tau_s = {tau:.3g} s is {100 * tau / half_s:.0f} % of the records' median half-cycle "
                f"({half_s:.3g} s): a relaxation that ends within each motion is a lag of the bend behind the knob "
                "(delay, rate), not the tip moving on after the knob stops")

    def describe(self, p: dict, se: dict) -> str:
        return "creep" + self._bracket(p, se)

    def is_zero(self, p: dict) -> bool:
        return p["fraction"] == 0.0
