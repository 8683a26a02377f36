"""The candidate effects a scan tests: every catalog effect the model lacks that the data can show.

``load`` takes a column (``load:sheath_wrap_deg``) and is tried on every extra column that
varies; an effect's other forms (``Effect.variants``: ``deadzone:tip``, ``load:friction:COLUMN``) are tried
beside it, and a form that acts on a friction base's one friction state in place of the plain term the model
carries (:func:`_swaps_in`: a model changed to a friction base may hold the plain form its first base forced); an
effect the data cannot reveal or fit (what it declares in ``Effect.requires``,
:mod:`endocal.validation.identifiability`) is not tested, and why is said.
"""

from __future__ import annotations

from collections.abc import Sequence

from endocal.errors import ModelError
from endocal.models import EFFECTS, HysteresisData
from endocal.models.base import HysteresisModel
from endocal.models.effects import make_effect, plain_form, variant_forms
from endocal.validation.data import load_candidates
from endocal.validation.identifiability import untestable_reason
from endocal.validation.structure import effect_labels


def takes_column(name: str) -> bool:
    """True for catalog effects that need a column, written ``NAME:COLUMN`` (``load``)."""
    try:
        EFFECTS[name]()
    except (ModelError, TypeError):
        return True
    return False


def _swaps_in(model: HysteresisModel, form: str, have: Sequence[str]) -> bool:
    """Whether ``form`` is tried in place of the plain effect ``model`` carries: a form that acts on the base's one
    friction state (``Effect.needs_friction_state``: ``load:friction:COLUMN``, ``rate:friction``, ``envelope:tip``),
    which the model's base carries now but a base without one refused, so a model changed to this base may hold the
    plain form only because its first base did."""
    if form in have or plain_form(form) not in have:
        return False
    effect = make_effect(form)
    return bool(effect.needs_friction_state) and not model.refuses(effect)


def candidate_effects(model: HysteresisModel, data: HysteresisData, candidates: Sequence[str] | None,
                      load_columns: Sequence[str] | None, bending_axes: Sequence[str], *,
                      train: HysteresisData, rolling: bool) -> tuple[list[str], dict[str, str]]:
    """The catalog effects to test, and why the others cannot be tested on this data.

    Parameters
    ----------
    model : HysteresisModel
        The model as it stands (its effects are not candidates).
    data : HysteresisData
        All the data the scan uses (load candidates must vary in it).
    candidates, load_columns : sequence of str, optional
        As :func:`scan_effects`.
    bending_axes : sequence of str
        Knob columns that are not load candidates.
    train : HysteresisData
        The data candidates are fitted on (the first training block, or the estimation data):
        an effect whose parameters it cannot show (the other knob at rest, no time stamps)
        is not fitted.
    rolling : bool
        Rolling-origin cross-validation: effects that need several speeds (``rate``,
        ``delay``) or holds (``creep``) to be told from a wider loop are tested only on data
        that has them. Under the estimation/validation scheme every fittable candidate is
        tested: the separate validation data decides.

    Returns
    -------
    tested : list of str
    untestable : dict of str to str
    """
    have = effect_labels(model)
    have_names = {lab.partition(":")[0] for lab in have}
    untestable: dict[str, str] = {}
    if candidates is None:
        cands: list[str] = []
        for name in EFFECTS:
            if takes_column(name):
                constant: list[str] = []
                if load_columns is None:
                    cols, constant = load_candidates(data, bending_axes)
                else:
                    cols = list(load_columns)
                modelled = [c for c in cols if any(lab in have for lab in (f"{name}:{c}", *variant_forms(name, c)))]
                cols = [c for c in cols if c not in modelled]
                if not cols and not modelled:
                    where = "the estimation data" if not rolling else "the data"
                    what = (f"no extra column varies in {where} ({len(constant)} constant)" if constant else
                            f"{where} has no extra column")
                    untestable[name] = (f"{what}: {name} cannot be identified (log a covariate such as "
                                        "sheath_wrap_deg, at two or more values)")
                # a form the base cannot carry is not a candidate (load:friction:COLUMN needs a friction state)
                cands += [lab for c in cols for lab in (f"{name}:{c}", *variant_forms(name, c))
                          if lab == f"{name}:{c}" or not model.refuses(make_effect(lab))]
                cands += [lab for c in modelled for lab in variant_forms(name, c) if _swaps_in(model, lab, have)]
            elif name not in have_names:
                # a variant the base cannot carry is not a candidate (rate:friction needs a friction state)
                cands += [name, *(v for v in variant_forms(name) if not model.refuses(make_effect(v)))]
            else:  # a form of a term the model carries, tried in its place (_swaps_in)
                cands += [v for v in variant_forms(name) if _swaps_in(model, v, have)]
    else:
        cands = [c for c in candidates if c not in have]
    tested = []
    where = ("the estimation data" if not rolling else
             f"the first training block (the first {train.n_samples} of {data.n_samples} samples)")
    for c in cands:
        # what the effect declares the records must hold (Effect.requires): to be fitted, and under rolling
        # origin, which has no separate validation record to decide, to be told from a wider loop
        reason = untestable_reason(c, data, to=("fit", "test") if rolling else ("fit",))
        if reason is None and train is not data:
            reason = untestable_reason(c, train, to=("fit",), where=where)
        if reason is not None:
            untestable[c] = reason
        else:
            tested.append(c)
    return tested, untestable
