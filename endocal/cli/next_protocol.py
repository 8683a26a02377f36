"""``endocal validate ... --next NEXT.toml``: say what the next experiment tests and how to record it."""

from __future__ import annotations

import shlex

from endocal.cli._common import err, out


def next_json(outcome) -> dict:
    """``next`` of ``validate --json``: :meth:`~endocal.validation.next_experiment.NextOutcome.to_dict`
    with the excite command lines as a shell takes them (``excite_commands``)."""
    return {**outcome.to_dict(), "excite_commands": [shlex.join(a) for a in outcome.excite]}


def render_next(outcome, as_json: bool) -> None:
    """Print what the protocol written tests and the ``excite`` commands that record it (to stderr
    under ``--json``, whose stdout is the JSON object). Nothing written: nothing printed (the
    caller refuses in one line)."""
    nx = outcome.experiment
    if nx is None:
        return
    say = err if as_json else out
    say.print(f"[bold]Next experiment[/] written to {outcome.path} ({nx.duration_s:.0f} s on probe {nx.probe}): tests "
              f"{', '.join(nx.suspects)}")
    for t in nx.tests:
        where = f"segment {t.segment}" if t.segment is not None else "the whole run"
        say.print(f"  {t.effect} ({t.status}): {where}, {t.half_cycles} half-cycles", markup=False)
    for note in nx.notes:
        say.print(f"  not in it: {note}", markup=False)
    for k, instruction in nx.conditions.items():
        say.print(f"  condition {k}: {instruction}", markup=False)
    say.print("Record it twice, once to add to the estimation data and once to validate on"
              + (" (and, for the condition, the same motion at the earlier value, to add to the estimation data too)"
                 if len(outcome.excite) > 2 else "") + ":", markup=False)
    for args in outcome.excite:
        say.print("  " + shlex.join(args), markup=False)
