"""Views of a validation that the command line and the Python API share.

The library runs a validation once and returns one
:class:`~endocal.validation.offline.ValidationResult`
(:func:`~endocal.validation.offline.validate_records`). These functions render it, beside the CLI
and the API, which both call them:

- :func:`validation_dict`: what ``endocal validate --json`` prints and ``Validation.to_dict()``
  returns, key for key: the result's own data, with each suspect's refit also as its shell
  ``command`` and the next experiment's ``excite_commands`` (:mod:`endocal.shell`);
- :func:`validation_summary`: at most :data:`SUMMARY_MAX_LINES` lines (how far off, where, what is
  missing, one keyed line per warning and note (:mod:`endocal.messages`), the next command),
  printed by the command line and joined by ``repr(validation)``.

``--explain`` prints every detail of the same result (:func:`endocal.cli.validate.render`).
"""

from __future__ import annotations

from pathlib import Path

from endocal.messages import capped, key_of, keyed_lines
from endocal.shell import excite_commands, refit_command, report_command, validate_command

#: Lines the summary of an offline validation prints at most (issue 26: a verdict a person reads at a glance).
SUMMARY_MAX_LINES = 15

#: Keys of notes the summary prints as warnings (the scores themselves are in question).
_WARNING_NOTES = ("in-sample", "beyond-range", "slow-clock")


def scheme_word(result) -> str:
    """What kind of RMSE the scan's numbers are, in one word."""
    if result.scan.scheme != "estimation/validation":
        return "held-out"
    return "in-sample" if result.in_sample else "validation"


def promise(suspect, what: str) -> str:
    """``-45 % validation RMSE (2.45 -> 1.33 deg)``, and where the scan fitted a subsample, the range to
    expect of the refit on every sample: ``, its refit on every sample expected at 1.3 .. 1.41 deg``."""
    return (f"-{suspect.gain_pct:.0f} % {what} RMSE ({suspect.base_rmse_heldout_deg:.3g} -> "
            f"{suspect.rmse_heldout_deg:.3g} deg)") + suspect.refit.expected_words()


def suspect_dict(suspect) -> dict:
    """A suspect's JSON: its fields, with ``command`` (its refit as shell text) right after ``refit``."""
    out = {}
    for k, val in suspect.to_dict().items():
        out[k] = val
        if k == "refit":
            out["command"] = refit_command(suspect.refit)
    return out


def base_dict(candidate) -> dict:
    """A base candidate's JSON (:class:`~endocal.validation.bases.BaseCandidate`): its fields, with ``command``
    (its refit as shell text)."""
    return {**candidate.to_dict(), "command": refit_command(candidate.refit)}


def validation_dict(result) -> dict:
    """The JSON of a :class:`~endocal.validation.offline.ValidationResult`: ``result.to_dict()`` with every
    suspect's (and tested candidate's) ``command`` and, with a next experiment, its ``excite_commands``."""
    d = result.to_dict()
    d["suspects"] = [suspect_dict(s) for s in result.scan.suspects]
    d["scan"]["suspects"] = [suspect_dict(s) for s in result.scan.suspects]
    d["scan"]["tested"] = [suspect_dict(s) for s in result.scan.tested]
    d["scan"]["bases"] = [base_dict(b) for b in result.scan.bases]  # the base candidates too
    if result.next is not None:
        d["next"] = {**d["next"], "excite_commands": excite_commands(result.next.excite)}
    return d


def validation_summary(result) -> list[str]:
    """The summary lines of a :class:`~endocal.validation.offline.ValidationResult` (at most
    :data:`SUMMARY_MAX_LINES`).

    How far off (the RMSE with its interval), where (the worst regime), what is missing (the first
    suggestion with its gain and p, or nothing), the untested suspects by name, one keyed line per
    warning and note, and the next command. When nothing is suggested but suspects are untested or
    effects untestable on these records, and ``next=`` can design for this model, the next command is
    this validation with ``--next``, which writes the experiment that tests them.
    """
    m, scan, c = result.model, result.scan, result.compare
    n = sum(d["n_samples"] for d in result.data)
    what = scheme_word(result)
    lo, hi = result.metrics.ci.get("rmse_deg", (float("nan"), float("nan")))
    # "validation" only when the model was fitted on other data; rolling origin adds its held-out RMSE
    word = "" if scan.scheme != "estimation/validation" else "in-sample " if result.in_sample else "validation "
    heldout = (f", held-out {scan.baseline_rmse_heldout_deg:.3g} deg (rolling origin)"
               if scan.scheme == "rolling-origin" else "")
    unit = m.get("drive_unit") or "deg"  # the command's: a linear drive's in mm; the angles stay deg
    drive = "" if unit == "deg" else f" (drive commanded in {unit})"
    head = [f"{m['label']} on axis {result.axis}{drive}: {word}RMSE {result.metrics.rmse_deg:.3g} deg (95 % CI "
            f"{lo:.3g} .. {hi:.3g}){heldout}, {n} samples from {len(result.data)} record(s)"]
    if c is not None:
        since = f"{c.old_label} ({Path(c.old_path).name})" if c.old_path is not None else c.old_label
        head.append(f"error {'fell' if c.change_pct < 0 else 'rose'} {abs(c.change_pct):.0f} % since {since}: {what} "
                    f"RMSE {c.old_heldout_rmse_deg:.3g} -> {c.new_heldout_rmse_deg:.3g} deg")
    worst = result.regimes.worst(1)
    if worst:
        r = worst[0]
        head.append(f"worst regime: {r.group}: {r.name}: RMSE {r.metrics.rmse_deg:.3g} deg ({r.ratio:.2f}x "
                    f"overall), {100 * r.fraction:.0f} % of samples")
    verdict, then = _verdict(result)
    head.append(verdict)
    change = scan.base_suggestions[:1]  # another base, the same paired test (validation.bases)
    if change:
        head.append(change[0].line(what))
        if scan.base_first:  # the base change before the first effect (validation.bases.base_before_effect)
            with_ = f" and {', '.join(change[0].added)}" if change[0].added else ""
            then = [f"next: refit with the {change[0].base} base{with_}, then validate the new model:",
                    "  " + refit_command(change[0].refit)]
    if result.pointers:
        head.append("untested suspects: " + ", ".join(dict.fromkeys(p.effect for p in result.pointers)))
    tail = [*then, "details: --explain (every metric with its interval, regime, residual test, candidate and note)"]
    # the fit's own warnings, then the notes that put the scores in question, as warnings; the
    # beyond-range note only where it matters (over a tenth of the samples)
    big = result.beyond_samples > 0.1 * n
    warned = [x for x in result.notes if key_of(x) in _WARNING_NOTES and (key_of(x) != "beyond-range" or big)]
    notes = [x for x in result.notes if key_of(x) not in _WARNING_NOTES]
    lines = capped(keyed_lines([*m.get("fit_warnings", []), *warned]) + keyed_lines(notes, "note"),
                   SUMMARY_MAX_LINES - len(head) - len(tail), "warnings and notes")
    return head + lines + tail


