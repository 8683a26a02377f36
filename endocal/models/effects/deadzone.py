"""``deadzone``: tendon slack taken up when the bend crosses neutral.

Each tendon of the antagonistic pair has some free length (slack). Far from neutral
the bending section springs back elastically and keeps the pulling tendon taut, so
the drive follows the knob one to one. Near the neutral bend the section no longer
springs back (its joint friction holds it): the loose tendon must be wound in before
the other one pulls, and the knob travels ``2h`` with no effect. Written on the
effective drive position ``v`` (deg of knob, what the base model sees), with
``s = v - m`` and ``x = u - m``::

    p_k = max(s_{k-1} + Δx_k, c)      if s_{k-1} >  c   (elastic: v follows the knob)
          min(s_{k-1} + Δx_k, -c)     if s_{k-1} < -c
          s_{k-1}                     otherwise          (frozen inside the band)
    s_k = clip(p_k, x_k - h, x_k + h)                     (a tendon cannot stretch past its slack)

``h`` (``deadzone_slack_deg``) is the half play of the slack in knob degrees, ``c``
(``deadzone_band_deg``) the half width of the band around ``m`` (``deadzone_center_deg``)
where the section does not spring back. With ``c = 0`` the slack is taken up only at
zero crossings; with a band covering the whole motion it is a play of width ``2h`` after
every reversal (pure input backlash). Outside the band ``v = u -+ h``: a dead band of
``2h`` compressed out of the command. The inverse is exact and causal (the slack is
wound in with one jump of the command).

Where the slack sits in the drive matters when the drive's friction has no return-point memory.
``deadzone`` puts it between the knob and the friction (the friction sees the slack's output: the
base's input). ``deadzone:tip`` (:class:`TipDeadzone`) puts it between the friction and the bending
section: the friction sees the whole knob motion, and the slack acts on the base's output, with
``h``, ``c`` and ``m`` in degrees of bend. A friction element at the knob, its tendons slack near
neutral, is the second (the simulator's ``[tendon] friction = "bouc-wen"`` with ``[deadzone]``: on
its sweeps a smooth friction base fits with ``deadzone:tip`` to the noise and with ``deadzone`` at
2.7 times it, tests/test_friction_family_limits.py). The operator is homogeneous and moves with a
shift (``m + S_{h,c}(x - m)``), so on the output it keeps its form, scaled by the drive's gain.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from endocal.errors import ModelError
from endocal.models.data import HysteresisData
from endocal.models.effects.base import InputEffect, OutputFilter, from_form
from endocal.models.params import Parameter


@njit(cache=True)
def _rest(x, h):
    # resting drive position after loading from neutral: the slack is taken up on the pulling side
    if x > h:
        return x - h
    if x < -h:
        return x + h
    return 0.0


@njit(cache=True)
def _step(s, dx, x, h, c):
    if s > c:
        p = max(s + dx, c)
    elif s < -c:
        p = min(s + dx, -c)
    else:
        p = s
    if p < x - h:
        return x - h
    if p > x + h:
        return x + h
    return p


@njit(cache=True)
def slack_forward_jac(u, h, c, m, run_starts, M):
    """Slack operator (module docstring) and its Jacobian.

    Returns ``v`` (n,), ``J`` (n, 3) w.r.t. ``(h, c, m)`` and ``G`` (n, q), the
    derivative of ``v`` w.r.t. the q upstream parameters whose Jacobian of ``u`` is ``M``.
    Each branch of the recursion is affine in its inputs, so the derivatives are carried
    along exactly (forward mode).
    """
    n = u.shape[0]
    q = M.shape[1]
    v = np.empty(n)
    J = np.zeros((n, 3))
    G = np.zeros((n, q))
    n_runs = run_starts.shape[0]
    ds = np.zeros(3)
    dg = np.zeros(q)
    for r in range(n_runs):
        a = run_starts[r]
        b = run_starts[r + 1] if r + 1 < n_runs else n
        x = u[a] - m
        s = _rest(x, h)
        # derivatives of the rest state
        ds[:] = 0.0
        dg[:] = 0.0
        if x > h:  # s = u - m - h
            ds[0] = -1.0
            ds[2] = -1.0
            for j in range(q):
                dg[j] = M[a, j]
        elif x < -h:  # s = u - m + h
            ds[0] = 1.0
            ds[2] = -1.0
            for j in range(q):
                dg[j] = M[a, j]
        for k in range(a, b):
            if k > a:
                xk = u[k] - m
                dx = u[k] - u[k - 1]
                if s > c:
                    p = s + dx
                    mode = 0
                    if p < c:
                        p = c
                        mode = 1
                elif s < -c:
                    p = s + dx
                    mode = 0
                    if p > -c:
                        p = -c
                        mode = 2
                else:
                    p = s
                    mode = 3
                if p < xk - h:
                    s = xk - h
                    ds[0] = -1.0
                    ds[1] = 0.0
                    ds[2] = -1.0
                    for j in range(q):
                        dg[j] = M[k, j]
                elif p > xk + h:
                    s = xk + h
                    ds[0] = 1.0
                    ds[1] = 0.0
                    ds[2] = -1.0
                    for j in range(q):
                        dg[j] = M[k, j]
                else:
                    s = p
                    if mode == 0:
                        for j in range(q):
                            dg[j] += M[k, j] - M[k - 1, j]
                    elif mode == 1:
                        ds[0] = 0.0
                        ds[1] = 1.0
                        ds[2] = 0.0
                        for j in range(q):
                            dg[j] = 0.0
                    elif mode == 2:
                        ds[0] = 0.0
                        ds[1] = -1.0
                        ds[2] = 0.0
                        for j in range(q):
                            dg[j] = 0.0
            v[k] = s + m
            J[k, 0] = ds[0]
            J[k, 1] = ds[1]
            J[k, 2] = ds[2] + 1.0
            for j in range(q):
                G[k, j] = dg[j]
    return v, J, G


@njit(cache=True)
def slack_inverse(v, h, c, m, run_starts):
    """Commands (n,) whose slack operator output is ``v``: exact, sample by sample.

    Per sample the candidates are, in order: keep the slack state (the knob moves with
    the drive), the knob pushing from below or above (``u = v +- h``), or holding still;
    the first whose forward step reproduces ``v`` is taken.
    """
    n = v.shape[0]
    u = np.empty(n)
    n_runs = run_starts.shape[0]
    for r in range(n_runs):
        a = run_starts[r]
        b = run_starts[r + 1] if r + 1 < n_runs else n
        s = v[a] - m
        # rest state: s = x -+ h outside the slack, 0 inside (take the loaded side)
        if s > 0.0:
            x = s + h
        elif s < 0.0:
            x = s - h
        else:
            x = 0.0
        u[a] = x + m
        for k in range(a + 1, b):
            target = v[k] - m
            x_new = _inverse_step(s, x, target, h, c)
            s = _step(s, x_new - x, x_new, h, c)
            x = x_new
            u[k] = x + m
    return u


@njit(cache=True)
def _inverse_step(s, x, target, h, c):
    tol = 1e-12 * (1.0 + abs(target) + h + c)
    cand = x + (target - s)
    if abs(_step(s, cand - x, cand, h, c) - target) <= tol:
        return cand
    if target > s:
        cand = target + h
    elif target < s:
        cand = target - h
    else:
        cand = min(max(x, target - h), target + h)
    return cand


class _Slack:
    """What both places of the slack share: the physics, the start, the operator and its inverse.

    Parameters (short names): ``slack_deg`` (half play ``h``), ``band_deg`` (half width ``c`` of the band
    where the section does not spring back) and ``center_deg`` (its centre ``m``), in degrees of the signal
    the slack acts on (:meth:`_scale`).
    """

    name = "deadzone"
    streamable = True
    stateful = True
    cause = ("tendon slack: each tendon has free length that must be wound in before it pulls, "
             "so near the neutral bend the knob moves without moving the tip")
    signature = ("residual plateaus right after the bend crosses neutral (or after each reversal for "
                 "a wide band): the angle stays flat while the command moves, then catches up")
    protocol = "large sines or triangles crossing neutral, and small loops around neutral"
    units = {"slack_deg": "deg", "band_deg": "deg", "center_deg": "deg"}
    requires = ()
    residual = ()
    lookalikes = {"envelope": 'a dead zone appears after every reversal, wherever it happens, while the envelope depends on the knob position only: run `sine` with an offset (reversals away from neutral)'}
    sim_section = "deadzone"
    #: the other place of the slack, tried by ``validate`` as a candidate of its own
    variants = ("deadzone:tip",)

    @classmethod
    def from_argument(cls, arg: str):
        """``deadzone:tip``: the slack between the friction and the bending section (``deadzone:knob``: the default)."""
        side = arg.strip()
        if side not in SIDES:
            raise ModelError(f"effect 'deadzone:{side}': write deadzone (the slack between the knob and the friction) "
                             "or deadzone:tip (between the friction and the bending section)")
        return SIDES[side]()

    @classmethod
    def from_settings(cls, settings: dict):
        """A model file's entry: ``{"form": "tip"}`` for the tip's side; files without it are the knob's."""
        return from_form("deadzone", settings, SIDES, "knob")

    def _scale(self, data: HysteresisData, u: np.ndarray) -> np.ndarray:
        """The signal whose range the start and bounds are taken from."""
        return u

    def _center_start(self, data: HysteresisData, u: np.ndarray) -> float:
        # where the angle passes its mid level, averaged over both directions, on the signal the slack acts on
        x = self._scale(data, u)
        y = data.meas_deg
        if y is None:
            return float(np.median(x))
        near = np.abs(y - 0.5 * (y.max() + y.min())) < 0.05 * np.ptp(y)
        return float(np.median(x[near])) if near.any() else float(np.median(x))

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        x = self._scale(data, u)
        span = float(np.ptp(x)) or 1.0
        return [
            Parameter(f"{self.prefix}_slack_deg", 0.02 * span, 0.0, 0.5 * span),
            Parameter(f"{self.prefix}_band_deg", 0.05 * span, 0.0, span),
            Parameter(f"{self.prefix}_center_deg", self._center_start(data, u), float(x.min()), float(x.max())),
        ]

    def start_candidates(self, data: HysteresisData, u: np.ndarray) -> list[dict]:
        """Start values tried before the fit (the base is re-started on each; the best is kept)."""
        span = float(np.ptp(self._scale(data, u))) or 1.0
        mid = self._center_start(data, u)
        # no slack at all is a candidate too: on data without it the fit must not start lost
        return [{"slack_deg": fh * span, "band_deg": fc * span, "center_deg": mid}
                for fh in (0.0, 0.015, 0.05) for fc in (0.0, 0.08, 1.0) if fh > 0 or fc == 0.08]

    def _forward(self, p: dict, x: np.ndarray, data: HysteresisData, M: np.ndarray):
        return slack_forward_jac(np.ascontiguousarray(x, dtype=float), float(p["slack_deg"]), float(p["band_deg"]),
                                 float(p["center_deg"]), data.run_starts, np.ascontiguousarray(M, dtype=float))

    def apply(self, p: dict, x: np.ndarray, data: HysteresisData) -> np.ndarray:
        return self._forward(p, x, data, np.zeros((len(x), 0)))[0]

    def invert(self, p: dict, v: np.ndarray, data: HysteresisData) -> np.ndarray:
        return slack_inverse(np.ascontiguousarray(v, dtype=float), float(p["slack_deg"]), float(p["band_deg"]),
                             float(p["center_deg"]), data.run_starts)

    def stream_state(self, p: dict) -> np.ndarray:
        # [started, s, x]
        return np.zeros(3)

    def invert_step(self, p: dict, v: float, state: np.ndarray) -> float:
        h, c, m = float(p["slack_deg"]), float(p["band_deg"]), float(p["center_deg"])
        target = v - m
        if state[0] == 0.0:
            x = target + h if target > 0.0 else (target - h if target < 0.0 else 0.0)
            state[0], state[1], state[2] = 1.0, target, x
            return x + m
        s, x = state[1], state[2]
        x_new = _inverse_step(s, x, target, h, c)
        state[1] = _step(s, x_new - x, x_new, h, c)
        state[2] = x_new
        return x_new + m

    def is_zero(self, p: dict) -> bool:
        return p["slack_deg"] == 0.0


