"""An additive term earns its gain itself (endocal/validation/scan.py, ``_without_own_share``).

A `drift` fitted on a long estimation record whose zero crept can move the base's zero there and so
lower the error of a short validation record on which the drift itself does nothing but harm: the
closed loop's false discoveries (docs/evidence/hidden-effects.md). The scan scores the same fitted
candidate with its term taken out; a gain the term does not earn itself is not suggested, and a
note says why. A drift present in every record keeps its suggestion.
"""

from __future__ import annotations

import numpy as np
import pytest

from endocal.models import HysteresisData, make_model
from endocal.validation.scan import scan_split
from tests._models_signals import PAPER_TABLE1

NOISE_DEG = 0.3
#: The zero's creep (deg/s): 3 deg over the 300 s record, ten times the noise.
CREEP_DPS = 0.01


def _records(drift_everywhere: bool):
    """Estimation: a long sweep whose zero creeps and a short one; validation: a short mixture of sines (10 Hz).
    ``drift_everywhere``: the short records creep at the same rate too (a drift of the plant)."""
    plant = make_model("pi", ["envelope"]).set_parameters(PAPER_TABLE1)
    rng = np.random.default_rng(5)

    def rec(t, u, creeps):
        y = plant.predict(HysteresisData(cmd_deg=u, t_s=t)) + NOISE_DEG * rng.standard_normal(u.size)
        return HysteresisData(cmd_deg=u, meas_deg=y + (CREEP_DPS * t if creeps else 0.0), t_s=t)

    t_long, t_short = np.arange(0.0, 300.0, 0.1), np.arange(0.0, 90.0, 0.1)
    long = rec(t_long, 50 * np.sin(2 * np.pi * 0.05 * t_long), True)
    short = rec(t_short, 45 * np.sin(2 * np.pi * 0.08 * t_short), drift_everywhere)
    val = rec(t_short, 30 * np.sin(2 * np.pi * 0.03 * t_short) + 20 * np.sin(2 * np.pi * 0.11 * t_short + 1),
              drift_everywhere)
    return HysteresisData.from_runs([long, short]), val


@pytest.fixture(scope="module")
def one_record_crept():
    train, val = _records(drift_everywhere=False)
    return scan_split(make_model("pi", ["envelope"]).fit(train), train, val, candidates=["drift"], jobs=1)


def test_a_drift_of_one_estimation_record_is_not_suggested(one_record_crept):
    res = one_record_crept
    drift = next(s for s in res.tested if s.effect == "drift")
    # the base's zero, no longer pulled by the long record's creep, lowers the short record's error...
    assert drift.gain_pct >= 10.0, drift
    # ...but the drift term itself only harms it: not a suspect, not a suggestion, and a note says so
    assert not drift.significant and "drift" not in [s.effect for s in res.suspects]
    note = next(n for n in res.notes if n.key == "borrowed")
    assert note.startswith("drift: ") and "not suggested" in note


def test_a_drift_of_every_record_is_suggested():
    train, val = _records(drift_everywhere=True)
    res = scan_split(make_model("pi", ["envelope"]).fit(train), train, val, candidates=["drift"], jobs=1)
    assert [s.effect for s in res.suspects] == ["drift"] and res.suspects[0].significant
    assert not [n for n in res.notes if n.key == "borrowed"]

