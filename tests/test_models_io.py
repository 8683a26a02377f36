"""Model files: exact round trip, clear errors for wrong version, fields, base or effect."""

import json

import numpy as np
import pytest

from endocal.errors import ModelError
from endocal.models import load_model, make_model, model_from_dict
from tests._models_signals import PAPER_TABLE1, chirp, damped_sine


@pytest.fixture(scope="module")
def model():
    rng = np.random.default_rng(3)
    _, u = damped_sine(dt_s=0.05)
    y = make_model("pi", ["envelope"]).set_parameters(PAPER_TABLE1).predict(u) + 0.3 * rng.standard_normal(u.size)
    return make_model("pi", ["envelope"], axis="ud").fit(u, y)


def test_round_trip_is_exact(model, tmp_path):
    path = tmp_path / "m.json"
    model.save(path)
    m2 = load_model(path)
    _, u = chirp(amp_deg=50.0)
    assert np.max(np.abs(m2.predict(u) - model.predict(u))) <= 1e-12
    assert m2.params_ == model.params_
    assert m2.stderr_ == pytest.approx(model.stderr_)
    assert m2.fit_report_ == model.fit_report_
    assert m2.axis == "ud" and m2.fixed_ == model.fixed_
    assert np.allclose(m2.correlation_, model.correlation_)
    text = path.read_text()
    assert "pickle" not in text and text.lstrip().startswith("{")
    d = json.loads(text)
    assert d["parameters"]["pi_r"]["stderr"] > 0 and d["parameters"]["envelope_k1"]["fixed"] is True
    assert len(d["training_data"][0]["sha256"]) == 64


def test_set_parameters_model_round_trips(tmp_path):
    m = make_model("pi", ["envelope"]).set_parameters(PAPER_TABLE1)
    m.save(tmp_path / "p.json")
    m2 = load_model(tmp_path / "p.json")
    _, u = damped_sine()
    assert np.max(np.abs(m2.predict(u) - m.predict(u))) == 0.0


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d.update(version=2), "unknown model file version 2"),
    (lambda d: d.update(format="something"), "not an endocal model file"),
    (lambda d: d.pop("parameters"), "missing \\['parameters'\\]"),
    (lambda d: d.update(colour="red"), "unknown \\['colour'\\]"),
    (lambda d: d.update(base="lstm"), "unknown base model 'lstm'"),
    (lambda d: d["effects"].append({"name": "magic", "settings": {}}), "unknown effect 'magic'"),
    (lambda d: d["parameters"].pop("pi_r"), "do not match"),
    (lambda d: d["settings"].update(colour=1), "malformed|unexpected keyword"),
])
def test_wrong_files_are_clear_errors(model, mutate, message):
    d = json.loads(json.dumps(model.to_dict()))
    mutate(d)
    with pytest.raises(ModelError, match=message):
        model_from_dict(d)


def test_unreadable_files(tmp_path):
    with pytest.raises(ModelError, match="does not exist"):
        load_model(tmp_path / "nope.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ModelError, match="not valid JSON"):
        load_model(bad)


def test_unfitted_model_cannot_be_saved(tmp_path):
    with pytest.raises(ModelError, match="not fitted"):
        make_model("linear").save(tmp_path / "x.json")
