"""Warnings and notes as the library makes them: each one's text and its key, from birth.

A :class:`Message` is a ``str`` (its full text, what ``--explain`` prints and the JSON holds)
that also carries its ``key``, one of :data:`KEYS`: the summary prints it as
``warning[KEY]: the fact``, and the docs explain each key. The key is given where the message is
made, never found from its wording afterwards, so rewording a message cannot change its key (ruff's
diagnostics carry their rule code from birth the same way).

This module imports nothing: every command imports it, ``--help`` included.
"""

from __future__ import annotations

import re

#: Every key a warning or note can carry, and what it means (what happened, what to do).
KEYS: dict[str, str] = {
    # ---- fit hysteresis (and validate, which repeats the warnings of the model's fit)
    "not-converged": "The optimiser stopped before converging (its evaluation budget or a tolerance): the parameters "
                     "may not be final. Refit with `--start-from` the model just written.",
    "slow-clock": "The records hold under one sample per second. Knob loops are logged at tens of Hz, so `t_s` is "
                  "probably in milliseconds (1000x too slow), which makes every time-based effect (delay, creep, "
                  "drift) meaningless. `endocal import csv` converts units.",
    "few-samples": "Fewer than 10 samples per free parameter: the fit may follow the noise. Check it on a record it "
                   "was not fitted on (`endocal validate`).",
    "at-bound": "An effect's parameter sits at a bound of its range: the data does not constrain it. The effect may "
                "be absent from this data, or stand in for something else.",
    "unidentified": "An effect's parameter has a standard error larger than its value: the data does not identify "
                    "it. Record motion that exercises the effect (`endocal effects` names the experiment), or drop "
                    "the effect.",
    "dead-band": "The envelope fitted a dead band (a nearly flat middle segment): its outer slopes and zero have no "
                 "useful standard errors, though its shape and the predictions are identified. The `deadzone` "
                 "effect models tendon slack as such.",
    "line-fit": "The fit is no better than a straight line through the data: the base model found no hysteresis "
                "loop it can shape. Look at the loop (`endocal report`) and try another base (`--model bspline` or "
                "`--model linear`).",
    "local-minimum": "Started from the `--start-from` model's values, the fit ended worse than that model itself (a "
                     "local minimum); it was fitted from scratch instead, and the better of the two kept.",
    "from-scratch": "A fit from scratch ended more than 1 % lower on the records than the one started from the "
                    "`--start-from` model's values (a local minimum), and was kept: the refit is not the candidate "
                    "`validate` scored, so its validation RMSE can differ from the one promised (usually lower).",
    "pi-weights": "The PI model's weight law (the paper's eq. 8, or free weights) fitted worse than a straight line "
                  "per direction of motion; the other law was taken.",
    "glitches": "Samples that jump away from their neighbours and back (a tracker or logger glitch), or a tracker "
                "repeating one reading while the knob moves, were left out; the fit and the scores use the samples "
                "around them.",
    "start-estimated": "A record does not start at rest (it was cut from a longer motion): every model, candidates "
                       "too, runs it from the start state that predicts its first stretch best. For information.",
    "start-cut": "A record's error before its first reversal is over twice its error after it, and no start state "
                 "tried explains it (a step, a first sweep from a relaxed sheath, a tip still bent): that stretch "
                 "measures the start, not the physics, and a time-dependent candidate may fit it. Cut the records "
                 "at their first reversal, or move the knob through its range before each acquisition.",
    # ---- validate
    "in-sample": "The estimation data includes the record validated: every score is in-sample and flatters the "
                 "model. Validate on a record the model was not fitted on.",
    "beyond-range": "Samples command beyond the range the model was fitted on: there the model is extrapolated, and "
                    "much of the error may be that. Refit on data that covers those commands.",
    "untestable": "An effect the data cannot reveal, or a candidate that could not be fitted (e.g. `load` with no "
                  "varying covariate column, `coupling` when the other knob never moves); the full text says what "
                  "to record.",
    "subsampled": "The effect scan fitted its candidates on 1 sample in N, to stay quick; the printed refit fits "
                  "every sample, and each suggestion gives the range of validation RMSE to expect of it (the "
                  "candidate fitted on two interleaved subsamples).",
    "few-units": "The validation data holds too few units (half-cycles or blocks) for the Holm-corrected tests of "
                 "every candidate to reach significance: record more cycles.",
    "alike": "Two candidate effects explain the residual about equally well; the full text names the experiment "
             "that tells them apart.",
    "demoted": "A candidate lowers the error more than the first suggestion but ranks after it, for a caution (a "
               "parameter at a bound, no hold where creep would show): it may stand in for something it does not "
               "model.",
    "cautioned-first": "A candidate whose only caution is that no record holds what would confirm it goes first "
                       "anyway: its refit beats the first suggestion without a caution by the gain bar, in a paired "
                       "test of the two. Record what the caution names to confirm it.",
    "borrowed": "An additive term (`drift`) lowered the validation error only through the parameters refitted beside "
                "it: the same fit with its own term taken out scores about as well. It is not suggested; the "
                "structure misses something on some record (the full text names the share).",
    "minor-loops": "The error concentrates after small reversals inside the loop: the base's memory rule (return-point "
                   "memory: a small reversal returns to the branch it left) misses the plant's minor loops. Try a base "
                   "without it (`--model bouc-wen` or `--model dahl`); validate scores them as candidates.",
    "memory-rule": "A base of the other memory rule (return-point memory or not) clears both bars but is not "
                   "suggested: the validation data hold too few small reversals inside the loop, where the two rules "
                   "differ, so its gain is its branch shapes'. Validate on a record with small reversals (a random "
                   "run) to judge the change.",
    "still-blocks": "Some held-out blocks of the rolling-origin scan hold no motion of the axis: there the scan says "
                    "little. Validate on a record where the axis moves throughout.",
    # ---- fit planes, fit force
    "frames-dropped": "Tracker frames were left out of the bending-plane fit (invalid, or off the sweep).",
    # ---- import csv, import ros
    "dedupe-dropped": "`--dedupe` dropped rows repeating an earlier row in every column the map uses (ROS bridges "
                      "write them).",
    "dedupe-merged": "`--dedupe` merged rows of one time stamp that fill different columns (a motor tick and a "
                     "tracker frame in the same millisecond).",
    "incomplete-rows": "Rows with some knob cells but not every knob position were left out of the motor samples.",
    "invalid-frames": "Tracker frames were invalid (a sensor's cell empty, its quaternion no rotation, or flagged by "
                      "the map's valid column) and were left out of the aligned table.",
    "unused-rows": "Rows held neither a motor sample nor a pose (or angle reading) in the mapped columns.",
    "gap": "Motor samples were left out of the aligned table with no tracker frame (or angle reading) to "
           "interpolate: a gap in the tracker's stream, or samples outside its span.",
    "unit": "Measured angles whose numbers look like a unit mistake (radians read as degrees, or the reverse): check "
            "the map's unit.",
    "no-aligned-table": "The streams were written but no aligned table could be made (the full text says why); "
                        "`fit` and `validate` read the aligned table.",
    "unpaired-poses": "Tip poses with no base pose within `--pair-tolerance` were dropped.",
    # ---- report
    "not-evaluated": "A model could not be scored on a record (another axis, a missing column); the full text says "
                     "why.",
    "planes-figure": "The bending-plane figure could not draw everything (sweeps not found, or not the ones the "
                     "planes were fitted on).",
    "no-tip-path": "A record's tracker stream is there but cannot be read (the note says why), so the report draws no "
                   "task-space tip trajectory for it; a record without one (an aligned table) is drawn without a note.",
    "force-stop": "The contact-force guard stopped a playback: the predicted tip force reached its threshold.",
    # ---- export c
    "float-holds": ("A float compensator whose inverse jumps (a play: deadzone, tension, rate; a linear or B-spline base'"
                    "s backlash) decides on the sign of each step of the desired angle, and float cannot see a step below"
                    " its resolution: there it can turn the knob by a play's width a tick later than double, or stay apar"
                    "t after holds. Generate double (the default) where the target has a double FPU."),
    # ---- anything else
    "other": "A message without a key of its own; `--explain` prints it in full.",
}


