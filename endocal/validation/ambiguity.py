"""Suspects that explain the residual alike, and the experiment that tells them apart.

After the scan ranks its suspects, two of them may lower the error about equally (a delay
and speed-dependent friction both widen a loop at one frequency), or one that lowers it
more may rank after the first because its fit is suspect (:attr:`Suspect.caution`): these
notes say so, in words, with what to record next. A first suggestion with a declared
look-alike (``Effect.lookalikes``) is settled against it on records that separate the two
(:func:`settle_lookalikes`): the records' preference, with p.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import asdict, dataclass

import numpy as np

from endocal.errors import ModelError
from endocal.models import EFFECTS, HysteresisData
from endocal.models.effects import make_effect, plain_form
from endocal.validation.identifiability import untestable_reason
from endocal.validation.paired import paired_test, unit_test
from endocal.validation.structure import with_candidate
from endocal.validation.suspects import Suspect

def tell_apart(a: str, b: str) -> str | None:
    """The records that separate effects ``a`` and ``b`` as either declares them (``Effect.lookalikes``);
    None when neither names the other."""
    for x, y in ((a, b), (b, a)):
        cls = EFFECTS.get(x)
        if cls is not None and y in cls.lookalikes:
            return cls.lookalikes[y]
    return None


def cautioned_last(suspects: list[Suspect], errs: dict, units, alpha: float, min_gain_pct: float,
                   unconfirmed: Collection[str] = ()) -> tuple[list[Suspect], str]:
    """``suspects`` (by decreasing gain) with the cautioned ones after the others, and a note (``""`` if none).

    A caution says the term may stand in for something it does not model, so by default it ranks
    last. One kind of caution says only that no record holds what would confirm the term (a `creep`
    fitted where no record holds the knob still: the effects in ``unconfirmed``); a stand-in takes
    up a share of the residual, and a term that explains much more than the next candidate is more
    than that. So the best such candidate goes first where its refit beats the first uncautioned
    one's by ``min_gain_pct`` and in a paired test of their own (``unit_test`` on ``units``, raw p
    below ``alpha``), and the note says why (a `creep` at -53 % behind a `rate:friction` at -14 % on
    a Bouc-Wen plant that creeps and has no speed-dependent friction). A caution about the fitted
    values themselves (a parameter at its bound, a creep that relaxes within each motion) keeps the
    term last however much it gains.
    """
    out = sorted(suspects, key=lambda s: bool(s.caution))
    plain = [s for s in out if not s.caution]
    flagged = [s for s in out if s.caution and s.effect in unconfirmed]
    if not (plain and flagged) or flagged[0].gain_pct <= plain[0].gain_pct:
        return out, ""
    c, u = flagged[0], plain[0]
    ahead = 100.0 * (1.0 - c.rmse_heldout_deg / u.rmse_heldout_deg) if u.rmse_heldout_deg > 0 else 0.0
    p = unit_test(errs[u.effect], errs[c.effect], units) if ahead >= min_gain_pct else 1.0
    if p >= alpha:
        return out, ""
    return [c] + [s for s in out if s is not c], (
        f"{c.effect} goes first despite its caution: its refit beats {u.effect}'s, the first suggestion without one, "
        f"by {ahead:.0f} % ({c.rmse_heldout_deg:.3g} vs {u.rmse_heldout_deg:.3g} deg, paired p = {p:.2g}); "
        f"{c.caution}")


def demoted(suspects: list[Suspect]) -> list[str]:
    """Notes on suggestions that lower the error more than the first but rank after it (a caution)."""
    if not suspects or suspects[0].caution:
        return []
    top = suspects[0]
    return [f"{s.effect} lowers the validation RMSE more than {top.effect} ({s.rmse_heldout_deg:.3g} vs "
            f"{top.rmse_heldout_deg:.3g} deg) but ranks after it: {s.caution}; it may stand in for something it does "
            "not model (how the records start, a loop shape)" for s in suspects[1:]
            if s.caution and s.rmse_heldout_deg < top.rmse_heldout_deg]


def _alike(a: Suspect, b: Suspect, errs: dict, alpha: float, close_pct: float) -> tuple[bool, float, float]:
    """Whether ``a`` and ``b`` explain the residual alike (within ``close_pct`` of each other, or apart by chance:
    the paired test of their errors at ``alpha``), with the test's p and the RMSEs' relative gap (percent)."""
    p, _ = paired_test(errs[b.effect], errs[a.effect])
    lo, hi = sorted((a.rmse_heldout_deg, b.rmse_heldout_deg))
    rel = 100.0 * (hi - lo) / max(lo, 1e-300)
    return not (p < alpha and rel >= close_pct), p, rel


def plain_first(suspects: list[Suspect], errs: dict, alpha: float, close_pct: float = 5.0) -> list[Suspect]:
    """Two forms of one effect that explain the residual alike rank by their physics, not by a few per cent.

    The plain form goes first (``deadzone`` before ``deadzone:tip``): another form is suggested only where the
    records prefer it. A form that acts on the base's one friction state (``Effect.needs_friction_state``:
    ``envelope:tip``, ``load:friction:COLUMN``, ``rate:friction``) is the other way round: it is the plain term's
    physics written for a base of one friction element (the stiffening past that element, a load that scales its
    holding force), and is a candidate only on such a base, so there it goes first, and the plain form, a second
    element in front of the first, only where the records prefer it.
    """
    out = list(suspects)
    for i in range(len(out)):
        s = out[i]
        plain = plain_form(s.effect)
        if plain is not None:
            partner, preferred = plain, (s.effect if make_effect(s.effect).needs_friction_state else plain)
        else:
            later = [x.effect for x in out[i + 1:] if plain_form(x.effect) == s.effect]
            if not later:
                continue
            partner = later[0]
            preferred = partner if make_effect(partner).needs_friction_state else s.effect
        if preferred == s.effect:
            continue
        j = next((k for k in range(i + 1, len(out)) if out[k].effect == partner), None)
        if j is not None and s.effect in errs and partner in errs and _alike(s, out[j], errs, alpha, close_pct)[0]:
            out.insert(i, out.pop(j))
    return out


def ambiguities(suspects: list[Suspect], errs: dict, alpha: float, close_pct: float = 5.0) -> list[str]:
    """Notes on suspects that explain the residual about as well as the top one."""
    if len(suspects) < 2:
        return []
    top = suspects[0]
    notes = []
    for other in suspects[1:]:
        if other.caution and not top.caution:
            continue  # ranked apart on purpose (demoted says why)
        alike, p, rel = _alike(top, other, errs, alpha, close_pct)
        if not alike:
            continue
        a, b = top.effect.partition(":")[0], other.effect.partition(":")[0]
        how = tell_apart(a, b) if a != b else (
            f"they are two forms of {a}, and more of what shows it separates them ({EFFECTS[a].protocol})")
        if how is None:
            how = (f"{top.effect} is revealed by {EFFECTS[a].protocol}; "
                   f"{other.effect} by {EFFECTS[b].protocol}")
        alike = "about equally" if rel < close_pct else f"alike within chance (paired p = {p:.2g})"
        notes.append(f"{top.effect} and {other.effect} explain the residual {alike} (held-out RMSE "
                     f"{top.rmse_heldout_deg:.3g} vs {other.rmse_heldout_deg:.3g} deg); to tell them apart: {how}")
    return notes


@dataclass(frozen=True)
class Settlement:
    """A suggestion against one of its declared look-alikes (``Effect.lookalikes``).

    Attributes
    ----------
    suggested, lookalike : str
        The first suggestion and the look-alike it names.
    separated : bool
        The estimation records hold what tells the two apart (each one's ``to="test"``
        requirements): then both were scored; else ``why`` says what is missing.
    why : str
        What the records lack to separate them (empty when they do).
    apart : str
        The records that separate them, in words (the effect's declaration).
    rmse_suggested_deg, rmse_lookalike_deg, rmse_both_deg : float or None
        Validation RMSE with the suggestion, with the look-alike in its place (the pair
        swapped), and with the look-alike after it.
    preferred : str or None
        Which one the records prefer (the lower validation RMSE); ``p_value`` the one-sided
        paired test that it is lower (:func:`~endocal.validation.paired.unit_test`).
    p_after : float or None
        The paired test that the look-alike after the suggestion lowers the error further.
    settled : bool
        ``p_value`` below alpha: the records prefer ``preferred``.
    """

    suggested: str
    lookalike: str
    separated: bool
    why: str = ""
    apart: str = ""
    rmse_suggested_deg: float | None = None
    rmse_lookalike_deg: float | None = None
    rmse_both_deg: float | None = None
    preferred: str | None = None
    p_value: float | None = None
    p_after: float | None = None
    settled: bool = False

    @property
    def gain_after_pct(self) -> float | None:
        if self.rmse_both_deg is None or not self.rmse_suggested_deg:
            return None
        return 100.0 * (1.0 - self.rmse_both_deg / self.rmse_suggested_deg)

    def words(self) -> str:
        """One line: which one the records prefer, with p, or what would separate them."""
        a, b = self.suggested, self.lookalike
        if not self.separated:
            return (f"{a} and {b} look alike and these records cannot separate them ({self.why}); to separate them: "
                    f"{self.apart} (--next sizes that segment)")
        other = b if self.preferred == a else a
        pref = self.rmse_suggested_deg if self.preferred == a else self.rmse_lookalike_deg
        rest = self.rmse_lookalike_deg if self.preferred == a else self.rmse_suggested_deg
        verdict = "the records prefer" if self.settled else "the records lean to"
        after = (f"; {b} after {a}: {self.rmse_both_deg:.3g} deg ({-self.gain_after_pct:+.0f} %, p = {self.p_after:.2g})"
                 if self.rmse_both_deg is not None else "")
        tail = "" if self.settled else f", not significant: to separate them, {self.apart} (--next sizes that segment)"
        return (f"{a} or its look-alike {b}: {verdict} {self.preferred} over {other} (validation RMSE {pref:.3g} vs "
                f"{rest:.3g} deg, p = {self.p_value:.2g}){after}{tail}")

    def to_dict(self) -> dict:
        return {**asdict(self), "gain_after_pct": self.gain_after_pct, "words": self.words()}


def settle_lookalikes(suspects: list[Suspect], tested: list[Suspect], errs: dict, train: HysteresisData,
                      val: HysteresisData, units, alpha: float, min_gain_pct: float,
                      fit_errors: Callable[[list[str]], np.ndarray], have: list[str]
                      ) -> tuple[list[Suspect], list[Settlement]]:
    """Score the first suggestion against each look-alike it declares, on records that separate them.

    For the first suggestion ``a`` and each look-alike ``b`` it declares (``Effect.lookalikes``) that the
    model lacks: when the estimation records hold what tells them apart (both effects' ``to="test"``
    requirements: several speeds for ``delay``/``rate``, holds for ``creep``/``drift``), the model with
    ``b`` in ``a``'s place (the pair swapped) and with ``b`` after ``a`` are scored on the validation
    data beside ``a`` alone; the paired test of ``a`` against ``b`` says which the records prefer, with
    p. A look-alike the records prefer (p < alpha) that clears the gain bar itself becomes the first
    suggestion. Where the records cannot separate them, the settlement says so (``--next`` designs the
    look-alike's segment).

    Parameters
    ----------
    suspects, tested : list of Suspect
        The scan's suggestions (ranked) and every candidate it tested.
    errs : dict
        Candidate -> its validation errors (deg), ``have + [candidate]`` fitted on ``train``.
    train, val : HysteresisData
        Estimation (as the candidates were fitted on) and validation data.
    units : Units
        The validation data's units of the paired test.
    fit_errors : callable
        Validation errors of ``base + effects`` fitted on ``train``.
    have : list of str
        The model's effects.

    Returns
    -------
    suspects : list of Suspect
        Re-ranked when a look-alike is preferred.
    settlements : list of Settlement
    """
    if not suspects:
        return suspects, []
    top = suspects[0]
    a = top.effect.partition(":")[0]
    if a not in EFFECTS:
        return suspects, []
    by_label = {s.effect: s for s in tested}
    out: list[Settlement] = []
    new_top = None
    have_names = {h.partition(":")[0] for h in have}
    for b, apart in EFFECTS[a].lookalikes.items():
        if b not in EFFECTS or b in have_names:
            continue
        why = untestable_reason(a, train, to=("test",)) or untestable_reason(b, train, to=("test",))
        if why is not None:
            out.append(Settlement(top.effect, b, False, why=why, apart=apart))
            continue
        try:
            err_b = errs[b] if b in errs else fit_errors(have + [b])
            err_ab = fit_errors(with_candidate(have, top.effect) + [b])
        except ModelError as exc:
            out.append(Settlement(top.effect, b, False, why=f"{b} could not be fitted on these records ({exc})",
                                  apart=apart))
            continue
        err_a = errs[top.effect]
        ra, rb, rab = (float(np.sqrt(np.mean(e**2))) for e in (err_a, err_b, err_ab))
        preferred, p = (b, unit_test(err_a, err_b, units)) if rb < ra else (top.effect, unit_test(err_b, err_a, units))
        settled = bool(p < alpha)
        out.append(Settlement(top.effect, b, True, apart=apart, rmse_suggested_deg=ra, rmse_lookalike_deg=rb,
                              rmse_both_deg=rab, preferred=preferred, p_value=float(p),
                              p_after=float(unit_test(err_a, err_ab, units)), settled=settled))
        s_b = by_label.get(b)
        if (preferred == b and settled and s_b is not None and s_b.gain_pct >= min_gain_pct and not s_b.caution
                and new_top is None):
            new_top = s_b
    if new_top is not None:
        suspects = [new_top] + [s for s in suspects if s.effect != new_top.effect]
    return suspects, out
