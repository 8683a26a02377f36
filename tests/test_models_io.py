"""Model files: exact round trip, clear errors for wrong version, fields, base or effect."""

import json
from pathlib import Path

import numpy as np
import pytest

from endocal.errors import ModelError
from endocal.models import load_model, make_model, model_from_dict, model_to_dict, save_model
from tests._models_signals import PAPER_TABLE1, chirp, damped_sine


@pytest.fixture(scope="module")
def model():
    rng = np.random.default_rng(3)
    _, u = damped_sine(dt_s=0.05)
    y = make_model("pi", ["envelope"]).set_parameters(PAPER_TABLE1).predict(u) + 0.3 * rng.standard_normal(u.size)
    return make_model("pi", ["envelope"], axis="ud").fit(u, y)


def test_round_trip_is_exact(model, tmp_path):
    path = tmp_path / "m.json"
    save_model(model, path)
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
    save_model(m, tmp_path / "p.json")
    m2 = load_model(tmp_path / "p.json")
    _, u = damped_sine()
    assert np.max(np.abs(m2.predict(u) - m.predict(u))) == 0.0


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d.update(version=3), "unknown model file version 3"),
    (lambda d: d.update(format="something"), "not an endocal model file"),
    (lambda d: d.pop("parameters"), "missing \\['parameters'\\]"),
    (lambda d: d.update(colour="red"), "unknown \\['colour'\\]"),
    (lambda d: d.update(base="lstm"), "unknown base model 'lstm'"),
    (lambda d: d["effects"].append({"name": "magic", "settings": {}}), "unknown effect 'magic'"),
    (lambda d: d["parameters"].pop("pi_r"), "do not match"),
    (lambda d: d["settings"].update(colour=1), "malformed|unexpected keyword"),
])
def test_wrong_files_are_clear_errors(model, mutate, message):
    d = json.loads(json.dumps(model_to_dict(model)))
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
        save_model(make_model("linear"), tmp_path / "x.json")


FIXTURES = Path(__file__).parent / "fixtures"


def test_version_1_bspline_files_load_as_first_coefficient_and_increments(tmp_path):
    # Saved by endocal before file version 2: coefficients bspline_up_c0..c7, the up branch
    # falling at its low end (c0 > c1) where few samples lie on it.
    old = json.loads((FIXTURES / "bspline_v1.json").read_text())
    m = load_model(FIXTURES / "bspline_v1.json")
    p = {k.removeprefix("bspline_"): v for k, v in m.params_.items()}
    up, down = m._coefs(m.structure_, p)
    c = {n: e["value"] for n, e in old["parameters"].items()}
    assert np.allclose(up, [c[f"bspline_up_c{i}"] for i in range(8)], rtol=0, atol=1e-12)
    assert np.allclose(down, [c[f"bspline_down_c{i}"] for i in range(8)], rtol=0, atol=1e-12)
    assert p["up_dc1"] < 0  # the falling stretch is kept: the file predicts as before
    # the increment's standard error from the version-1 covariance: var(c1 - c0)
    names = old["correlation"]["names"]
    r = np.array(old["correlation"]["matrix"], dtype=float)[names.index("bspline_up_c1"), names.index("bspline_up_c0")]
    s0, s1 = (old["parameters"][f"bspline_up_c{i}"]["stderr"] for i in (0, 1))
    assert m.stderr_["bspline_up_dc1"] == pytest.approx(np.sqrt(s0**2 + s1**2 - 2 * r * s0 * s1), rel=1e-9)
    # saved again it is a version-2 file that predicts the same
    save_model(m, tmp_path / "v2.json")
    assert json.loads((tmp_path / "v2.json").read_text())["version"] == 2
    u = np.linspace(-30, 30, 200)
    assert np.array_equal(load_model(tmp_path / "v2.json").predict(u), m.predict(u))
