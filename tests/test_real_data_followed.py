"""Issue 27, "How good", real data: a followed suggestion never makes the validation RMSE worse by more than 5 %
(issue 32: a suggested base change neither).

On the real piezo recording (`data_samples/piezo`, 20 cycles at 1 Hz), as a lab would use it: one cycle
to fit on, another to validate on. For a deterministic spread of pairs (every 3rd cycle as estimation
data, each against the cycles 5 and 11 later, around the recording) and two base models (alternating, so
each estimation cycle is fitted once and the test stays near half a minute), validate; when it suggests
an effect, the user refits with it (on the estimation cycle, from the model, as the printed command does)
and the refit's RMSE on the validation cycle must be at most 1.05 times the model's.

Why 5 %: the issue's bar. The refit is the fit the scan scored, so its error is the suggestion's
held-out number; a suggestion worse than the model there would be a scan that lists a candidate whose
gain is negative, which the gain bar (10 %) forbids. The bar is checked on the refit as made, not on
the scan's number, so a refit that ended elsewhere would show.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.test_real_data import PIEZO, _cycle

#: (base model, estimation cycle, validation cycle): bases alternate over every 3rd cycle of the recording
PAIRS = [(base, est, (est + lag) % 20) for est, base in zip(range(0, 20, 3), ["linear", "pi"] * 4)
         for lag in (5, 11)]
#: Worst the followed suggestion may make the validation RMSE (issue 27: "never worse by more than 5 %")
BAR = 1.05
#: Pairs whose bar fails on this recording, with the numbers (found, not picked: see the module docstring)
KNOWN = {}


@pytest.fixture(scope="module")
def piezo():
    from endocal.runs.aligned import load_aligned

    return load_aligned(PIEZO)


def _case(base, est, val_k):
    marks = [pytest.mark.xfail(strict=True, raises=AssertionError, reason=KNOWN[(base, est, val_k)])] \
        if (base, est, val_k) in KNOWN else []
    return pytest.param(base, est, val_k, id=f"{base}-fit{est}-val{val_k}", marks=marks)


@pytest.mark.parametrize("base,est,val_k", [_case(*p) for p in PAIRS])
def test_a_followed_suggestion_never_makes_the_validation_rmse_worse_by_more_than_5_pct(piezo, base, est, val_k):
    from endocal.models import make_model
    from endocal.validation.data import axis_data
    from endocal.validation.offline import validate_offline
    from endocal.validation.predict import predict_extrapolated
    from endocal.validation.structure import template

    train = [_cycle(piezo, est)]
    fit_data = axis_data(train, "piezo")
    model = make_model(base, axis="piezo").fit(fit_data)
    val = _cycle(piezo, val_k)
    res = validate_offline(model, [val], train=train, model_path="m.json", n_boot=50)
    assert res.scan.scheme == "estimation/validation"
    v = axis_data([val], "piezo")
    before = res.metrics.rmse_deg
    for change in res.scan.base_suggestions[:1]:  # issue 32: another base suggested, refitted as printed (--model)
        assert change.refit.base == change.base and change.refit.effects == tuple(e.label for e in model.effects_)
        refit = make_model(change.base, list(change.refit.effects), axis="piezo").fit(fit_data)
        after = float(np.sqrt(np.mean((predict_extrapolated(refit, v)[0] - v.meas_deg) ** 2)))
        assert after <= BAR * before, (base, est, val_k, change.base, before, after)
    if not res.suspects:  # nothing to follow: the loop stops here, and the model stands
        return
    first = res.suspects[0]
    assert first.refit.base == base and first.refit.effects[-1] == first.effect
    refit = template(model, list(first.refit.effects)).fit_from(model, fit_data)  # the printed refit command
    after = float(np.sqrt(np.mean((predict_extrapolated(refit, v)[0] - v.meas_deg) ** 2)))  # as validate scores
    assert after <= BAR * before, (base, est, val_k, first.effect, before, after)
