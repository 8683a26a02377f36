"""The effect contract (issue 31): every registered effect declares what the library knows about it.

The test walks :data:`endocal.models.EFFECTS` at the time it runs (built-ins, and any effect
registered later: a user's file, an entry point) and fails naming what an effect does not
declare; a deliberately incomplete class gets its named messages.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import pytest

from endocal.models import EFFECTS
from endocal.models.effects import InputEffect
from endocal.models.effects.contract import missing_declarations, sample_data
from endocal.models.effects.requirements import TIME_STAMPS, Requirement, condition_varies_within
from endocal.models.params import Parameter
from endocal.sim import EFFECTS as SIMULATED
from endocal.validation.identifiability import untestable_reason


@pytest.mark.parametrize("name", list(EFFECTS))
def test_every_registered_effect_declares_the_contract(name):
    missing = missing_declarations(EFFECTS[name])
    assert not missing, f"effect '{name}' does not declare: " + "; ".join(missing)


@pytest.mark.parametrize("name", list(EFFECTS))
def test_lookalikes_name_registered_effects_both_ways(name):
    for other in EFFECTS[name].lookalikes:
        assert other in EFFECTS, f"effect '{name}' names an unknown look-alike '{other}'"
        assert name in EFFECTS[other].lookalikes, f"'{other}' does not name '{name}' back as its look-alike"


def test_the_simulator_and_the_catalogue_agree():
    # the simulator's effects are asked of the catalogue: each names a section that exists
    assert set(SIMULATED) == {c.sim_section for c in EFFECTS.values() if c.sim_section}
    assert set(SIMULATED) <= set(EFFECTS)


class _Incomplete(InputEffect):
    """A user's first try: a name and an equation, nothing of what validation needs."""

    name = "stickslip"
    units: ClassVar[dict] = {"jump_deg": "deg", "free": "deg"}

    def initial(self, data, u):
        return [Parameter("stickslip_jump_deg", 0.1, 0.0, 5.0), Parameter("stickslip_free", 0.0)]

    def apply(self, p, u, data):
        return u + p["jump_deg"]

    def invert(self, p, v, data):
        return v - p["jump_deg"]

    def describe(self, p, se):
        return "stickslip" + self._bracket(p, se)


def test_an_incomplete_class_is_named_item_by_item():
    missing = missing_declarations(_Incomplete, run=False)
    for attr in ("cause", "signature", "protocol", "requires", "residual", "lookalikes"):
        assert any(m.startswith(f"no '{attr}'") for m in missing), (attr, missing)
    assert not any("'name'" in m or "'units'" in m for m in missing), missing


def test_parameters_without_bounds_and_a_broken_inverse_are_named():
    class Declared(_Incomplete):
        cause = "stick-slip at every reversal"
        signature = "a jump after each reversal"
        protocol = "slow triangles"
        requires = (TIME_STAMPS,)
        residual = ("speed",)
        lookalikes: ClassVar[dict] = {}

    assert missing_declarations(Declared) == ["parameters without bounds: free (give finite bounds, or list them "
                                              "in open_bounds)"]

    class Open(Declared):
        open_bounds = ("free",)

        def invert(self, p, v, data):
            return v  # forgets the shift: apply(invert(y)) misses y by the jump

    assert missing_declarations(Open) == ["its inverse does not invert: apply(invert(y)) misses y by up to 0.1 deg "
                                          "on a sweep"]

    class NaN(Open):
        def apply(self, p, u, data):
            return np.full(u.size, np.nan)

    assert missing_declarations(NaN) == ["its predict returns NaN or inf on a sample record"]


def test_a_null_that_is_not_an_additive_terms_own_parameters_is_named():
    class Declared(_Incomplete):
        cause, signature, protocol = "stick-slip at every reversal", "a jump after each reversal", "slow triangles"
        requires, residual, open_bounds = (TIME_STAMPS,), ("speed",), ("free",)
        lookalikes: ClassVar[dict] = {}
        null: ClassVar[dict] = {"jump_deg": 0.0}  # an input effect: validate could not take it out

    assert missing_declarations(Declared, run=False) == [
        "'null' ({'jump_deg': 0.0}) must map short parameter names of 'units' to finite numbers, on an additive "
        "term (OutputEffect) only: the values at which the term adds nothing"]


