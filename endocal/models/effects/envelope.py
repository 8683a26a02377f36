"""``envelope``: the static, piecewise-linear input shape of the modified PI model.

Duodenoscope paper, eq. 6 (envelope) and eq. 10 (its inverse)::

    f(θ) = k0 (θ - θ0) + k1 (θ0 - θ1)   for θ < θ0
           k1 (θ - θ1)                  for θ0 <= θ <= θ2
           k2 (θ - θ2) + k1 (θ2 - θ1)   for θ > θ2

written here as ``k1 (θ - θ1) + (k0 - k1) min(θ - θ0, 0) + (k2 - k1) max(θ - θ2, 0)``
(identical for θ0 <= θ2, and defined everywhere). A shallow middle slope ``k1`` is a
dead band around neutral; steeper outer slopes are the stiffening at large bends.
On ``pi`` it makes the paper's modified PI; on ``linear``/``bspline`` it is a static
input nonlinearity.
"""

from __future__ import annotations

import numpy as np

from endocal.errors import ModelError
from endocal.models.data import HysteresisData
from endocal.models.effects.base import InputEffect, OutputFilter, from_form
from endocal.models.effects.requirements import full_amplitude
from endocal.models.params import Parameter

_K_MIN = 1e-12
#: The validation records test the stiffening at large bends when they sweep this share of the fitted range.
FULL_SPAN = 0.9
#: :meth:`Envelope.why_loose`: outer slopes this many times the middle one make the middle a dead band
#: (the tip moves 5 % as much per knob degree there as outside it)
DEAD_BAND_RATIO = 20.0


def envelope(theta_deg, theta0, theta1, theta2, k0, k1, k2):
    """Envelope ``f(θ)`` of the duodenoscope paper, eq. 6 (input in deg, output in envelope units)."""
    th = np.asarray(theta_deg, dtype=float)
    return k1 * (th - theta1) + (k0 - k1) * np.minimum(th - theta0, 0.0) + (k2 - k1) * np.maximum(th - theta2, 0.0)


def envelope_inverse(x, theta0, theta1, theta2, k0, k1, k2):
    """Inverse envelope ``f⁻¹(x)`` (duodenoscope paper, eq. 10); needs k0, k1, k2 > 0 and θ0 <= θ2."""
    if not (k0 > 0 and k1 > 0 and k2 > 0):
        raise ModelError(f"the envelope cannot be inverted: slopes must be positive, got k0={k0}, k1={k1}, k2={k2}")
    if theta0 > theta2:
        raise ModelError(f"the envelope cannot be inverted: theta0={theta0} lies above theta2={theta2}")
    x = np.asarray(x, dtype=float)
    x0 = k1 * (theta0 - theta1)  # f(θ0)
    x2 = k1 * (theta2 - theta1)  # f(θ2)
    mid = x / k1 + theta1
    return np.where(x < x0, (x - x0) / k0 + theta0, np.where(x > x2, (x - x2) / k2 + theta2, mid))


