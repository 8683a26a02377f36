"""Suspects that explain the residual alike, and the experiment that tells them apart.

After the scan ranks its suspects, two of them may lower the error about equally (a delay
and speed-dependent friction both widen a loop at one frequency), or one that lowers it
more may rank after the first because its fit is suspect (:attr:`Suspect.caution`): these
notes say so, in words, with what to record next.
"""

from __future__ import annotations

from endocal.models import EFFECTS
from endocal.validation.paired import paired_test
from endocal.validation.suspects import Suspect

def tell_apart(a: str, b: str) -> str | None:
    """The records that separate effects ``a`` and ``b`` as either declares them (``Effect.lookalikes``);
    None when neither names the other."""
    for x, y in ((a, b), (b, a)):
        cls = EFFECTS.get(x)
        if cls is not None and y in cls.lookalikes:
            return cls.lookalikes[y]
    return None


def demoted(suspects: list[Suspect]) -> list[str]:
    """Notes on suggestions that lower the error more than the first but rank after it (a caution)."""
    if not suspects or suspects[0].caution:
        return []
    top = suspects[0]
    return [f"{s.effect} lowers the validation RMSE more than {top.effect} ({s.rmse_heldout_deg:.3g} vs "
            f"{top.rmse_heldout_deg:.3g} deg) but ranks after it: {s.caution}; it may stand in for something it does "
            "not model (how the records start, a loop shape)" for s in suspects[1:]
            if s.caution and s.rmse_heldout_deg < top.rmse_heldout_deg]


def ambiguities(suspects: list[Suspect], errs: dict, alpha: float, close_pct: float = 5.0) -> list[str]:
    """Notes on suspects that explain the residual about as well as the top one."""
    if len(suspects) < 2:
        return []
    top = suspects[0]
    notes = []
    for other in suspects[1:]:
        if other.caution and not top.caution:
            continue  # ranked apart on purpose (demoted says why)
        p, _ = paired_test(errs[other.effect], errs[top.effect])
        lo, hi = sorted((top.rmse_heldout_deg, other.rmse_heldout_deg))
        rel = 100.0 * (hi - lo) / max(lo, 1e-300)
        if p < alpha and rel >= close_pct:
            continue
        a, b = top.effect.partition(":")[0], other.effect.partition(":")[0]
        how = tell_apart(a, b)
        if how is None:
            how = (f"{top.effect} is revealed by {EFFECTS[a].protocol}; "
                   f"{other.effect} by {EFFECTS[b].protocol}")
        alike = "about equally" if rel < close_pct else f"alike within chance (paired p = {p:.2g})"
        notes.append(f"{top.effect} and {other.effect} explain the residual {alike} (held-out RMSE "
                     f"{top.rmse_heldout_deg:.3g} vs {other.rmse_heldout_deg:.3g} deg); to tell them apart: {how}")
    return notes