def test_a_variant_is_checked_as_the_effect_itself_is():
    class Declared(_Incomplete):
        cause, signature, protocol = "stick-slip at every reversal", "a jump after each reversal", "slow triangles"
        requires, residual, open_bounds = (TIME_STAMPS,), ("speed",), ("free",)
        lookalikes: ClassVar[dict] = {}
        variants = ("slip:double",)  # not this effect's name

    assert missing_declarations(Declared, run=False) == [
        "'variants' (('slip:double',)) must be a tuple of forms written 'stickslip:ARG', which from_argument(ARG) makes"]

    class Doubled(Declared):
        variants = ("stickslip:double",)
        times = 1

        @classmethod
        def from_argument(cls, arg):
            inst = cls()
            inst.times = 2
            return inst

        def apply(self, p, u, data):
            return u + self.times * p["jump_deg"]

        def invert(self, p, v, data):
            return v - p["jump_deg"]  # right for the effect, one jump short for its variant

    assert missing_declarations(Doubled) == ["variant 'stickslip:double': its inverse does not invert: apply(invert(y)) "
                                             "misses y by up to 0.1 deg on a sweep"]


def test_a_requirement_of_ones_own_says_why_in_words():
    def reversals(d):
        return bool(np.any(np.diff(np.sign(np.diff(d.cmd_deg))) != 0))

    req = Requirement("reversals", "a reversal of the knob", reversals, remedy="run `sine`")
    d = sample_data()
    assert req.reason(d, name="stickslip") is None
    ramp = d.with_cmd(np.linspace(0.0, 30.0, d.n_samples))
    assert req.reason(ramp, name="stickslip") == ("the records lack a reversal of the knob: stickslip cannot be "
                                                  "identified (run `sine`)")
    with pytest.raises(ValueError, match="to must be one of"):
        Requirement("x", "x", reversals, to="always")


def test_built_in_requirements_keep_their_words():
    d = sample_data()
    no_time = type(d)(cmd_deg=d.cmd_deg, meas_deg=d.meas_deg)
    assert untestable_reason("delay", no_time) == "no time stamps: delay cannot be identified"
    assert untestable_reason("drift", d) is None and untestable_reason("coupling", d) is None
    one_axis = type(d)(cmd_deg=d.cmd_deg, meas_deg=d.meas_deg, t_s=d.t_s, run_starts=d.run_starts)
    assert untestable_reason("coupling", one_axis).startswith("one axis only: coupling cannot be identified")


def test_a_condition_constant_within_each_record_is_confounded_unless_the_motion_repeats():
    """Issue 32.1: a condition that changes only between records separates nothing by itself."""
    t = np.arange(2000) / 100.0
    sine, chirp = 30 * np.sin(2 * np.pi * 0.2 * t), 30 * np.sin(2 * np.pi * (0.1 + 0.01 * t) * t)
    cond = [np.full(t.size, v) for v in (180.0, 120.0)]

    def records(a, b):
        from endocal.models import HysteresisData

        runs = [HysteresisData(cmd_deg=u, meas_deg=u, t_s=t, extras={"wrap_deg": c}) for u, c in ((a, cond[0]),
                                                                                                  (b, cond[1]))]
        return HysteresisData.from_runs(runs)

    why = condition_varies_within(records(sine, chirp), "wrap_deg")
    assert why.startswith("'wrap_deg' is constant within each record and the records at its 2 values differ in "
                          "their motion")
    assert untestable_reason("load:wrap_deg", records(sine, chirp)).endswith(
        "load cannot be identified (log the condition as a column, and record the same motion at two of its values, "
        "or change it during a run)")
    assert condition_varies_within(records(sine, sine), "wrap_deg") is None  # the same motion at two values
    assert untestable_reason("load:wrap_deg", records(sine, sine)) is None
