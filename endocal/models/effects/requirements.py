"""What the records must hold to fit an effect, or to test it: an effect's ``requires``.

An effect declares its needs as a tuple of :class:`Requirement` (``Effect.requires``);
validation asks each one, on the records at hand, whether they hold it
(:meth:`Requirement.reason`: None, or why not in words with the experiment that would). Two
purposes:

``to="fit"``
    without it the effect's parameters cannot be fitted at all (no time stamps for a delay,
    the other knob never moving for coupling): the scan does not fit it;
``to="test"``
    it can be fitted, but a record without it cannot tell the effect from a wider loop (one
    frequency for ``rate``, no holds for ``creep``): a rolling-origin scan, which has no
    separate validation record to decide, does not test it;
``to="next"``
    only the next experiment asks for it (the validation records reach the full amplitude).

Ready-made requirements: :data:`TIME_STAMPS`, :func:`other_knob_moving`,
:func:`speeds_spanning`, :func:`holds_after_moves`, :func:`condition_varying` and
:func:`full_amplitude`. An effect of one's own writes
``Requirement("reversals", "a reversal of the knob", lambda d: has_reversal(d), to="test",
remedy="run `sine`")``: the predicate returns True (held), False (not held: the reason
says the records lack ``words``) or a string saying why not.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from endocal.models.data import OTHER_CMD, HysteresisData

#: The purposes a requirement serves (see the module docstring).
PURPOSES = ("fit", "test", "next")


@dataclass(frozen=True)
class Requirement:
    """A property the records must have to fit or to test an effect.

    Parameters
    ----------
    key : str
        Short identifier (``"time"``, ``"speeds"``, ``"holds"``, ...); unique within an effect.
    words : str
        What the records must hold, in words (``"holds after moves"``).
    predicate : callable
        ``predicate(data: HysteresisData)``: True (held), False (not held) or why not in words
        (see :meth:`check`); one that takes ``**context`` also gets the effect and the fitted span.
    to : {"fit", "test", "next"}
        What it is needed for (module docstring).
    remedy : str
        The experiment that would provide it (``"run `staircase`"``), said in parentheses.
    lacking : str
        What ``--next`` calls records without it (``"no holds"``); default ``"no KEY"``.
    caution : str
        When set, a fit of the effect on records that lack it (estimation and validation alike)
        carries this caution, and ranks after the effects fitted without one.
    """

    key: str
    words: str
    predicate: Callable
    to: str = "test"
    remedy: str = ""
    lacking: str = ""
    caution: str = ""

    def __post_init__(self):
        if self.to not in PURPOSES:
            raise ValueError(f"requirement '{self.key}': to must be one of {PURPOSES}, got {self.to!r}")
        if not callable(self.predicate):
            raise TypeError(f"requirement '{self.key}': predicate must be callable, got {self.predicate!r}")

    @property
    def status(self) -> str:
        """What ``--next`` calls records without it."""
        return self.lacking or f"no {self.key}"

    def check(self, data: HysteresisData, **context) -> tuple[str, str] | None:
        """None when ``data`` holds it, else ``(why, remedy)``.

        The predicate's answer: True or None: held; False: not held (why: the records lack
        :attr:`words`); a string: not held, that is why; a ``(why, remedy)`` tuple: the same
        with its own remedy. ``context`` (``effect``, ``span_deg``) reaches predicates that
        accept keywords.
        """
        out = self.predicate(data, **context) if context and _takes_context(self.predicate) else self.predicate(data)
        if out is True or out is None:
            return None
        if out is False:
            return f"the records lack {self.words}", self.remedy
        if isinstance(out, tuple):
            return str(out[0]), str(out[1])
        return str(out), self.remedy

    def reason(self, data: HysteresisData, name: str = "", where: str = "", **context) -> str | None:
        """None when ``data`` holds it, else why not in words.

        Parameters
        ----------
        data : HysteresisData
        name : str
            The effect (``"rate cannot be identified"``); without it the bare reason.
        where : str
            The part of the data the effect would be fitted on (``"the estimation data"``): the
            reason then says it cannot be fitted there.
        """
        out = self.check(data, **context)
        if out is None:
            return None
        why, remedy = out
        if where:
            why = f"{why} in {where}"
        if name:
            why += f": {name} cannot be {'fitted there' if where else 'identified'}"
        return why + (f" ({remedy})" if remedy else "")


def _takes_context(fn: Callable) -> bool:
    import inspect

    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):
        return False
    return any(p.kind is p.VAR_KEYWORD for p in params)


# ---------------------------------------------------------------------------- ready-made requirements
def _has_time(data: HysteresisData):
    return data.t_s is not None or "no time stamps"


#: Time stamps (``t_s``): every effect of time (a lag, a relaxation, a drift, a speed).
TIME_STAMPS = Requirement("time", "time stamps", _has_time, to="fit")


def one_frequency(data: HysteresisData) -> str | None:
    """Why the data has a single frequency of motion (None when it has several): the half-cycles'
    durations (within a record) span less than 1.5 : 1 between their 10th and 90th percentiles."""
    from endocal.validation.regimes import turning_points

    turns = turning_points(data)
    t = data.t_s if data.t_s is not None else np.arange(data.n_samples, dtype=float)
    same_run = np.searchsorted(data.run_starts, turns[1:], side="right") == np.searchsorted(
        data.run_starts, turns[:-1], side="right")
    half = np.diff(t[turns])[same_run] if turns.size > 1 else np.array([])
    if half.size < 2:
        return "too few reversals"
    lo, hi = np.quantile(half, [0.1, 0.9])
    return "one frequency only" if hi < 1.5 * lo else None


def speeds_spanning(remedy: str, to: str = "test") -> Requirement:
    """The same motion at several speeds (half-cycles whose durations span 1.5 : 1 or more)."""
    return Requirement("speeds", "motion at several speeds", lambda d: one_frequency(d) or True,
                       to=to, remedy=remedy, lacking="one speed")


def no_hold_after_move(data: HysteresisData) -> bool:
    """True when no record holds the knob still (1 s or more) after it moved by 5 % of the span
    within the 2 s before the hold."""
    from endocal.validation.regimes import hold_mask

    hold = hold_mask(data, 1.0)
    span = float(np.ptp(data.cmd_deg))
    t = data.t_s
    starts = np.flatnonzero(hold & ~np.concatenate([[False], hold[:-1]]))
    for k in starts:
        run0 = int(data.run_starts[np.searchsorted(data.run_starts, k, side="right") - 1])
        if k == run0:
            continue  # a record that starts at rest: no move before this hold
        # the 2 s before the hold, within its own record: each record's clock starts again (the
        # concatenated t_s is not sorted), so a search over all of it can land in another record
        j = run0 + int(np.searchsorted(t[run0:k + 1], t[k] - 2.0)) if t is not None else max(k - 20, run0)
        if np.ptp(data.cmd_deg[j:k + 1]) >= 0.05 * span:
            return False
    return True


def holds_after_moves(remedy: str, to: str = "test", caution: str = "") -> Requirement:
    """A hold of the knob (1 s or more) right after a move."""
    return Requirement("holds", "holds after moves", lambda d: not no_hold_after_move(d) or "no holds",
                       to=to, remedy=remedy, lacking="no holds", caution=caution)


@dataclass(frozen=True)
class _OtherKnob(Requirement):
    """The other knob's command logged and moving; the reason on the part an effect is fitted on
    (``where``) says where to record it."""

    def reason(self, data: HysteresisData, name: str = "", where: str = "", **context) -> str | None:
        from endocal.validation.data import is_constant

        if OTHER_CMD not in data.extras:
            return f"one axis only: {name} cannot be identified (drive both knobs: run `lissajous` or `circle`)"
        if is_constant(data.extras[OTHER_CMD]):
            if where:
                return (f"the other knob never moves in {where}: {name} cannot be fitted there (record estimation "
                        "data in which both knobs move, e.g. `lissajous` or `circle`, or each knob in turn: "
                        "`sine-set`)")
            return f"the other knob never moves: {name} cannot be identified (run `lissajous` or `circle`)"
        return None


def _other_moves(data: HysteresisData):
    from endocal.validation.data import is_constant

    return OTHER_CMD in data.extras and not is_constant(data.extras[OTHER_CMD])


def other_knob_moving(to: str = "fit") -> Requirement:
    """The other bending knob logged (``other_cmd_deg``) and moving."""
    return _OtherKnob("other knob", "the other knob moving", _other_moves, to=to)


def condition_varies_within(data: HysteresisData, column: str) -> str | None:
    """Why ``column`` cannot separate a condition from the records (None: it varies within a record,
    or the same motion was recorded at two of its values)."""
    from endocal.validation.data import is_constant

    if column not in data.extras:
        return f"no column '{column}'"
    values = np.asarray(data.extras[column], dtype=float)
    if is_constant(values):
        return f"'{column}' is constant"
    if any(not is_constant(values[sl]) for sl in data.run_slices()):
        return None
    # constant within each record: only the same motion at two values separates the condition from
    # whatever else differs between the records (their motion, their start, the base's misfit)
    by_value: dict[float, list[np.ndarray]] = {}
    for sl in data.run_slices():
        by_value.setdefault(round(float(values[sl][0]), 9), []).append(data.cmd_deg[sl])
    if len(by_value) >= 2 and same_motion_at_two_values(list(by_value.values())):
        return None
    return (f"'{column}' is constant within each record and the records at its {len(by_value)} values differ in "
            "their motion, so a load term cannot be told from any other difference between the records (their "
            "motion, their start, the base's misfit on them)")


def same_motion_at_two_values(groups: list[list[np.ndarray]], tol_frac: float = 0.05) -> bool:
    """True when two groups (records at two values of a condition) hold the same motion: commands of
    equal length within ``tol_frac`` of their span, sample by sample."""
    for i, a_group in enumerate(groups):
        for b_group in groups[i + 1:]:
            for a in a_group:
                for b in b_group:
                    n = min(a.size, b.size)
                    if n < 2 or abs(a.size - b.size) > 0.02 * max(a.size, b.size):
                        continue
                    span = max(float(np.ptp(a)), float(np.ptp(b)), 1e-12)
                    if float(np.max(np.abs(a[:n] - b[:n]))) <= tol_frac * span:
                        return True
    return False


def condition_varying(remedy: str, to: str = "test") -> Requirement:
    """The effect's condition column varies within a record, or the same motion was recorded at two
    of its values (the predicate reads the column from ``effect.column``)."""
    def held(data: HysteresisData, effect=None, **_):
        column = getattr(effect, "column", None)
        if column is None:
            return True  # no column named yet: the candidates' search over columns decides
        return condition_varies_within(data, column) or True

    return Requirement("condition", "a condition that varies within a record (or the same motion at two values)",
                       held, to=to, remedy=remedy)


def full_amplitude(share: float = 0.9) -> Requirement:
    """The validation records sweep ``share`` of the range the model was fitted on (``span_deg``)."""
    def held(data: HysteresisData, span_deg: float | None = None, **_):
        if span_deg is None or float(np.ptp(data.cmd_deg)) >= share * span_deg:
            return True
        return (f"the validation record spans {np.ptp(data.cmd_deg):.3g} of the {span_deg:.3g} deg the model was "
                "fitted on")

    return Requirement("amplitude", "the full amplitude of the fitted range", held, to="next",
                       lacking="not the full amplitude")
