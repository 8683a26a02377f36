"""The Python API (:mod:`endocal.api`, exported by ``endocal``): ground truth, the object contract, bad input.

The ground truth is the duodenoscope paper's table-1 model with a 0.12 s delay, written as
aligned tables with 0.3 deg of white noise: the loop from Python (fit without the delay,
validate, take the suggestion, refit) must name the delay, recover it and the paper's
parameters, and end at the noise floor with nothing missing.
"""

from __future__ import annotations

import ast
import io
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure
from matplotlib.image import imread

import endocal
import endocal as ec
from endocal import api
from endocal.errors import EndocalError, ModelError, OutputExistsError, RunFormatError
from endocal.models import PIModel
from endocal.report import figures as F
from tests._models_signals import PAPER_TABLE1, chirp, damped_sine, non_periodic, triangle

ROOT = Path(__file__).resolve().parents[1]
DELAY_S = 0.12
NOISE_DEG = 0.3
DT_S = 0.04  # 25 Hz: a delay of 3 samples


def _truth() -> PIModel:
    return PIModel(effects=["envelope", "delay"], axis="ap").set_parameters({**PAPER_TABLE1, "delay_s": DELAY_S})


@pytest.fixture(scope="module")
def loop(tmp_path_factory):
    """Estimation tables (damped sine, chirp), validation tables (triangle, random), and the loop run on them."""
    root = tmp_path_factory.mktemp("api")
    rng = np.random.default_rng(7)
    truth = _truth()

    def table(name, signal):
        t, u = signal
        y = truth.predict(u, t_s=t) + NOISE_DEG * rng.standard_normal(u.size)
        path = root / name
        pd.DataFrame({"t_s": t, "ap_cmd_deg": u, "ap_meas_deg": y}).to_csv(path, index=False)
        return path

    est = [table("damped-sine.csv", damped_sine(dt_s=DT_S)), table("chirp.csv", chirp(dt_s=DT_S))]
    val = [table("triangle.csv", triangle(dt_s=DT_S)), table("random.csv", non_periodic(dt_s=DT_S))]
    model = ec.fit([ec.load_run(p) for p in est], axis="ap", model="pi", effects=["envelope"])
    v = ec.validate(model, val)
    model2 = v.suggestions[0].refit()
    v2 = ec.validate(model2, val)
    return {"root": root, "est": est, "val": val, "model": model, "v": v, "model2": model2, "v2": v2}


