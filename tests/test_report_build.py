"""`build_report` on simulator runs: numbers equal validate's, every figure drawn, tests that decide right."""

from __future__ import annotations

import base64
import io
import json
import re
import shutil

import matplotlib.image as mpimg
import numpy as np
import pandas as pd
import pytest

from endocal.errors import ModelError, OutputExistsError, RunFormatError
from endocal.models import load_model, make_model, save_model
from endocal.planes import PlanesCalibration
from endocal.report import build_report
from endocal.runs.aligned import load_aligned
from endocal.validation.data import axis_data
from endocal.validation.metrics import error_metrics
from endocal.validation.offline import validate_offline
from tests.test_cli_excite import endocal


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    """Two ap triangle runs (fit / held out), one ml run, and models fitted through the library."""
    root = tmp_path_factory.mktemp("report")
    runs = {"fit": ("triangle", "--set", "cycles=4", "--seed", "1"),
            "held": ("triangle", "--set", "cycles=3", "--seed", "2"),
            "mlrun": ("triangle", "--set", "cycles=2", "--axes", "ml", "--seed", "3")}
    for name, args in runs.items():
        proc = endocal("excite", args[0], "--out", root / name, "--quiet", *args[1:])
        assert proc.returncode == 0, proc.stderr
    fit = axis_data(load_aligned(root / "fit"), "ap").decimate(5)  # 20 Hz: loops keep their shape, fits stay fast
    paths = {}
    for label, base, effects in (("linear", "linear", []), ("pi_env", "pi", ["envelope"])):
        paths[label] = root / f"{label}.json"
        save_model(make_model(base, effects=effects, axis="ap").fit(fit), paths[label])
    shutil.copy(paths["linear"], root / "linear_copy.json")
    paths["linear_copy"] = root / "linear_copy.json"
    ml = axis_data(load_aligned(root / "mlrun"), "ml").decimate(5)
    paths["ml_linear"] = root / "ml_linear.json"
    save_model(make_model("linear", axis="ml").fit(ml), paths["ml_linear"])
    return root, paths


@pytest.fixture(scope="module")
def report(sim):
    root, p = sim
    planes = PlanesCalibration(
        deviation_deg={"y+": 12.7, "y-": 20.2, "x+": 2.3, "x-": 15.6},
        deviation_ci_deg={h: (v - 0.4, v + 0.4) for h, v in {"y+": 12.7, "y-": 20.2, "x+": 2.3, "x-": 15.6}.items()},
        deviation_signed_deg={"y+": -12.7, "y-": 20.2, "x+": 2.3, "x-": -15.6},
        deviation_signed_ci_deg={"y+": (-13.1, -12.3), "y-": (19.8, 20.6), "x+": (1.9, 2.7), "x-": (-16.0, -15.2)},
        tilt_deg=dict.fromkeys(("y+", "y-", "x+", "x-"), 0.0), offset_deg=dict.fromkeys(("y+", "y-", "x+", "x-"), 0.0),
        delta_deg=1.0, delta_ci_deg=(0.5, 1.5),
        residual_deviation_deg={"y+": 0.3, "y-": 0.5, "x+": 0.2, "x-": 0.4},
        residual_deviation_signed_deg={"y+": 0.3, "y-": -0.5, "x+": 0.2, "x-": -0.4},
        residual_source="cross-validated")
    steps = []
    rep = build_report([p["linear"], p["pi_env"], p["ml_linear"]], [root / "fit", root / "held", root / "mlrun"],
                       planes=planes, out=root / "out" / "report.html", regime_boot=0,
                       progress=lambda step, done, total: steps.append((done, total)))
    return rep, steps


def test_summary_numbers_equal_validate_and_error_metrics(sim, report):
    root, p = sim
    rep, _ = report
    aligned = load_aligned(root / "held")
    g = rep.group("held", "ap")
    for label in ("linear", "pi_env"):
        model = load_model(p[label])
        independent = error_metrics(aligned.meas_deg("ap"), model.predict(axis_data(aligned, "ap")))
        assert g.evaluation(label).metrics == independent
    model, ev = load_model(p["linear"]), g.evaluation("linear")
    validated = validate_offline(model, [aligned])  # linear: its effect scan is the quickest
    assert ev.metrics.to_dict() == validated.metrics.to_dict()
    assert [r.metrics.rmse_deg for r in ev.regimes.regimes] == [r.metrics.rmse_deg for r in validated.regimes.regimes]
    # the summary quotes exactly these numbers
    f = g.finding
    assert f.best_rmse_deg == min(e.metrics.rmse_deg for e in g.evaluations)
    assert f"{f.best_rmse_deg:.3f} deg" in f.sentence
    saved = json.loads((root / "out" / "report.json").read_text())
    row = next(r for r in saved["metrics"] if r["data"] == "held" and r["model"] == "linear")
    assert row["rmse_deg"] == ev.metrics.rmse_deg and row["median_pct"] == ev.metrics.median_pct
    assert [row["rmse_deg_ci_low"], row["rmse_deg_ci_high"]] == list(ev.metrics.ci["rmse_deg"])
    csv = pd.read_csv(root / "out" / "report_metrics.csv")
    crow = csv[(csv["data"] == "held") & (csv["model"] == "linear")].iloc[0]
    assert crow["rmse_deg"] == pytest.approx(ev.metrics.rmse_deg, rel=1e-15)


