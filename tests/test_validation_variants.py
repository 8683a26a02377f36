"""An effect's other forms (``Effect.variants``: ``deadzone:tip``, ``rate:friction``) in `validate`'s scan: tried as
candidates of their own where the base can carry them, and suggested before the plain form only where the records
prefer them."""

from __future__ import annotations

import numpy as np
import pytest

from endocal.errors import ModelError
from endocal.models import make_model
from endocal.models.effects import EFFECTS, make_effect
from endocal.validation.ambiguity import plain_first
from endocal.validation.candidates import candidate_effects
from endocal.validation.suspects import Suspect
from tests.test_models_boucwen import _speed_record


def test_an_effects_other_form_ranks_after_its_plain_form_unless_the_records_prefer_it():
    """`deadzone:tip` before `deadzone` by a gain the paired test cannot tell from chance: the plain form goes
    first. Where the records prefer the variant (every block's error lower), it stays first."""
    rng = np.random.default_rng(0)
    base = rng.standard_normal(4000)

    def suspect(effect, err):
        rmse = float(np.sqrt(np.mean(err**2)))
        return Suspect(effect=effect, column=None, gain_pct=100 * (1 - rmse / 2.0), p_value=0.001, p_raw=0.001,
                       rmse_heldout_deg=rmse, base_rmse_heldout_deg=2.0, significant=True, refit=None, cause="",
                       signature="", protocol="", n_blocks=40)

    plain = base.copy()
    alike = base + 0.01 * rng.standard_normal(base.size)  # the same residual, as good by chance
    errs = {"deadzone": plain, "deadzone:tip": alike * 0.99}
    order = plain_first([suspect("deadzone:tip", errs["deadzone:tip"]), suspect("deadzone", plain)], errs, 0.05)
    assert [s.effect for s in order] == ["deadzone", "deadzone:tip"]
    errs["deadzone:tip"] = 0.7 * base  # lower in every block: the records prefer it
    order = plain_first([suspect("deadzone:tip", errs["deadzone:tip"]), suspect("deadzone", plain)], errs, 0.05)
    assert [s.effect for s in order] == ["deadzone:tip", "deadzone"]


def test_every_variant_is_a_candidate_where_the_base_can_carry_it():
    d = _speed_record().decimate(4)
    for base in ("pi", "dahl"):
        model = make_model(base, axis="ap").fit(d)
        tested, _ = candidate_effects(model, d, None, None, [], train=d, rolling=False)
        wanted = {v for cls in EFFECTS.values() for v in cls.variants if not model.refuses(make_effect(v))}
        assert wanted <= set(tested), (base, tested)
        assert ("rate:friction" in tested) is (base == "dahl")


def test_a_form_no_effect_has_is_refused_naming_the_forms_it_has():
    assert make_effect("deadzone:tip").label == "deadzone:tip" and make_effect("rate:friction").prefix == "rate_friction"
    with pytest.raises(ModelError, match=r"^effect 'deadzone:foo': write deadzone \(.*\) or deadzone:tip \("):
        make_effect("deadzone:foo")
    with pytest.raises(ModelError, match=r"^effect 'rate:fast': write rate \(.*\) or rate:friction \("):
        make_effect("rate:fast")