def _hinge_start(u: np.ndarray, y: np.ndarray, split: float):
    """Start values from a continuous three-segment line fitted to (u, y), hysteresis averaged out.

    A least-squares fit of ``y ≈ a + k1 (u - θ1) + (k0-k1) min(u-θ0, 0) + (k2-k1)
    max(u-θ2, 0) + c sign(du)`` over a grid of kinks finds the dead band and the stiffening;
    returns ``θ0, θ1, θ2, k0/k1, k2/k1``. The last term, a constant offset per direction of
    motion (the loop's half width), keeps a record with more of one branch than the other
    (1.5 cycles) from bending the line towards it.
    """
    stride = max(1, u.size // 4000)
    uu, yy = u[::stride], y[::stride]
    moving = np.sign(np.diff(u, prepend=u[0]))[::stride]
    lo_grid = np.quantile(uu, np.linspace(0.03, 0.5, 12))
    hi_grid = np.quantile(uu, np.linspace(0.5, 0.97, 12))
    lo_grid = lo_grid[lo_grid <= split]
    hi_grid = hi_grid[hi_grid >= split]
    best = None
    ones = np.ones_like(uu)
    for a in lo_grid:
        for b in hi_grid:
            if b <= a:
                continue
            A = np.column_stack([ones, uu, np.minimum(uu - a, 0.0), np.maximum(uu - b, 0.0), moving])
            coef, *_ = np.linalg.lstsq(A, yy, rcond=None)
            cost = float(np.sum((A @ coef - yy) ** 2))
            if best is None or cost < best[0]:
                best = (cost, float(a), float(b), coef)
    if best is None:
        return float(np.quantile(u, 0.2)), split, float(np.quantile(u, 0.8)), 1.0, 1.0
    _, a, b, (c0, c1, d0, d2, _) = best
    k1 = c1 if c1 > 0 else max(abs(c1), 1e-6)
    ratio0 = max((c1 + d0) / k1, 0.05)
    ratio2 = max((c1 + d2) / k1, 0.05)
    th1 = float(np.clip(-c0 / k1, u.min(), u.max()))
    return a, th1, b, float(ratio0), float(ratio2)


class _Shape:
    """What both places of the static shape share: the physics, the start, the map and its inverse."""

    name = "envelope"
    streamable = True
    cause = "static stiffness of the bending section: dead band around neutral (slack tendons), stiffening at large bends"
    signature = "residual that is a function of the command amplitude alone, the same on both branches (S-shaped vs command)"
    protocol = "large-amplitude sweeps through neutral (damped sine)"
    units = {"theta0_deg": "deg", "theta1_deg": "deg", "theta2_deg": "deg", "k0": "", "k1": "", "k2": ""}
    open_bounds = ("theta1_deg",)  # the zero of f: anywhere (a flat middle puts it far out)
    requires = (full_amplitude(FULL_SPAN),)
    residual = ()  # a static shape: the residual tests look at time, speed and the other knob, not at it
    lookalikes = {"deadzone": (
        "a dead zone appears after every reversal, wherever it happens, while the envelope depends on the "
        "knob position only: run `sine` with an offset (reversals away from neutral)")}
    sim_section = "envelope"
    position_map = True
    segment_order = 90  # every other segment sweeps the full range already: it reuses theirs

    #: the stiffening past the friction, tried by ``validate`` as a candidate of its own on a friction base
    variants = ("envelope:tip",)

    @classmethod
    def from_argument(cls, arg: str):
        """``envelope:tip``: the bending section's shape past a friction element without return-point memory."""
        if arg.strip() != "tip":
            raise ModelError(f"effect 'envelope:{arg.strip()}': write envelope (the shape on the command, the paper's "
                             "eq. 6) or envelope:tip (on the bend, past a friction base's one friction element)")
        return TipEnvelope()

    @classmethod
    def from_settings(cls, settings: dict):
        """A model file's entry: ``{"form": "tip"}`` for the tip's side; files without it are the command's."""
        return from_form("envelope", settings, {"": Envelope, "tip": TipEnvelope}, "")

    def segment(self, design, n_half_cycles: int):
        """The full amplitude of the fitted range: any segment on this axis (every one sweeps it), else a sine."""
        return design.full_range(n_half_cycles)

    def gauge(self, base_absorbs: str) -> dict[str, float]:
        # A homogeneous base (the play operator, Phi_{c r}[c x] = c Phi_r[x]): with exponential weights
        # the envelope's scale trades off exactly against r, w and beta, so one scale parameter is
        # fixed; k1 = 1 makes f read in degrees around neutral. Branches that absorb any affine map
        # of their input: the middle slope and the zero are fixed, so f only carries the shape.
        if base_absorbs == "scale":
            return {f"{self.prefix}_k1": 1.0}
        if base_absorbs == "affine":
            return {f"{self.prefix}_k1": 1.0, f"{self.prefix}_theta1_deg": 0.0}
        return {}

    def shapes_base(self) -> dict:
        # the modified PI of the duodenoscope paper: exponential weights on the envelope, no offset
        return {"weights": "exponential", "offset": False}

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        # theta0 <= theta2 (eq. 10 inverts only then) is held by a bound between them: neutral
        # (knob 0), where the dead band the kinks bound lies, when the range holds it, else the
        # middle of the range; never where the knob spends its time (the median, which a record
        # of 1.5 cycles puts on one side, bounding the kinks away from the dead band). A sweep to
        # one side (0 -> +50 -> 0) holds only the upper kink, and finds it (a split at the middle
        # made the lower kink take it: 1.5x the noise). Each kink stays within the range: one
        # beyond it shapes nothing the data hold, and a kink that wandered out (to -461 deg on
        # 1.5 cycles) had no gradient to come back.
        lo, hi = float(np.min(u)), float(np.max(u))
        split = 0.0 if lo <= 0.0 <= hi else 0.5 * (lo + hi)
        margin = 0.01 * (hi - lo)
        th0, th2, th1 = float(np.quantile(u, 0.2)), float(np.quantile(u, 0.8)), split
        ratio0 = ratio2 = 1.0
        if data.meas_deg is not None and np.ptp(u) > 0:
            th0, th1, th2, ratio0, ratio2 = _hinge_start(u, data.meas_deg, split)
        pre = self.prefix
        return [
            Parameter(f"{pre}_theta0_deg", min(th0, split), min(lo, split - margin), split),
            Parameter(f"{pre}_theta1_deg", th1),
            Parameter(f"{pre}_theta2_deg", max(th2, split), split, max(hi, split + margin)),
            Parameter(f"{pre}_k0", ratio0, _K_MIN, np.inf),
            Parameter(f"{pre}_k1", 1.0, _K_MIN, np.inf),
            Parameter(f"{pre}_k2", ratio2, _K_MIN, np.inf),
        ]

    def adapt_start(self, start: dict[str, Parameter], fixed: dict[str, float]) -> None:
        # Keep the start's slope ratios at the scale the user fixed (e.g. the paper's k1).
        names = [f"{self.prefix}_{key}" for key in ("k0", "k1", "k2")]
        for name in names:
            if name in fixed:
                scale = fixed[name] / start[name].value
                for other in names:
                    if other not in fixed:
                        start[other].value *= scale
                return

    def _args(self, p: dict):
        return (p["theta0_deg"], p["theta1_deg"], p["theta2_deg"], p["k0"], p["k1"], p["k2"])

    def apply(self, p: dict, u: np.ndarray, data: HysteresisData) -> np.ndarray:
        return envelope(u, *self._args(p))

    def invert(self, p: dict, v: np.ndarray, data: HysteresisData) -> np.ndarray:
        return envelope_inverse(v, *self._args(p))

    def apply_jac(self, p: dict, u: np.ndarray, data: HysteresisData, M: np.ndarray):
        """``f(u)``, its derivatives w.r.t. (θ0, θ1, θ2, k0, k1, k2) (n, 6), and ``f'(u)·M`` (chain rule)."""
        th0, th1, th2, k0, k1, k2 = self._args(p)
        lo = np.minimum(u - th0, 0.0)
        hi = np.maximum(u - th2, 0.0)
        below = u < th0
        above = u > th2
        v = k1 * (u - th1) + (k0 - k1) * lo + (k2 - k1) * hi
        own = np.column_stack([
            -(k0 - k1) * below, np.full(u.shape, -k1), -(k2 - k1) * above,
            lo, (u - th1) - lo - hi, hi,
        ])
        slope = np.where(below, k0, np.where(above, k2, k1))
        return v, own, slope[:, None] * M

    def stream_state(self, p: dict) -> np.ndarray:
        return np.zeros(1)  # a static map: nothing to hold between samples

    def invert_step(self, p: dict, v: float, state: np.ndarray) -> float:
        # scalar form of eq. 10 (a numpy call per sample would dominate a 1 kHz loop)
        th0, th1, th2, k0, k1, k2 = self._args(p)
        x0 = k1 * (th0 - th1)
        x2 = k1 * (th2 - th1)
        if v < x0:
            return (v - x0) / k0 + th0
        if v > x2:
            return (v - x2) / k2 + th2
        return v / k1 + th1

    def why_loose(self, p: dict, se: dict) -> str:
        """One line for a dead band the gauge ``k1`` cannot express well, else ``""``.

        Slack tendons leave a nearly flat middle segment. With its slope ``k1`` held as the
        scale (the gauge, 1), flat means outer slopes ``k0``, ``k2`` ever steeper and a zero
        ``θ1`` ever farther out: those (and the base's scale) lose their standard errors while
        the shape they draw, and every prediction, stays pinned down. Said when both outer
        slopes exceed the middle one DEAD_BAND_RATIO times, any of them is loose and ``k1`` is
        held (the model's gauge, or a user's fixed value).
        """
        ratio = min(p["k0"], p["k2"]) / p["k1"]
        loose = [k for k in ("theta1_deg", "k0", "k2") if not se.get(k, 0.0) <= abs(p[k])]
        if not (ratio > DEAD_BAND_RATIO and loose and se.get("k1", 0.0) == 0.0):  # k1 held: the gauge
            return ""
        band = f"{p['theta0_deg']:.2f}..{p['theta2_deg']:.2f} deg"
        return (f"the envelope is a dead band: its slope from theta0 to theta2 ({band}) is 1/{ratio:.0f} of the outer "
                f"slopes, so with k1 held at {p['k1']:.4g} as the scale its outer slopes and zero ({', '.join(loose)}) "
                "have no useful standard errors; the shape and the predictions are identified (`deadzone` models "
                "tendon slack as such)")

    def is_zero(self, p: dict) -> bool:
        return False


class Envelope(_Shape, InputEffect):
    """Piecewise-linear envelope ``f`` (duodenoscope paper, eqs. 6 and 10).

    Parameters (prefix ``envelope_``): ``theta0_deg``, ``theta1_deg``, ``theta2_deg``
    (knob angles, deg: lower kink, zero of f, upper kink) and ``k0``, ``k1``, ``k2``
    (slopes below, between and above the kinks, envelope units per deg). Its scale
    trades off against the base model's (the play operator is homogeneous), so the
    model fixes a gauge (``envelope_k1``) unless the user fixes parameters himself.
    """

    order = 90

    def wrap(self, inner: str) -> str:
        return f"f({inner})"

    def describe(self, p: dict, se: dict) -> str:
        return "f = envelope" + self._bracket(p, se)


class TipEnvelope(_Shape, OutputFilter):
    """``envelope:tip``: the same shape on the base's output, the bend, past the friction.

    The bending section's stiffness acts on what the tendons deliver past their friction. Where the friction
    has return-point memory (a bank of plays, a B-spline per direction) the paper's shape on the command takes
    it; past one friction element without that memory (``dahl``, ``bouc-wen``) the element's exponential runs in
    knob degrees, and a shape in front of it would stretch the exponential with the stiffening. On the Bouc-Wen
    plant's speed ladder `dahl` with it fits at 1.13x the noise in-sample, with ``envelope`` 1.21x
    (tests/test_friction_family_limits.py). Parameters (prefix ``envelope_tip_``): as ``envelope``'s, the kinks and
    zero in degrees of bend; the base's affine gauge holds ``k1`` at 1 and ``θ1`` at 0.
    """

    form = "tip"
    usage = "envelope:tip"
    order = 6  # the bending section, past the tendons' slack (deadzone:tip, 5): before the bend relaxes (creep)
    needs_friction_state = ("it shapes the bend past a friction element without return-point memory; a base with that "
                            "memory takes the bending section's shape as 'envelope'")

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        # on the bend: the kinks start where the measured angle has its quantiles, the slopes at 1 (the base's output
        # is the bend before the shape, unknown until the fit)
        y = data.meas_deg if data.meas_deg is not None else u
        return super().initial(HysteresisData(cmd_deg=y), y)

    def apply_jac(self, p: dict, y: np.ndarray, data: HysteresisData, J: np.ndarray):
        """Output, the upstream Jacobian carried through the shape (n, m), and the own columns (n, 6)."""
        v, own, carried = super().apply_jac(p, y, data, J)
        return v, carried, own

    def wrap(self, inner: str) -> str:
        return f"ftip({inner})"

    def describe(self, p: dict, se: dict) -> str:
        return "ftip = envelope:tip" + self._bracket(p, se)
