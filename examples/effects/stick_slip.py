"""``stickslip``: at every reversal the tip holds until static friction gives, then jumps.

A user's own effect for endocal (docs/how-to/add-effect.md), the second worked example beside
``tendon_wear.py``. Load it with ``--effects-file examples/effects/stick_slip.py``; the simulator
hides it with ``[user_effects.stickslip]`` (examples/effects/stickslip-plant.toml).

The equation (an input effect: it changes the knob command before the base model sees it)::

    u_r   the command at the last reversal (or at the record's start)
    v(t) = u_r + (u(t) - u_r) * S((|u(t) - u_r| - s) / w)

with ``S`` the logistic function: while the knob has moved less than ``s`` (``stickslip_deg``)
back from the reversal the tip is held at ``u_r``; past it, static friction gives and the tip
jumps to follow the knob. The release takes ``w`` = 0.05 ``s`` + 0.05 deg of knob travel, so the
equation is smooth in ``s`` and a least-squares fit can move it (a hard step would leave the
fit no gradient). A reversal is a turn of the command by more than :data:`REVERSAL_DEG`.

It has no inverse: the angles inside the held range are reached by no command, so a model with
it cannot compensate (``has_inverse = False``: compensation refuses the model, in one line).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from endocal.models.data import reversals
from endocal.models.effects.base import InputEffect
from endocal.models.effects.requirements import Requirement
from endocal.models.params import Parameter, fmt_value

#: the least turn of the command that counts as a reversal (deg): above a logged command's jitter
REVERSAL_DEG = 0.05


@njit  # a loop over every sample, in every evaluation of the fit: compiled (numba comes with endocal)
def _reversal_commands(u, starts, ends, tol):
    out = np.empty_like(u)
    for r in range(starts.shape[0]):
        a, b = starts[r], ends[r]
        ur, ext, direction = u[a], u[a], 0.0
        for i in range(a, b):
            x = u[i]
            if direction == 0.0:  # not moved yet: the record's start holds
                if abs(x - ur) > tol:
                    direction = 1.0 if x > ur else -1.0
                    ext = x
            elif (x - ext) * direction > 0.0:  # on in the same direction
                ext = x
            elif (ext - x) * direction > tol:  # turned back at the extreme: a reversal
                ur, direction, ext = ext, -direction, x
            out[i] = ur
    return out


def reversal_commands(u: np.ndarray, starts, ends) -> np.ndarray:
    """Per sample, the command at the last reversal before it (or at its record's start), deg.

    A reversal is where the command, having moved one way, turns back by more than
    :data:`REVERSAL_DEG` from its extreme; the extreme is the reversal's command.
    """
    return _reversal_commands(np.ascontiguousarray(u, dtype=float), np.asarray(starts, dtype=np.int64),
                              np.asarray(ends, dtype=np.int64), REVERSAL_DEG)


#: the fewest reversals a record needs to show a stick at each (and the slip after it)
MIN_REVERSALS = 6


def _reversing(data):
    """A record reverses the knob :data:`MIN_REVERSALS` times or more."""
    most = max(reversals(data.cmd_deg[sl]) for sl in data.run_slices())
    return True if most >= MIN_REVERSALS else f"the records reverse the knob {most} times at most, under {MIN_REVERSALS}"


class StickSlip(InputEffect):
    """The tip holds at each reversal until the knob has moved ``stickslip_deg`` back, then jumps (module
    docstring)."""

    name = "stickslip"
    order = 30  # after the time shift (delay), before the static shapes
    cause = "static friction above sliding friction: the tip sticks at each reversal, then slips all at once"
    signature = ("residual that jumps right after each reversal: the model leaves the reversal too early, "
                 "then lags the sudden slip")
    protocol = "reversals of every size, slow enough that each stick lasts several samples (small sines about the middle)"
    units = {"deg": "deg"}
    has_inverse = False
    no_inverse = "the angles inside each held range are reached by no command"
    requires = (Requirement("reversals", f"{MIN_REVERSALS} reversals of the knob in a record", _reversing, to="fit",
                            remedy="validate --next designs small sines"),)
    residual = ("abs speed",)
    lookalikes = {"deadzone": "a dead zone lags every reversal smoothly and never jumps; small reversals "
                              "inside the loop show the jump of a stick-slip",
                  "delay": "a delay lags the whole motion, a stick-slip only after reversals: a record "
                           "with fast moves between slow reversals separates them"}

    def initial(self, data, u):
        return [Parameter(f"{self.prefix}_deg", 0.5, 0.0, 20.0)]

    def start_candidates(self, data, u):
        """Start values tried before the fit (the release is steep: the fit refines near a start)."""
        return [{"deg": s} for s in (0.5, 1.0, 2.0, 4.0, 8.0)]

    def apply(self, p, u, data):
        ends = [sl.stop for sl in data.run_slices()]
        ur = reversal_commands(np.asarray(u, dtype=float), data.record_starts(), ends)
        s = p["deg"]
        w = 0.05 * s + 0.05
        d = u - ur
        with np.errstate(over="ignore"):
            held = 1.0 / (1.0 + np.exp(-(np.abs(d) - s) / w))
        return ur + d * held

    def invert(self, p, v, data):
        from endocal.errors import ModelError

        raise ModelError("effect 'stickslip' has no inverse: the angles inside each held range are reached by no "
                         "command; compensate without it")

    def segment(self, design, n_half_cycles):
        """Small sines about the middle of the range: many reversals, each held a while."""
        amplitude = min(design.amplitude, max(design.min_amplitude_deg, 10.0))
        cycles = max(1, math.ceil(n_half_cycles / 2))
        f = min(design.f_typ_hz, design.cap_hz(amplitude))
        k = design.add("sine", axes=[design.axis], amplitude_deg=amplitude, offset_deg=design.centre,
                       frequency_hz=round(f, 6), cycles=cycles)
        return design.planned(k, 2 * cycles)

    def wrap(self, inner):
        return f"stickslip({inner})"

    def describe(self, p, se):
        return f"stickslip[{fmt_value(p['deg'], se.get('deg'), 'deg')}]"