class Message(str):
    """A warning or note: its text (a ``str``), and its :attr:`key` from :data:`KEYS`.

    ``Message("delay_s = -0.5 sits at its lower bound ...", "at-bound")``. String operations
    (slicing, ``+``, formatting) give plain text without the key: make the message whole, then
    wrap it.

    Raises
    ------
    KeyError
        ``key`` is not in :data:`KEYS` (a key printed is a key the docs explain).
    """

    __slots__ = ("key",)

    def __new__(cls, text: str, key: str) -> Message:
        if key not in KEYS:
            raise KeyError(f"message key {key!r} is not in endocal.messages.KEYS")
        self = super().__new__(cls, text)
        self.key = key
        return self

    def __getnewargs__(self) -> tuple[str, str]:  # pickled across the scan's worker processes, key and all
        return str(self), self.key

    def __reduce__(self):
        return (Message, (str(self), self.key))


_PREFIX = re.compile(r"^(warning|note|fit warning): ")


def key_of(text: str) -> str:
    """The key a message was made with (:class:`Message`); ``"other"`` for plain text, which no key names."""
    return getattr(text, "key", "other")


#: First clauses that only say what a message is about ("load: ...", "bending planes: ..."): the fact follows.
_TOPICS = {"bending planes", "no aligned table"}


