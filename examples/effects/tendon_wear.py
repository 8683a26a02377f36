"""``wear``: a tendon that lengthens with use, so the knob's gain falls with its cumulative travel.

A user's own effect for endocal (docs/how-to/add-effect.md). Load it with
``--effects-file examples/effects/tendon_wear.py`` on ``endocal fit hysteresis``, ``validate``,
``report``, ``excite`` and ``effects``; the simulator hides it with ``[user_effects.wear]`` in a sim
config (examples/effects/wear-plant.toml).

The equation (an input effect: it changes the knob command before the base model sees it)::

    T(t) = sum over the record so far of |du|          the knob's travel (deg)
    v(t) = u(t) * (1 - k * T(t) / 1000)                the command the bend answers to

with ``k`` (``wear_per_kdeg``) the share of the gain lost per 1000 deg of travel. Travel counts
from each record's first sample: a record is a session on a probe that has rested.

The inverse (feedforward compensation) solves ``u (1 - k T) = v`` sample by sample, ``T``
growing with the ``|du|`` of the command it computes: a quadratic in ``u`` per sample (closed
form below), so it streams too.
"""

from __future__ import annotations

import math

import numpy as np

from endocal.models.effects.base import InputEffect
from endocal.models.effects.requirements import Requirement
from endocal.models.params import Parameter, fmt_value

#: the least travel a record needs for a wear to show (deg): a few full cycles of the knob; a record that
#: travels less (a single sweep) cannot tell a worn gain from a lower one
MIN_TRAVEL_DEG = 500.0


def _travel_of(u: np.ndarray, data) -> np.ndarray:
    """Cumulative travel (deg) of the command ``u`` in each record, from its first recorded sample
    (0 in a lead-in); ``u`` may differ from ``data.cmd_deg`` after earlier effects."""
    out = np.zeros_like(u)
    for sl, first in zip(data.run_slices(), data.record_starts()):
        out[first + 1:sl.stop] = np.cumsum(np.abs(np.diff(u[first:sl.stop])))
    return out


def _enough_travel(data):
    """The records travel far enough for a wear to show (per record: travel restarts with each)."""
    longest = max(float(np.abs(np.diff(data.cmd_deg[sl])).sum()) for sl in data.run_slices())
    if longest >= MIN_TRAVEL_DEG:
        return True
    return f"the longest record travels {longest:.0f} deg of knob, under {MIN_TRAVEL_DEG:.0f} deg"


class Wear(InputEffect):
    """The knob's gain falls with its cumulative travel (module docstring); parameter ``wear_per_kdeg``."""

    name = "wear"
    order = 40  # after the time shift (delay, order 10), before the static shapes (deadzone, envelope)
    cause = "a tendon that lengthens with use: the same knob angle pulls less as its travel adds up"
    signature = ("residual proportional to the command that grows through each record: "
                 "the loop shrinks as the knob travels")
    protocol = "a long record of large cycles, the same amplitude all through (its late cycles are smaller than its early ones)"
    units = {"per_kdeg": "1/kdeg"}
    has_inverse = True
    streamable = True
    requires = (Requirement("travel", f"{MIN_TRAVEL_DEG:.0f} deg of knob travel in one record", _enough_travel,
                            to="fit", remedy="record a long run of large cycles"),)
    residual = ("time",)
    lookalikes = {"drift": "drift shifts every angle alike, wear scales them: a record at two amplitudes "
                           "separates them (wear's error grows with the angle, drift's does not)"}

    def initial(self, data, u):
        return [Parameter(f"{self.prefix}_per_kdeg", 0.0, 0.0, 0.5)]

    def start_candidates(self, data, u):
        """Start values tried before the fit: none, light and heavy wear."""
        return [{"per_kdeg": k} for k in (0.0, 0.02, 0.1)]

    def apply(self, p, u, data):
        return u * (1.0 - p["per_kdeg"] * _travel_of(u, data) / 1000.0)

    def invert(self, p, v, data):
        out = np.empty_like(v, dtype=float)
        for sl, first in zip(data.run_slices(), data.record_starts()):
            out[sl.start:first] = v[sl.start:first]  # a lead-in: no travel yet
            state = self.stream_state(p)
            state[1] = v[first]  # the record starts where its first command is
            for i in range(first, sl.stop):
                out[i] = self.invert_step(p, float(v[i]), state)
        return out

    def stream_state(self, p):
        """``[travel so far (deg), previous command (deg), started (0/1)]``."""
        return np.zeros(3)

    def invert_step(self, p, v, state):
        """The command ``u`` with ``u (1 - c T_prev - c |u - u_prev|) = v``, ``c = k/1000``.

        For ``u >= u_prev``: ``-c u^2 + (g + c u_prev) u - v = 0`` with ``g = 1 - c T_prev``; for
        ``u < u_prev``: ``c u^2 + (g - c u_prev) u - v = 0``; each root written ``2v / (b + sqrt(b^2 - 4av))``
        (the one that tends to ``v / g`` as ``c -> 0``, stable for small ``c``).
        """
        c = p["per_kdeg"] / 1000.0
        travel, prev = state[0], state[1]
        if state[2] == 0.0:  # the first sample: no travel yet
            prev = v
            state[2] = 1.0
        g = 1.0 - c * travel
        u = v / g if g > 0 else v
        for a, b, up in ((-c, g + c * prev, True), (c, g - c * prev, False)):
            disc = b * b + 4.0 * a * v
            if disc < 0.0 or b + math.sqrt(disc) == 0.0:
                continue
            cand = 2.0 * v / (b + math.sqrt(disc))
            if (cand >= prev) == up:
                u = cand
                break
        state[0] = travel + abs(u - prev)
        state[1] = u
        return u

    def wrap(self, inner):
        return f"wear({inner})"

    def describe(self, p, se):
        return f"wear[{fmt_value(p['per_kdeg'], se.get('per_kdeg'), '/kdeg')}]"