# ---------------------------------------------------------------------------- ground truth
def test_the_loop_names_the_missing_delay_and_its_refit_recovers_the_truth(loop):
    v, model2, v2 = loop["v"], loop["model2"], loop["v2"]
    # without the delay, every prediction lags by 0.12 s: the scan's first suggestion is it
    first = v.suggestions[0]
    assert first.effect == "delay" and first.significant and first.p_value < 0.01
    assert v.rmse_deg > 3 * NOISE_DEG
    # the refit is the model's structure plus the delay, on the estimation data the model file
    # names, started from the validated model
    assert first.plan.data_paths == tuple(map(str, loop["est"])) and first.plan.effects == ("envelope", "delay")
    assert model2.effects == ["delay", "envelope"] and model2.start_from is loop["model"]
    # every parameter of the truth within 4 standard errors (the fit fixes the gauge k1 = 1:
    # play operators are homogeneous, k -> k/k1, r -> r/k1, w -> w k1, beta -> beta k1)
    k1 = PAPER_TABLE1["envelope_k1"]
    expect = {"delay_s": DELAY_S, "pi_r": PAPER_TABLE1["pi_r"] / k1, "pi_w": PAPER_TABLE1["pi_w"] * k1,
              "pi_beta": PAPER_TABLE1["pi_beta"] * k1, "envelope_theta0_deg": PAPER_TABLE1["envelope_theta0_deg"],
              "envelope_theta1_deg": PAPER_TABLE1["envelope_theta1_deg"],
              "envelope_theta2_deg": PAPER_TABLE1["envelope_theta2_deg"],
              "envelope_k0": PAPER_TABLE1["envelope_k0"] / k1, "envelope_k2": PAPER_TABLE1["envelope_k2"] / k1}
    for name, value in expect.items():
        z = (model2.params[name] - value) / model2.stderr[name]
        assert abs(z) < 4.0, (name, model2.params[name], value, model2.stderr[name])
    # 5000 samples of 0.3 deg noise: the residual's RMSE is 0.3 deg within ~0.3/sqrt(2n) = 0.003 deg
    # (x 3 for the fitted parameters' share and the sampling), on the fit and on the 3000
    # validation samples alike (within 3 x 0.3/sqrt(2 x 3000) = 0.012 deg)
    assert model2.rmse_deg == pytest.approx(NOISE_DEG, abs=0.01)
    assert v2.rmse_deg == pytest.approx(NOISE_DEG, abs=0.012)
    # the true structure: nothing missing
    assert v2.clean and v2.suggestions == [] and v2.untested == []
    # and the error fell from the lag's (> 3x the noise, as first validated) to the noise floor
    assert v2.compare is not None and v2.compare.old_label == "pi+envelope"
    assert v2.compare.old_heldout_rmse_deg == pytest.approx(v.heldout_rmse_deg)
    assert v2.compare.new_heldout_rmse_deg == pytest.approx(NOISE_DEG, abs=0.012)


# ---------------------------------------------------------------------------- the contract
def test_reprs_are_short_and_lead_with_the_verdict(loop):
    model, v, v2 = loop["model"], loop["v"], loop["v2"]
    r = repr(model).splitlines()
    assert r[0] == "Model pi+envelope of axis ap" and r[1].strip() == model.equation
    assert r[2].startswith(f"  fit: RMSE {model.rmse_deg:.3g} deg on 5001 samples")
    # a validation's repr is its summary, the lines `endocal validate` prints
    rv = repr(v).splitlines()
    assert rv == v.summary() and len(rv) <= 15
    assert rv[0].startswith(f"pi+envelope on axis ap: validation RMSE {v.rmse_deg:.3g} deg (95 % CI")
    assert any(line.startswith("missing: delay: -") for line in rv)
    assert "  " + v.suggestions[0].command in rv
    rv2 = repr(v2)
    assert "error fell" in rv2 and "since pi+envelope: validation RMSE" in rv2 and "nothing missing" in rv2
    assert repr(v.suggestions[0]).startswith("Suggestion: add delay: -")
    run = ec.load_run(loop["val"][0])
    assert repr(run).splitlines()[0] == f"Run {str(run.path)!r}: aligned table"


def test_to_dict_is_the_commands_json_from_the_same_objects(loop, tmp_path):
    model, v = loop["model"], loop["v"]
    # the model: the file it saves is its to_dict, and the CLI's --json of the same fit has the same content
    path = model.save(tmp_path / "m.json")
    assert json.loads(path.read_text()) == json.loads(model.to_json()) == model.to_dict()
    from tests._cli import endocal as cli

    res = cli("fit", "hysteresis", *map(str, loop["est"]), "--axis", "ap", "--model", "pi", "--effects", "envelope",
              "--out", str(tmp_path / "cli.json"), "--json")
    assert res.returncode == 0, res.stderr
    theirs, ours = json.loads(res.stdout), model.to_dict()
    assert set(theirs) == set(ours)
    for key in ("axis", "base", "settings", "effects", "structure", "parameters", "cmd_range_deg", "training_data"):
        assert theirs[key] == ours[key], key
    assert set(theirs["provenance"]) == set(ours["provenance"])
    assert ours["provenance"]["command"].startswith("endocal.api.fit(")
    # the validation: its to_dict is the result's, with each refit also as its shell command, strict JSON
    d = v.to_dict()
    assert {k: x for k, x in d.items() if k not in ("suspects", "scan")} == {
        k: x for k, x in v.result.to_dict().items() if k not in ("suspects", "scan")}
    assert d["suspects"][0]["command"] == v.suggestions[0].command
    assert json.loads(v.to_json())["suspects"][0]["effect"] == v.suggestions[0].effect == d["suspects"][0]["effect"]
    assert v.suggestions[0].to_dict() == d["suspects"][0]
    # a run: what `endocal info --json` prints
    run = ec.load_run(loop["val"][0])
    info = cli("info", str(run.path), "--json")
    assert json.loads(info.stdout) == json.loads(run.to_json())


