"""`envelope:tip` (endocal/models/effects/envelope.py, TipEnvelope): the bending section's shape on the bend, past a
friction element without return-point memory. Ground truth on a record simulated with known parameters, the
difference from the shape on the command, the inverse, the model file and the refusal by a base with return-point
memory."""

from __future__ import annotations

import numpy as np
import pytest

from endocal.errors import ModelError
from endocal.models import HysteresisData, load_model, make_model, save_model
from tests.test_models_boucwen import BW_TRUTH, NOISE_DEG

#: a dead band of +-8 deg of bend (slope 1/3) and stiffening beyond it, on the Bouc-Wen truth's output (about +-40 deg)
SHAPE = {"envelope_tip_theta0_deg": -8.0, "envelope_tip_theta2_deg": 8.0, "envelope_tip_k0": 3.0, "envelope_tip_k2": 3.0}
GAUGE = {"envelope_tip_k1": 1.0, "envelope_tip_theta1_deg": 0.0}
TRUTH = {**BW_TRUTH, **SHAPE}


def _record(seed: int = 0) -> HysteresisData:
    """A decaying sine of 50 deg at 0.05 Hz, 60 s at 50 Hz, through `bouc-wen` + `envelope:tip`, plus 0.3 deg noise."""
    t = np.arange(0.0, 60.0, 0.02)
    u = 50.0 * np.sin(2 * np.pi * 0.05 * t) * (1.0 - t / 120.0)
    y = make_model("bouc-wen", ["envelope:tip"]).set_parameters({**TRUTH, **GAUGE}).predict(u)
    return HysteresisData(cmd_deg=u, meas_deg=y + NOISE_DEG * np.random.default_rng(seed).standard_normal(u.size), t_s=t)


@pytest.fixture(scope="module")
def fitted():
    d = _record()
    return d, make_model("bouc-wen", ["envelope:tip"], axis="ap").fit(d)


def test_the_fit_finds_the_shape_it_was_simulated_with(fitted):
    d, m = fitted
    # the noise floor, +2 % for nine parameters fitted on 3000 samples
    assert m.fit_report_.rmse_deg < 1.02 * NOISE_DEG
    for name, value in TRUTH.items():
        assert abs(m.params_[name] - value) <= 4 * m.stderr_[name] + 1e-9, (name, m.params_[name], m.stderr_[name])
    # the base's affine gauge holds the shape's middle slope and zero
    assert all(m.params_[k] == v for k, v in GAUGE.items())
    assert "ftip = envelope:tip[" in str(m)


def test_the_shape_on_the_command_cannot_take_the_shape_on_the_bend(fitted):
    """In front of the friction element the shape stretches the element's exponential with the stiffening: the
    same record stays well above the noise (8.0x measured 2026-12-07; the tip form 0.99x)."""
    d, _ = fitted
    front = make_model("bouc-wen", ["envelope"], axis="ap").fit(d)
    assert front.fit_report_.rmse_deg > 1.2 * NOISE_DEG


def test_the_inverses_give_the_command_back_and_the_file_keeps_the_form(fitted, tmp_path):
    d, m = fitted
    y = m.predict(d.cmd_deg)
    # the bisection's tolerance, far below a servo's resolution (0.088 deg)
    assert np.max(np.abs(m.inverse(y) - d.cmd_deg)) < 1e-6
    # the shape holds no state: the streaming compensator gives the batch inverse's commands
    comp = m.compensator()
    assert np.max(np.abs(np.array([comp.step(v) for v in y]) - d.cmd_deg)) < 1e-6
    save_model(m, tmp_path / "m.json")
    again = load_model(tmp_path / "m.json")
    assert [e.label for e in again.effects_] == ["envelope:tip"]
    assert np.allclose(again.predict(d.cmd_deg), y, atol=1e-12)


@pytest.mark.parametrize("base", ["pi", "bspline", "linear"])
def test_a_base_with_return_point_memory_refuses_it_in_one_line(base):
    with pytest.raises(ModelError) as exc:
        make_model(base, ["envelope:tip"]).fit(_record())
    msg = str(exc.value)
    assert "\n" not in msg and "envelope:tip" in msg and "'envelope'" in msg and "bouc-wen" in msg


def test_the_c_export_names_the_base_it_cannot_generate_before_any_effect(fitted):
    """A friction base has no C generator: that is the one line, not the effect (leaving it out would not help)."""
    from endocal.export.c import generate_c

    with pytest.raises(ModelError) as exc:
        generate_c(fitted[1])
    assert str(exc.value).startswith("the 'bouc-wen' base has no C code generator"), str(exc.value)


def test_a_model_file_with_an_unknown_form_is_refused_naming_the_file_and_the_effect(fitted, tmp_path):
    import json

    path = tmp_path / "m.json"
    save_model(fitted[1], path)
    d = json.loads(path.read_text())
    d["effects"][0]["settings"]["form"] = "top"
    path.write_text(json.dumps(d))
    with pytest.raises(ModelError) as exc:
        load_model(path)
    msg = str(exc.value)
    assert "\n" not in msg and "m.json" in msg and "effect 'envelope': unknown form 'top'" in msg and "'tip'" in msg
