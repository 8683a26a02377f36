"""Every hidden effect recorded the way a user records (issue 12, "simulated, less shaped").

Unlike tests/test_validation_hidden.py, nothing is picked per case: the default simulated
probe with its servo and tracker lag, one seed, estimation on the duodenoscope paper's damped
sine plus a chirp, validation on a band-limited random run, and the thesis's model, a
B-spline, carrying `delay` as a user of this rig does for its known lag (without the hidden
delay case, where the delay is what is hidden). The estimation/validation scheme must name the
hidden effect first, and the refit with it must cut the validation RMSE by at least 50 %.

Where that fails, the case is a strict xfail with the reason measured: a fix shows up as an
unexpected pass. The gaps are physics the data cannot show, not tuning:
- `envelope`: the B-spline's free branch shapes already take up a static stiffening, so the
  model is not missing it (validation RMSE 0.336 deg against a 0.329 deg noise floor);
- `coupling`: the damped sine, the chirp and the random run move one knob; the other bend
  never changes, so nothing couples (0.340 deg against 0.333 deg);
- `rate` at the simulator's default gain: the random run's knob speeds leave the friction
  growth small (0.41 deg against 0.33 deg): at most -20 % is there to be found;
- `load`: named first, but the refit cuts -46 %: the wrap's load acts through the sheath's
  friction, the catalog term adds it at the output.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from endocal.models import make_model
from endocal.sim import SimConfig
from endocal.validation.data import axis_data
from endocal.validation.offline import validate_offline
from tests.test_validation_hidden import NO_SLACK, simulate

HIDDEN = {
    "drift": {"drift": {"enabled": True, "rate_deg_per_min": [3.0, -1.0]}},
    "delay": {"delay": {"enabled": True}},
    "rate": {"rate": {"enabled": True}},
    "creep": {"creep": {"enabled": True}},
    "load": {"load": {"enabled": True, "amplitude_deg": 150.0}},
    "deadzone": {"deadzone": {"enabled": True}},
    "envelope": {"envelope": {"enabled": True}},
    "coupling": {"coupling": {"enabled": True}},
}
NAME_GAPS = {
    "envelope": "the B-spline already takes up a static stiffening: nothing is missing on this data",
    "coupling": "single-knob protocols: the other bend never changes, so coupling cannot show",
    "rate": "at the default friction gain the random run's speeds leave < 20 % to find (below the 10 % gain bar "
            "after noise)",
}
CUT_GAPS = {**NAME_GAPS, "load": "the catalog's load term acts at the output, the simulator's through the sheath: -46 %"}
SCAN_SAMPLES = 3000  # validate's decimation budget for the candidates' fits, as in test_validation_hidden


@functools.lru_cache(maxsize=None)
def _case(hidden: str):
    cfg = SimConfig.default().replace(**NO_SLACK).replace(**HIDDEN[hidden])
    est = [simulate(cfg, "damped-sine", {}, seed=0)[0], simulate(cfg, "chirp", {"amplitude_deg": 50.0}, seed=0)[0]]
    val, noise = simulate(cfg, "random", {"amplitude_deg": 60.0}, seed=0)
    effects = [] if hidden == "delay" else ["delay"]
    train = axis_data(est, "ap")
    model = make_model("bspline", effects, axis="ap").fit(train)
    res = validate_offline(model, [val], train=est, model_path="m.json", max_scan_samples=SCAN_SAMPLES)
    return res, train, val, effects, noise


def _params(gaps):
    return [pytest.param(h, marks=pytest.mark.xfail(strict=True, reason=gaps[h])) if h in gaps else h for h in HIDDEN]


@pytest.mark.parametrize("hidden", _params(NAME_GAPS))
def test_the_hidden_effect_is_named_first(hidden):
    res = _case(hidden)[0]
    assert res.scan.scheme == "estimation/validation"
    first = res.scan.suspects[0].effect.split(":")[0] if res.scan.suspects else None
    assert first == hidden, [(s.effect, round(s.gain_pct, 1)) for s in res.scan.tested]


@pytest.mark.parametrize("hidden", _params(CUT_GAPS))
def test_the_refit_halves_the_validation_error(hidden):
    res, train, val, effects, noise = _case(hidden)
    assert res.scan.suspects, "nothing named"
    refit = make_model("bspline", effects + [res.scan.suspects[0].effect], axis="ap").fit(train)
    v = axis_data([val], "ap")
    after = float(np.sqrt(np.mean((refit.predict(v) - v.meas_deg) ** 2)))
    before = res.scan.baseline_rmse_heldout_deg
    assert after <= 0.5 * before, (before, after, noise)
