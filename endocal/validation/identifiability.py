"""Which effects a record can reveal at all, and why not when it cannot.

Each check takes the data and returns None when the effect can be seen in it, else why not
in words, with the experiment that would show it (``rate`` needs the same motion at several
frequencies, ``creep`` a hold after a move, ``coupling`` the other knob moving).
"""

from __future__ import annotations

import numpy as np

from endocal.models import HysteresisData
from endocal.models.data import OTHER_CMD
from endocal.validation.data import is_constant
from endocal.validation.regimes import hold_mask, turning_points


def _one_frequency(data: HysteresisData) -> str | None:
    """Why the data has a single frequency of motion (None when it has several)."""
    turns = turning_points(data)
    t = data.t_s if data.t_s is not None else np.arange(data.n_samples, dtype=float)
    same_run = np.searchsorted(data.run_starts, turns[1:], side="right") == np.searchsorted(
        data.run_starts, turns[:-1], side="right")
    half = np.diff(t[turns])[same_run] if turns.size > 1 else np.array([])
    if half.size < 2:
        return "too few reversals"
    lo, hi = np.quantile(half, [0.1, 0.9])
    return "one frequency only" if hi < 1.5 * lo else None


def rate_reason(data: HysteresisData) -> str | None:
    """Why ``data`` cannot tell speed-dependent friction from a wider loop (None: it can)."""
    why = _one_frequency(data)
    if why is None:
        return None
    return (f"{why}: rate cannot be identified (speed-dependent friction needs the same motion at several "
            "frequencies: run `chirp` or `sine-set`)")


def delay_reason(data: HysteresisData) -> str | None:
    """Why ``data`` cannot tell a delay from a wider loop (None: it can)."""
    if data.t_s is None:
        return "no time stamps: delay cannot be identified"
    why = _one_frequency(data)
    if why is None:
        return None
    return (f"{why}: delay cannot be identified (at one frequency a time shift looks like a wider loop: "
            "run `chirp` or `random`)")


def creep_reason(data: HysteresisData) -> str | None:
    """Why ``data`` cannot show creep: no hold after a move (None: it can)."""
    hold = hold_mask(data, 1.0)
    span = float(np.ptp(data.cmd_deg))
    t = data.t_s
    starts = np.flatnonzero(hold & ~np.concatenate([[False], hold[:-1]]))
    for k in starts:
        run0 = data.run_starts[np.searchsorted(data.run_starts, k, side="right") - 1]
        # within this record: several records restart their clocks, so a search over all of t is unordered
        j = int(run0) + int(np.searchsorted(t[run0:k + 1], t[k] - 2.0)) if t is not None else k - 20
        j = max(int(j), int(run0))
        if k > run0 and np.ptp(data.cmd_deg[j:k + 1]) >= 0.05 * span:
            return None
    return ("no holds: creep cannot be identified (it shows as the tip still moving after the knob stops: "
            "run `staircase`)")


def coupling_reason(data: HysteresisData, where: str = "") -> str | None:
    """Why ``data`` cannot show coupling: no other knob, or one that never moves (in ``where``); None: it can."""
    if OTHER_CMD not in data.extras:
        return "one axis only: coupling cannot be identified (drive both knobs: run `lissajous` or `circle`)"
    if is_constant(data.extras[OTHER_CMD]):
        if where:
            return (f"the other knob never moves in {where}: coupling cannot be fitted there (record estimation "
                    "data in which both knobs move, e.g. `lissajous` or `circle`, or each knob in turn: `sine-set`)")
        return "the other knob never moves: coupling cannot be identified (run `lissajous` or `circle`)"
    return None


def time_reason(name: str):
    """A check that effect ``name`` needs time stamps."""
    def reason(data: HysteresisData) -> str | None:
        return None if data.t_s is not None else f"no time stamps: {name} cannot be identified"
    return reason


#: Effect name -> check of whether the data can reveal it (None: it can; else why not).
IDENTIFIABILITY = {
    "rate": rate_reason,
    "creep": creep_reason,
    "coupling": coupling_reason,
    "delay": delay_reason,
    "drift": time_reason("drift"),
}

#: Effect name -> check of whether its parameters can be fitted at all (the estimation/validation
#: scheme tests every fittable candidate on the separate validation data).
FITTABILITY = {
    "coupling": coupling_reason,
    "delay": time_reason("delay"),
    "drift": time_reason("drift"),
    "creep": time_reason("creep"),
    "rate": time_reason("rate"),
}