class Deadzone(_Slack, InputEffect):
    """Tendon slack between the knob and the friction, wound in near the neutral bend (module docstring).

    Parameters (prefix ``deadzone_``): ``slack_deg`` (half play ``h`` of the slack, deg of
    knob), ``band_deg`` (half width ``c`` of the band where the section does not spring
    back, deg), ``center_deg`` (its centre ``m``, deg of knob).
    """

    order = 30
    usage = "deadzone[:tip]"

    def apply_jac(self, p: dict, u: np.ndarray, data: HysteresisData, M: np.ndarray):
        return self._forward(p, u, data, M)

    def wrap(self, inner: str) -> str:
        return f"slack({inner})"

    def describe(self, p: dict, se: dict) -> str:
        return "slack = deadzone" + self._bracket(p, se)


class TipDeadzone(_Slack, OutputFilter):
    """``deadzone:tip``: the slack between the friction and the bending section, on the base's output.

    Parameters (prefix ``deadzone_tip_``): ``slack_deg``, ``band_deg``, ``center_deg``, in degrees of
    bend (the knob's slack times the drive's gain).
    """

    form = "tip"
    usage = "deadzone:tip"
    order = 5  # in the tendons: before the bend relaxes (creep) and the tracker reads it (coupling)

    def _scale(self, data: HysteresisData, u: np.ndarray) -> np.ndarray:
        return data.meas_deg if data.meas_deg is not None else u

    def apply_jac(self, p: dict, y: np.ndarray, data: HysteresisData, J: np.ndarray):
        """Output, the upstream Jacobian carried through the slack (n, m), and the own columns (n, 3)."""
        v, own, carried = self._forward(p, y, data, J)
        return v, carried, own

    def wrap(self, inner: str) -> str:
        return f"tipslack({inner})"

    def describe(self, p: dict, se: dict) -> str:
        return "tipslack = deadzone:tip" + self._bracket(p, se)


#: ``deadzone:SIDE`` -> the class of the slack on that side of the friction
SIDES = {"knob": Deadzone, "tip": TipDeadzone}
