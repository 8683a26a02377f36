"""A model's structure (base, settings, effects), refitted on other data.

The effect scan and the report's ladder refit the structure of the model under validation,
with or without a candidate effect, on estimation data or on a rolling-origin training
block; :func:`template` makes that fresh model, :func:`split_fit` fits it starting from the
model's own values, :func:`fitted_on` says when no refit is needed at all.
"""

from __future__ import annotations

from collections.abc import Sequence

from endocal.models import HysteresisData, make_model
from endocal.models.base import HysteresisModel
from endocal.models.effects import plain_form

#: The stopping rule of the fits validation makes on a subsample of the estimation data (candidates,
#: bases, expected ranges: :func:`scan_ftol`) and on rolling-origin folds: stop when a step lowers the
#: cost by less than 1e-4 of itself. The scan decides at 10 % of the RMSE; the model's own fit keeps
#: models.base.FTOL (1e-7). On the demo's records (scripts/demo.sh, pi + envelope, 7 candidates) the
#: candidates ended within 0.42 % of their training RMSE at FTOL and within 1.5 % of its validation RMSE,
#: in 7 to 39 evaluations where FTOL takes 78 to 584: they crawl along shallow valleys (eq. 8's beta) for
#: hundreds of steps that each lower the cost by under 1e-4 (tests/test_validation_quick_fit.py holds
#: them within 1 % and 2 % on the README's records; bench/bench_loop.py).
#: Their start candidates are screened as ``fit`` screens them (on 4 000 samples): screened on 2 000
#: (16.7 Hz instead of 33 Hz on the README's records), a 0.05 s `delay` fell into another basin, -29 %
#: where it gains -34 %, to save 0.35 s.
SCAN_FTOL = 1e-4


def scan_ftol(stride: int) -> float | None:
    """The stopping rule of a scan's fits on 1 estimation sample in ``stride``: :data:`SCAN_FTOL` where it
    subsamples (the printed refit, on every sample, then comes with the range to expect), else None, the
    fit's own: on every sample the printed refit is the very fit the scan scored (to 1e-6)."""
    return SCAN_FTOL if stride > 1 else None


def resolved_settings(model: HysteresisModel) -> dict:
    """``model``'s base settings with every ``"auto"`` replaced by what its fit resolved it to
    (``structure_``): a PI model's ``weights="auto"`` fitted as ``exponential`` stays exponential.

    Refitting ``"auto"`` would resolve it afresh, on other data or with another effect in the
    chain, and may pick another structure than the one scored: a `pi` + `envelope` model of a
    tendon log kept ``exponential`` in the scan and went ``free`` (21 weights) in the printed
    refit, which then delivered -8 % where the scan promised -45 % (issue 33). The scan's
    candidates and the refit it prints both take these settings.
    """
    structure = getattr(model, "structure_", None) or {}
    return {k: (structure[k] if v == "auto" and k in structure else v) for k, v in model.get_settings().items()}


def template(model: HysteresisModel, effects: Sequence[str]) -> HysteresisModel:
    """An unfitted ``base + effects`` with ``model``'s base, resolved settings (:func:`resolved_settings`),
    fixed parameters and axis, continued beyond its fitted range (a held-out block may command beyond
    a training block's)."""
    return make_model(model.base_name, list(effects), **resolved_settings(model), fixed=model.fixed, axis=model.axis,
                      out_of_range="extrapolate")


def effect_labels(model: HysteresisModel) -> list[str]:
    """The model's effects as ``--effects`` writes them."""
    effects = model.effects_ if hasattr(model, "effects_") else model._effects()
    return [e.label for e in effects]


def with_candidate(labels: Sequence[str], candidate: str) -> list[str]:
    """The effects ``labels`` with ``candidate``: in place of the effect it is another form of
    (:func:`~endocal.models.effects.plain_form`) where ``labels`` hold that one, else added (a form swap:
    ``load:friction:sheath_wrap_deg`` for ``load:sheath_wrap_deg`` once the base has a friction state)."""
    plain = plain_form(candidate)
    if plain is not None and plain in labels:
        return [candidate if lab == plain else lab for lab in labels]
    return [*labels, candidate]


def changed_settings(model: HysteresisModel) -> dict:
    """The resolved base settings of ``model`` (:func:`resolved_settings`) that differ from their
    defaults (``n_knots``, ``n_operators``, ``weights``...), so a refit keeps the model's structure."""
    import inspect

    sig = inspect.signature(type(model).__init__)
    out = {}
    for k, v in resolved_settings(model).items():
        default = sig.parameters[k].default
        if default is not inspect.Parameter.empty and v != default:
            out[k] = v
    return out


def fitted_on(model: HysteresisModel, data: HysteresisData) -> bool:
    """Whether ``model`` was fitted on exactly ``data`` (the per-run fingerprints its fit recorded).

    Then the model *is* its structure fitted on that estimation data: scoring it as it stands
    is what a refit would do, minus the chance of the refit stopping in another local minimum
    (a B-spline + delay refitted from its own values once ended 68 % worse on the validation
    record than the file it came from).
    """
    recorded = getattr(model, "training_data_", None) or []
    return bool(recorded) and [r.get("sha256") for r in recorded] == [f["sha256"] for f in data.fingerprint()]


def split_fit(model: HysteresisModel, effects: Sequence[str], train: HysteresisData, stride: int = 1,
              ftol: float | None = None) -> HysteresisModel:
    """``base + effects`` (with ``model``'s settings) fitted on ``train``, every ``stride``-th sample.

    The effects ``model`` already has start from its fitted values (it was fitted on this
    estimation data), so only a new effect searches its start candidates. ``ftol``: the fit's stopping
    rule (:func:`scan_ftol`; None: the fit's own).
    """
    dt = train.decimate(stride) if stride > 1 else train
    return template(model, effects).fit_from(model, dt, ftol=ftol)