def test_models_save_and_load_as_versioned_json(loop, tmp_path):
    model2 = loop["model2"]
    path = model2.save(tmp_path / "m2.json")
    again = ec.load_model(path)
    assert again.to_dict() == model2.to_dict() and again.path == path
    assert again.equation == model2.equation and again.effects == model2.effects
    with pytest.raises(OutputExistsError, match="already exists: choose another path or pass force=True"):
        model2.save(path)
    model2.save(path, force=True)


def test_plots_are_the_reports_figures(loop):
    model, v = loop["model"], loop["v"]
    for kind in ("time_series", "loops", "residuals", "regimes"):
        fig = v.plot(kind)
        assert isinstance(fig, Figure) and fig.axes
        assert fig._repr_png_()[:8] == b"\x89PNG\r\n\x1a\n"  # a notebook shows it without pyplot
    assert "triangle.csv+random.csv (table), axis ap" in v.plot("loops")._suptitle.get_text()
    params = model.plot()
    assert len(params.axes[0].get_yticklabels()) == len(model.params)
    with pytest.raises(ValueError, match="kind must be one of time_series, loops, residuals, regimes"):
        v.plot("bode")
    assert isinstance(ec.load_run(loop["val"][0]).plot(), Figure)


def test_a_report_from_python_keeps_its_figures(loop, tmp_path):
    rep = ec.make_report([loop["model"], loop["model2"]], loop["val"][:1], bootstrap=50, out=tmp_path / "r.html")
    # five of the record, the ladder, each model's parameters (a table has no tip path)
    assert repr(rep).startswith("Report: 2 model(s) on 1 record(s), 8 figures")
    assert rep.files["html"].is_file() and json.loads(rep.files["json"].read_text()) == json.loads(rep.to_json())
    ladder = rep.plot("ladder-ap")
    fig = next(f for f in rep.figures if f.id == "ladder-ap")
    # the very figure the HTML embeds: drawn once, its PNG made from it
    assert ladder is fig.figure
    assert imread(io.BytesIO(F.to_png(ladder))).shape == imread(io.BytesIO(fig.png)).shape
    assert rep.plot(0) is rep.figures[0].figure
    with pytest.raises(KeyError, match="no figure 'nope'"):
        rep.plot("nope")


