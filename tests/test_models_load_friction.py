"""`load:friction:COLUMN` (endocal/models/effects/load.py, FrictionLoad): a friction base's holding force scales with
a logged condition. Ground truth on a record simulated with known parameters, the inverse with the logged column,
the refusal by a base without a friction state, the model file, and the Bouc-Wen plant whose friction grows with the
sheath's wrap, where the play form (`load:COLUMN`) cannot fit what this form fits (issue 32)."""

from __future__ import annotations

import numpy as np
import pytest

from endocal.errors import ModelError
from endocal.models import HysteresisData, load_model, make_model, save_model
from tests.test_models_boucwen import BW_TRUTH, NOISE_DEG

COL = "sheath_wrap_deg"
#: the holding force proportional to the wrap, 60..300 deg: 1 + g (x - 180) with g = 1/180
TRUTH = {**BW_TRUTH, f"load_friction_{COL}_gain": 1.0 / 180.0}


def _record(seed: int = 0, noise_deg: float = NOISE_DEG) -> HysteresisData:
    """Three cycles of a 50 deg sine at 0.05 Hz while the wrap swings from 60 to 300 deg at 1/3 of that frequency,
    through `bouc-wen` + `load:friction` with :data:`TRUTH`, plus noise."""
    t = np.arange(0.0, 120.0, 0.02)
    u = 50.0 * np.sin(2 * np.pi * 0.05 * t)
    wrap = 180.0 - 120.0 * np.cos(2 * np.pi * 0.05 / 3.0 * t)
    d = HysteresisData(cmd_deg=u, meas_deg=np.zeros_like(u), t_s=t, extras={COL: wrap})
    m = make_model("bouc-wen", [f"load:friction:{COL}"]).set_parameters(
        {**TRUTH, f"load_friction_{COL}_lo": 60.0, f"load_friction_{COL}_hi": 300.0})
    y = m.predict(u, t_s=t, extras={COL: wrap})
    return HysteresisData(cmd_deg=u, meas_deg=y + noise_deg * np.random.default_rng(seed).standard_normal(u.size),
                          t_s=t, extras={COL: wrap})


@pytest.fixture(scope="module")
def fitted():
    d = _record()
    return d, make_model("bouc-wen", [f"load:friction:{COL}"], axis="ap").fit(d)


def test_the_fit_finds_the_gain_it_was_simulated_with(fitted):
    d, m = fitted
    # the noise floor, +2 % for six parameters fitted on 6000 samples
    assert m.fit_report_.rmse_deg < 1.02 * NOISE_DEG
    for name, value in TRUTH.items():
        # within four standard errors, and the record identifies each (its error under 5 % of the value)
        assert abs(m.params_[name] - value) <= 4 * m.stderr_[name] + 1e-12, (name, m.params_[name], m.stderr_[name])
        assert m.stderr_[name] < 0.05 * max(abs(value), 1.0 if name.startswith("bouc") else 1e-3)
    assert f"load:friction:{COL}[g=" in str(m)


def test_the_play_form_cannot_take_a_holding_force_that_follows_the_wrap(fitted):
    """A play in front of the base adds a second friction, a dead band after each reversal, where the plant holds
    more of the same exponential: on this record it stays well above the noise (1.96x measured 2026-12-07; the friction
    form 1.00x)."""
    d, _ = fitted
    play = make_model("bouc-wen", [f"load:{COL}"], axis="ap").fit(d)
    assert play.fit_report_.rmse_deg > 1.5 * NOISE_DEG


def test_the_inverse_with_the_logged_column_gives_the_command_back(fitted):
    d, m = fitted
    y = m.predict(d.cmd_deg, t_s=d.t_s, extras={COL: d.column(COL)})
    u = m.inverse(y, t_s=d.t_s, extras={COL: d.column(COL)})
    # the bisection's tolerance, far below a servo's resolution (0.088 deg)
    assert np.max(np.abs(u - d.cmd_deg)) < 1e-6


def test_the_model_file_keeps_the_form(fitted, tmp_path):
    d, m = fitted
    path = tmp_path / "m.json"
    save_model(m, path)
    again = load_model(path)
    assert [e.label for e in again.effects_] == [f"load:friction:{COL}"]
    assert np.allclose(again.predict(d.cmd_deg, t_s=d.t_s, extras={COL: d.column(COL)}),
                       m.predict(d.cmd_deg, t_s=d.t_s, extras={COL: d.column(COL)}), atol=1e-12)


@pytest.mark.parametrize("base", ["pi", "bspline", "linear"])
def test_a_base_without_a_friction_state_refuses_it_in_one_line(base):
    with pytest.raises(ModelError) as exc:
        make_model(base, [f"load:friction:{COL}"]).fit(_record())
    msg = str(exc.value)
    assert "\n" not in msg and f"load:friction:{COL}" in msg and f"'load:{COL}'" in msg and "bouc-wen" in msg


def test_validate_tries_the_friction_form_in_place_of_the_play_and_prints_the_swap():
    """A model changed to a friction base may hold the play its first base forced (a B-spline cannot carry the friction
    form): validate tries the friction form in its place, names the swap, and its printed refit makes it."""
    from endocal.validation.offline import validate_offline
    from endocal.views import validation_summary

    train, val = _record(seed=0), _record(seed=1)
    model = make_model("bouc-wen", [f"load:{COL}"], axis="ap").fit(train)
    res = validate_offline(model, val, train=train, model_path="m.json", max_scan_samples=3000)
    top = res.suspects[0]
    assert top.effect == f"load:friction:{COL}" and top.significant, [(s.effect, s.gain_pct) for s in res.scan.tested]
    # the play leaves 2x the noise (test above); the friction form takes the rest: -40 % or more
    assert top.gain_pct > 40.0
    assert top.refit.effects == (f"load:friction:{COL}",)
    line = next(x for x in validation_summary(res) if x.startswith("missing"))
    assert f"load:friction:{COL} (in place of load:{COL})" in line, line
