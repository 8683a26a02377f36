"""``tension``: sheath friction proportional to tendon tension (loops widen with the bend).

Capstan friction along the sheath is proportional to the tendon's tension (``|d ln T /
dΘ| = μ``), and the tension that holds a bend grows with the bend. So the knob travel lost
to friction at a reversal, the backlash, is not one width for the whole range (as in a
play operator of fixed threshold) but grows with the bend the tendon holds: loops around
a large bend are wider than loops around neutral, and a damped sine draws loops that
shrink as it decays. A Prandtl-Ishlinskii model cannot do this, its minor loops are
congruent (duodenoscope paper, eq. 7: the plays' thresholds are constants), nor can a
static envelope in front of it (eq. 6) without also changing the branches' slope.

Modelled as a play whose half width is proportional to the (envelope-shaped) command's
distance from neutral, taken at the previous sample::

    w_k = c · |x_{k-1}|,    v_k = clip(v_{k-1}, x_k - w_k, x_k + w_k)

with ``c`` (``tension_friction``, dimensionless: ``e^{μΘ} - 1`` to first order, the extra
knob travel per degree of bend) fitted in ``[0, 0.5]``. Using the previous sample keeps the
inverse explicit and causal, ``x_k = v_k ± c |x_{k-1}|`` while the drive moves, so the
whole model stays analytically invertible (on ``pi`` with the ``envelope``: eqs. 9-11,
then this, then eq. 10) and the effect streams.
"""

from __future__ import annotations

import numpy as np
from endocal.models._kernels import causal_play_inverse, play_inverse_step, play_reference, varplay_forward_jac
from endocal.models.data import HysteresisData
from endocal.models.effects.base import InputEffect
from endocal.models.params import Parameter

#: ``c`` above this would let the play swallow most of the knob's travel at large bends
C_MAX = 0.5


def tension_inverse(v: np.ndarray, c: float, run_starts: np.ndarray) -> np.ndarray:
    """Commands ``x`` (n,) whose tension play output is ``v`` (exact, causal): ``x_k = v_k ± c |x_{k-1}|``."""
    v = np.ascontiguousarray(v, dtype=float)
    return causal_play_inverse(v, np.zeros(v.size), np.full(v.size, float(c)), run_starts)


class Tension(InputEffect):
    """Tension-proportional friction play (module docstring). Parameter ``tension_friction``."""

    name = "tension"
    order = 95  # after the envelope: the width follows the bend-shaped command
    streamable = True
    stateful = True
    cause = ("capstan friction in the sheath is proportional to tendon tension, which grows with the bend: "
             "the backlash at a reversal grows with how far the tip is bent")
    signature = ("residual of opposite sign on the two branches that grows with the amplitude; large loops "
                 "too narrow and small loops too wide (a damped sine's late, small cycles over-predicted)")
    protocol = "cycles of several amplitudes (damped sine, random)"
    units = {"friction": ""}
    requires = ()
    residual = ()
    lookalikes = {}

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        return [Parameter(f"{self.prefix}_friction", 0.02, 0.0, C_MAX)]

    def start_candidates(self, data: HysteresisData, u: np.ndarray) -> list[dict]:
        """Start values tried before the fit (the best is kept): little or much tension friction."""
        return [{"friction": c} for c in (0.0, 0.03, 0.1)]

    def apply(self, p: dict, u: np.ndarray, data: HysteresisData) -> np.ndarray:
        # apply_jac's output without its Jacobian
        c = float(p["friction"])
        x = np.ascontiguousarray(u, dtype=float)
        prev = np.concatenate([x[:1], x[:-1]])
        none = np.zeros((x.size, 0))  # no Jacobian columns: the output alone
        return varplay_forward_jac(x, c * np.abs(prev), none, none, data.run_starts)[0]

    def apply_jac(self, p: dict, u: np.ndarray, data: HysteresisData, M: np.ndarray):
        """Output (n,), its derivative w.r.t. ``friction`` (n, 1) and w.r.t. upstream parameters (n, q)."""
        c = float(p["friction"])
        x = np.ascontiguousarray(u, dtype=float)
        M = np.ascontiguousarray(M, dtype=float)
        prev = np.concatenate([x[:1], x[:-1]])
        Mprev = np.concatenate([M[:1], M[:-1]])
        Wg = np.ascontiguousarray(np.column_stack([(c * np.sign(prev))[:, None] * Mprev, np.abs(prev)]))
        v, J = varplay_forward_jac(x, c * np.abs(prev), Wg, M, data.run_starts)
        q = M.shape[1]
        return v, J[:, q:], J[:, :q]

    def invert(self, p: dict, v: np.ndarray, data: HysteresisData) -> np.ndarray:
        return tension_inverse(np.ascontiguousarray(v, dtype=float), float(p["friction"]), data.run_starts)

    def stream_state(self, p: dict) -> np.ndarray:
        # [started, v_prev, x_prev]
        return np.zeros(3)

    def invert_step(self, p: dict, v: float, state: np.ndarray) -> float:
        if state[0] == 0.0:
            state[0], state[1], state[2] = 1.0, v, v
            return v
        x = play_inverse_step(v, state[1], state[2], float(p["friction"]) * abs(state[2]))
        state[1], state[2] = play_reference(v, state[1], x, state[2]), x
        return x

    def wrap(self, inner: str) -> str:
        return f"tplay({inner})"

    def describe(self, p: dict, se: dict) -> str:
        return "tplay = tension" + self._bracket(p, se)

    def is_zero(self, p: dict) -> bool:
        return p["friction"] == 0.0