def test_clearly_different_models_differ_significantly(report):
    rep, _ = report
    for data in ("fit", "held"):
        g = rep.group(data, "ap")
        assert g.comparison.test == "wilcoxon" and g.units.kind == "half-cycle" and g.units.n >= 6
        assert g.finding.best == "pi_env"
        assert g.finding.significant is True
        pair = g.comparison.pair("linear", "pi_env")
        assert pair.better == "pi_env" and pair.p_value < 0.05
        # the envelope removes the largest part of the linear model's error on this drive
        assert g.finding.margin_pct > 20


def test_identical_models_show_no_significant_difference(sim, tmp_path):
    root, p = sim
    rep = build_report([p["linear"], p["linear_copy"]], [root / "held"], n_boot=0, regime_boot=0)
    g = rep.group("held", "ap")
    assert g.comparison.p_value == 1.0 and g.comparison.effect_size == 0.0
    assert g.finding.significant is False and "not significant" in g.finding.sentence
    assert g.finding.margin_deg == 0.0


def test_every_figure_present_nonempty_and_page_self_contained(sim, report):
    root, _ = sim
    rep, steps = report
    html = (root / "out" / "report.html").read_text()
    pngs = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    assert len(pngs) == len(rep.figures)
    ids = {f.id for f in rep.figures}
    for data in ("fit", "held"):
        assert {f"{k}-{data}-ap" for k in ("ts", "loops", "box", "resid", "regime")} <= ids
    assert {"ladder-ap", "params-linear", "params-pi_env", "params-ml_linear", "planes", "tip-paths"} <= ids
    for b64 in pngs:
        img = mpimg.imread(io.BytesIO(base64.b64decode(b64)), format="png")
        assert img.shape[0] > 200 and img.shape[1] > 300
        assert float(np.std(img[..., :3])) > 0.05  # drawn, not blank
    assert not re.search(r'(src|href)="(https?:)?//', html) and "<script" not in html
    assert "@media print" in html
    assert steps and steps[-1][0] == steps[-1][1]  # progress reached its total


def test_nothing_dropped_silently(report, sim):
    root, _ = sim
    rep, _ = report
    skipped = {(n.model, n.data): n.reason for n in rep.not_evaluated}
    # the ap records never move the ml knob, the ml record has no ap motion
    assert "does not excite" in skipped[("ml_linear", "fit")]
    assert "does not excite" in skipped[("linear", "mlrun")]
    assert rep.group("mlrun", "ml").evaluation("ml_linear").metrics.n > 0
    html = (root / "out" / "report.html").read_text()
    assert html.count("Not evaluated:") == len(rep.not_evaluated)
    assert any("ml_linear on fit" in line for line in rep.summary_lines())


def test_bad_inputs_are_domain_errors(sim, tmp_path):
    root, p = sim
    with pytest.raises(ModelError, match="does not exist"):
        build_report([tmp_path / "nope.json"], [root / "held"])
    with pytest.raises(RunFormatError, match="does not exist"):
        build_report([p["linear"]], [tmp_path / "nope"])
    t = np.linspace(0, 10, 200)
    pd.DataFrame({"t_s": t, "ud_cmd_deg": np.sin(t), "ud_meas_deg": np.sin(t)}).to_csv(tmp_path / "ud.csv", index=False)
    with pytest.raises(ModelError, match="fitted on axis 'ap' but no data has it"):
        build_report([p["linear"]], [tmp_path / "ud.csv"])
    with pytest.raises(RunFormatError, match="no overlap"):
        build_report([p["linear"]], [root / "held", tmp_path / "ud.csv"])
    out = tmp_path / "r.html"
    out.write_text("keep")
    with pytest.raises(OutputExistsError):
        build_report([p["linear"]], [root / "held"], out=out, n_boot=0, regime_boot=0)
    assert out.read_text() == "keep" and not (tmp_path / "report.json").exists()