def _clauses(body: str) -> list[str]:
    """``body`` split at each ``": "`` outside brackets."""
    parts, depth, last = [], 0, 0
    for i, ch in enumerate(body):
        if ch in "([":
            depth += 1
        elif ch in ")]":
            depth = max(0, depth - 1)
        elif ch == ":" and depth == 0 and body[i + 1:i + 2] == " " and i > last:
            parts.append(body[last:i])
            last = i + 2
    return parts + [body[last:]]


def head(text: str) -> str:
    """A message's fact: its words up to the first ``": "`` outside brackets (the whole text when there is none).

    The library words a warning as ``fact: consequence; what to do``; the summary keeps the fact
    (also cut at a ``"; "`` outside brackets). A
    first clause that names a topic (one word, as ``load: ...``) keeps the clause after it; a
    question right after the fact is kept (``0.1 samples per second: is t_s in seconds?``).
    """
    parts = _clauses(_PREFIX.sub("", text))
    n = 2 if len(parts) > 1 and (" " not in parts[0] or parts[0] in _TOPICS) else 1
    if len(parts) > n and re.fullmatch(r"[^;(]*\?", parts[n].split(" (")[0]):
        n += 1
        parts[n - 1] = parts[n - 1].split(" (")[0]
    fact = ": ".join(parts[:n])
    depth = 0
    for i, ch in enumerate(fact):  # "fact; what to do": the fact
        depth += (ch in "([") - (ch in ")]")
        if ch == ";" and depth <= 0 and i > 0:
            return fact[:i]
    return fact


#: Keys whose summary line is more than the fact: key -> function of the full text giving the line.
_SHORT = {
    # a unit that looks wrong: the fact, and the map keys to check
    "unit": lambda t: head(t) + ": check " + ", ".join(dict.fromkeys(re.findall(r"\[\w+\.\w+\] unit", t))),
}


def keyed(text: str, kind: str = "warning", key: str | None = None) -> str:
    """``kind[KEY]: fact`` -- one line for the summary (``--explain`` prints ``text`` in full)."""
    key = key or key_of(text)
    if key not in KEYS:  # a key printed is a key the docs explain
        raise KeyError(f"warning key {key!r} is not in endocal.messages.KEYS")
    return f"{kind}[{key}]: {_SHORT.get(key, head)(text)}"


#: Keys whose messages each begin with a name (a parameter's ``name = value``, an effect's ``effect: ...``):
#: several make one line naming them all. Key -> (what ends the name, what the line says of them).
_GROUPED = {
    "at-bound": (" = ", "sit at a bound of their range"),
    "unidentified": (" = ", "have standard errors above their values"),
    "untestable": (": ", "cannot be tested on this data"),
}


def keyed_lines(messages, kind: str = "warning") -> list[str]:
    """One :func:`keyed` line per message, in order; empty messages skipped. A message is its text
    (its key found from its words) or ``(key, text)``. Several messages of a key that names a
    parameter or an effect first (:data:`_GROUPED`) make one line naming them."""
    pairs = [(m if isinstance(m, tuple) else (key_of(m), m)) for m in messages if m]
    pairs = [(k, t) for k, t in pairs if t]
    lines, done = [], set()
    for k, t in pairs:
        group = [x for kx, x in pairs if kx == k]
        if k in _GROUPED and len(group) > 1:
            if k not in done:
                done.add(k)
                end, says = _GROUPED[k]
                names = ", ".join(dict.fromkeys(_PREFIX.sub("", x).split(end, 1)[0] for x in group))
                lines.append(f"{kind}[{k}]: {names} {says}")
            continue
        lines.append(keyed(t, kind, k))
    return lines


def capped(lines: list[str], budget: int, what: str = "warnings") -> list[str]:
    """At most ``budget`` of ``lines``: when there are more, the first ``budget - 1`` and a line
    saying how many more ``--explain`` prints."""
    if len(lines) <= budget:
        return lines
    keep = max(budget - 1, 0)
    return lines[:keep] + [f"... {len(lines) - keep} more {what} (--explain prints them)"]