# ---------------------------------------------------------------------------- planes and force
def test_planes_and_force_from_python(tmp_path):
    planes_run = ec.run_protocol("planes", tmp_path / "planes", seed=1, sample_rate_hz=20, repetitions=1)
    planes = ec.fit_planes(planes_run, bootstrap=20)
    assert repr(planes).startswith("Planes: bending planes (direction, bend_line; 95 % CI, 4 sweeps)")
    # the simulator twists the half-planes by 12.7, 20.2, 2.3 and 15.6 deg; the README's fit of three
    # sweeps a half-plane at 100 Hz recovers them within 0.2 deg, one sweep at 20 Hz within 0.5
    assert planes.deviation_deg == pytest.approx({"y+": 12.7, "y-": 20.2, "x+": 2.3, "x-": 15.6}, abs=0.5)
    assert isinstance(planes.plot(), Figure)
    path = planes.save(tmp_path / "planes.json")
    assert ec.load_planes(path).to_dict() == planes.to_dict()
    assert json.loads(path.read_text()) == {"format": "endocal-planes", "version": 1, **json.loads(planes.to_json())}
    loads = [None, 0.5, 1.0]
    runs = [ec.run_protocol("force-calibration", tmp_path / f"f{i}", seed=i, sample_rate_hz=25, cycles=2,
                            tip_load_n=load) for i, load in enumerate(loads)]
    force = ec.fit_force(runs)
    assert repr(force).startswith("ForceModel ap: F_n = dM_knob / (G * L(beta))")
    # each loaded run predicted by a model fitted without it: within 10 % of the hung load (the README's
    # five full-length runs: within 2 %; two passes of three runs here)
    assert [h.load_n for h in force.model.heldout_] == [0.5, 1.0]
    assert all(abs(h.error_pct) < 10 for h in force.model.heldout_)
    saved = force.save(tmp_path / "force.json")
    assert json.loads(saved.read_text()) == json.loads(force.to_json())


# ---------------------------------------------------------------------------- bad input
def _one_line(exc: BaseException) -> str:
    text = str(exc)
    assert "\n" not in text and text
    return text


def test_a_missing_folder_is_one_clear_error(tmp_path):
    with pytest.raises(RunFormatError) as e:
        ec.load_run(tmp_path / "nowhere")
    assert "nowhere does not exist: give a run folder or an aligned table" in _one_line(e.value)
    with pytest.raises(RunFormatError) as e:
        ec.fit([tmp_path / "nowhere"], axis="ap")
    assert isinstance(e.value, ValueError) and isinstance(e.value, EndocalError)
    with pytest.raises(ModelError) as e:
        ec.load_model(tmp_path / "nowhere.json")
    assert "does not exist" in _one_line(e.value)


def test_a_run_of_another_probe_is_refused_in_one_line(tmp_path):
    tee = ROOT / "data_samples" / "sim-triangle"
    duo = ec.run_protocol("triangle", tmp_path / "duo", probe="duodenoscope", seed=1, period_s=4, cycles=1,
                          sample_rate_hz=20)
    assert duo.probe == {"name": "duodenoscope", "bending_axes": ["ud", "lr"]}
    with pytest.raises(RunFormatError) as e:
        ec.fit([tee, duo], axis="ap")
    assert _one_line(e.value) == (
        f"{duo.path} is a run of probe 'duodenoscope' (axes ud, lr), but {tee} is a run of probe 'tee' (axes ap, "
        "ml): a hysteresis model describes one probe's tendons; give runs of probe 'tee' only")
    model = ec.fit(tee, axis="ap", model="linear")
    assert model.provenance["probe"] == {"name": "tee", "bending_axes": ["ap", "ml"]}
    with pytest.raises(RunFormatError) as e:
        ec.validate(model, [duo])
    assert _one_line(e.value) == (
        f"{duo.path} is a run of probe 'duodenoscope' (axes ud, lr), but the model was fitted on runs of probe "
        "'tee' (axes ap, ml): a hysteresis model describes one probe's tendons; give validation runs of probe "
        "'tee' only")
    # the command line says the same line, exit code 2
    from tests._cli import endocal as cli

    res = cli("fit", "hysteresis", str(tee), str(duo.path), "--axis", "ap", "--out", str(tmp_path / "m.json"))
    assert res.returncode == 2 and "a run of probe 'duodenoscope'" in res.stderr
    assert not (tmp_path / "m.json").exists()
    # validate refuses the other probe's run as the API does (one check serves both), before any work
    from tests._cli import one_line_exit_2

    model.save(tmp_path / "tee.json")
    one_line_exit_2(cli("validate", str(tmp_path / "tee.json"), str(duo.path), "--json-out", str(tmp_path / "v.json")),
                    str(e.value))
    assert not (tmp_path / "v.json").exists()