def _request_of(result):
    """What a result made by ``validate_offline`` alone was asked, as far as it records it."""
    from endocal.validation.offline import ValidationRequest

    return ValidationRequest(model_path=result.model.get("path"), data=tuple(str(d["source"]) for d in result.data))


def _named(s, result) -> str:
    """A suspect as the summary names it: a form tried in place of the plain term the model carries says so."""
    from endocal.models.effects import plain_form

    plain = plain_form(s.effect)
    if plain is not None and plain in result.model.get("effects", ()):
        return f"{s.effect} (in place of {plain})"
    return s.effect


def _verdict(result) -> tuple[str, list[str]]:
    """What is missing, in one line, and the next command (lines)."""
    req = result.request or _request_of(result)
    scan, what = result.scan, scheme_word(result)
    untested = list(dict.fromkeys([*(p.effect for p in result.pointers), *scan.untestable]))
    again = (validate_command(req.model_path, req.data, train=req.train, cv=req.cv, planes=req.planes,
                              probe=req.probe, next_path="next.toml")
             if req.next_possible and req.model_path is not None and result.next is None else None)
    design = [f"next: write the experiment that tests {', '.join(untested)}: {again}"] if again and untested else []
    n = sum(d["n_samples"] for d in result.data)
    old_path = result.compare.old_path if result.compare is not None else None
    models = [p for p in (old_path, req.model_path) if p is not None]
    report = [f"next: compare the models on these records, with figures: {report_command(models, req.data)}"] \
        if models else []
    if result.suspects:
        s = result.suspects[0]
        thin = not any(x.significant for x in result.suspects)
        others = [x.effect for x in result.suspects[1:]]
        verdict = (f"{'first candidate' if thin else 'missing'}: {_named(s, result)}: {promise(s, what)}, "
                   + (s.evidence if thin else f"p = {s.p_value:.2g}")
                   + (f"; also: {', '.join(others)}" if others else ""))
        if result.beyond_samples > 0.5 * n:
            return verdict, ["next: refit on data that covers this record's commands (most of it lies beyond the "
                             "model's range), then validate again"]
        then = "validate the new model on a third record" if req.folded else "validate the new model"
        return verdict, [f"next: refit with {s.effect}, then {then}:", "  " + refit_command(s.refit)]
    if scan.scheme == "none":
        return f"missing: not tested: {scan.scheme_reason}", []
    if result.pointers:
        p = result.pointers[0]
        return ("missing: nothing the scan confirmed, but the data point at effects it could not settle"
                + (f"; and {result.unexplained}" if result.unexplained else ""),
                design or [f"next: to test {p.effect}: {p.experiment}"])
    # after a refit (a model to compare with) the report of the two stays a next step beside the design
    then = [*design, *report] if design and old_path is not None else design or report
    if result.unexplained:
        return (f"nothing missing from the catalog (no effect lowers the {what} RMSE by {scan.min_gain_pct:g} % or "
                f"more), but {result.unexplained}", then)
    if scan.tested and scan.tested[0].gain_pct >= scan.min_gain_pct:
        best = scan.tested[0]
        return (f"nothing significant missing: the best candidate, {best.effect}, lowers the {what} RMSE by "
                f"{best.gain_pct:.0f} % but not consistently (p = {best.p_value:.2g})", then)
    still = (f"; but {scan.still_blocks} of its {scan.folds} held-out blocks hold no motion of this axis"
             if scan.still_blocks else "")
    return (f"nothing missing: no catalog effect lowers the {what} RMSE by {scan.min_gain_pct:g} % or more{still}",
            then)