def test_bad_arguments_are_refused_before_any_work(loop):
    with pytest.raises(ModelError, match="refit_on must be 'estimation' or 'all'"):
        ec.validate(loop["model"], loop["val"], refit_on="everything")
    with pytest.raises(ModelError, match="folds must be 2 or more"):
        ec.validate(loop["model"], loop["val"], folds=1)
    with pytest.raises(ModelError, match="unknown model 'pie'"):
        ec.fit(loop["est"], axis="ap", model="pie")
    with pytest.raises(ModelError, match="no data given"):
        ec.fit([], axis="ap")
    with pytest.raises(ModelError, match="a DataFrame; write it as an aligned table"):
        ec.fit(pd.read_csv(loop["est"][0]), axis="ap")


# ---------------------------------------------------------------------------- the package
def test_import_endocal_stays_light_and_exports_the_api():
    # in a fresh interpreter: `import endocal` (and so `endocal --help`) loads none of the heavy libraries
    code = ("import sys, endocal; heavy = ('numpy', 'pandas', 'scipy', 'matplotlib', 'pyarrow', 'numba'); "
            "print([m for m in heavy if m in sys.modules]); from endocal import fit, Model; "
            "print([m for m in heavy if m in sys.modules])")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert res.returncode == 0, res.stderr
    # nor does taking the API's names: each function imports what it calls
    assert res.stdout.split("\n")[:2] == ["[]", "[]"]
    assert set(endocal._API) == set(api.__all__) and set(endocal.__all__) == {"__version__", *api.__all__}
    assert endocal.fit is api.fit and endocal.Validation is api.Validation
    assert {"fit", "validate", "make_report", "__version__"} <= set(dir(endocal))
    with pytest.raises(AttributeError, match="module 'endocal' has no attribute 'fitt'"):
        endocal.fitt  # noqa: B018
    # names that are also subpackages would be shadowed once those are imported: none is
    assert not any((ROOT / "endocal" / name).exists() or (ROOT / "endocal" / f"{name}.py").exists()
                   for name in api.__all__)



def test_the_commands_json_and_summary_are_the_apis_to_dict_and_repr(loop, tmp_path):
    """One validation, every view: for the same model file and records, `validate --json-out` writes
    `Validation.to_dict()` key for key, and the terminal summary is its repr line for line."""
    from tests._cli import endocal as cli

    path = loop["model"].save(tmp_path / "m.json")  # its provenance names the estimation data
    v = ec.validate(path, loop["val"])
    res = cli("validate", str(path), *map(str, loop["val"]), "--json-out", str(tmp_path / "v.json"))
    assert res.returncode == 0, res.stderr
    theirs, ours = json.loads((tmp_path / "v.json").read_text()), json.loads(v.to_json())
    assert list(theirs) == list(ours) and theirs == ours
    assert theirs["suspects"][0]["command"] == v.suggestions[0].command
    assert theirs["suspects"][0]["command"].startswith(f"endocal fit hysteresis {loop['est'][0]}")
    assert res.stdout.splitlines() == repr(v).splitlines()


def _uses_the_api(path: Path) -> bool:
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import) and any(a.name.startswith("endocal.api") for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and node.level == 0 and (
                (node.module or "").startswith("endocal.api")
                or node.module == "endocal" and any(a.name in ("api", *api.__all__) for a in node.names)):
            return True
    return False


def test_the_api_sits_on_top_of_the_library_beside_the_cli():
    # the API calls the library as the CLI does; no library module calls back into either
    from tests.test_layers import _imports

    assert not [n for n in _imports(ROOT / "endocal" / "api.py") if n.startswith("endocal.cli")]
    callers = [str(p.relative_to(ROOT)) for p in sorted((ROOT / "endocal").rglob("*.py"))
               if p != ROOT / "endocal" / "__init__.py" and _uses_the_api(p)]
    assert callers == []
