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
from endocal.models import HysteresisData, load_model, make_model, save_model
from endocal.planes import load_planes
from endocal.planes.from_runs import segment_runs
from endocal.report import build_report
from endocal.report import figures as F
from endocal.report.ladder import FOLDS, MAX_CV_SAMPLES
from endocal.runs.aligned import load_aligned
from endocal.validation.data import axis_data
from endocal.validation.metrics import error_metrics
from endocal.validation.offline import validate_offline
from tests._cli import endocal  # in-process: the same parsing, errors and exit codes, without a start-up per call


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
    # bending planes: one sweep per half-plane, then the same protocol through the compensator
    # and the refit that measures the residuals (`fit planes RUN --after AFTER`)
    cal = root / "cal"
    for args in (("excite", "planes", "--set", "repetitions=1", "--out", cal / "planes", "--seed", "1", "--quiet"),
                 ("fit", "planes", cal / "planes", "--out", cal / "before.json", "--bootstrap", "10"),
                 ("excite", "planes", "--set", "repetitions=1", "--planes", cal / "before.json", "--out", cal / "after",
                  "--seed", "5", "--quiet"),
                 ("fit", "planes", cal / "planes", "--after", cal / "after", "--out", cal / "planes.json",
                  "--bootstrap", "10")):
        proc = endocal(*args)
        assert proc.returncode == 0, proc.stderr
    paths["planes"] = cal / "planes.json"
    return root, paths


@pytest.fixture(scope="module")
def report(sim):
    root, p = sim
    steps = []
    rep = build_report([p["linear"], p["pi_env"], p["ml_linear"]], [root / "fit", root / "held", root / "mlrun"],
                       planes=p["planes"], out=root / "out" / "report.html", regime_boot=0,
                       progress=lambda step, done, total: steps.append((done, total, step)))
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
    # the ladder's held-out RMSE is the one validate prints (same folds, same decimation, same refits)
    step = next(s for s in rep.ladder if s["data"] == "held" and s["model"] == "linear")
    assert step["heldout_rmse_deg"] == validated.scan.baseline_rmse_heldout_deg
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
    # the ladder refits both the same way: same held-out errors, no change, nothing significant
    a, b = rep.ladder
    assert a["heldout_rmse_deg"] == b["heldout_rmse_deg"] and b["change_pct"] == 0.0
    assert b["p_value"] == 1.0 and b["significant"] is False


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
    assert [d for d, _, _ in steps] == sorted(d for d, _, _ in steps)  # and never went back
    assert any(step.startswith("ladder:") for _, _, step in steps)  # the cross-validation is the long part


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


def _rolling_origin_by_hand(model, table, axis: str) -> tuple[float, float, int, int]:
    """Held-out and in-sample RMSE of ``model``'s structure on one record, from the method's definition:
    numpy slices of the table's columns and the models' own fit and predict, none of the validation code
    the ladder runs (folds, decimation, held-out errors, scored predictions).

    Decimated to at most MAX_CV_SAMPLES (every ``stride``-th row); the first half only trains; the rest
    is cut into FOLDS blocks; fold k is fitted on everything before block k and run from the record's
    start over the end of block k. The in-sample error is each fold's own fit residual.
    """
    t, u, y = (table[c].to_numpy() for c in ("t_s", f"{axis}_cmd_deg", f"{axis}_meas_deg"))
    stride = -(-u.size // MAX_CV_SAMPLES)
    t, u, y = t[::stride], u[::stride], y[::stride]
    edges = np.linspace(round(0.5 * u.size), u.size, FOLDS + 1).round().astype(int)
    held, fit_sq, n_fit = [], 0.0, 0
    for a, b in zip(edges[:-1], edges[1:]):
        m = make_model(model.base_name, [e.label for e in model.effects_], **model.get_settings(), axis=axis,
                       out_of_range="extrapolate").fit(HysteresisData(cmd_deg=u[:a], meas_deg=y[:a], t_s=t[:a]))
        held.append(m.predict(HysteresisData(cmd_deg=u[:b], meas_deg=y[:b], t_s=t[:b]))[a:b] - y[a:b])
        fit_sq, n_fit = fit_sq + m.fit_report_.rmse_deg ** 2 * a, n_fit + a
    return float(np.sqrt(np.mean(np.concatenate(held) ** 2))), float(np.sqrt(fit_sq / n_fit)), stride, u.size


def test_ladder_heldout_equals_a_direct_rolling_origin_computation(sim, report):
    root, p = sim
    rep, _ = report
    table = load_aligned(root / "held").table
    for label in ("linear", "pi_env"):
        model = load_model(p[label])
        heldout, train, stride, n = _rolling_origin_by_hand(model, table, "ap")
        step = next(s for s in rep.ladder if s["data"] == "held" and s["model"] == label)
        assert step["heldout_rmse_deg"] == pytest.approx(heldout, rel=1e-12)
        assert step["train_rmse_deg"] == pytest.approx(train, rel=1e-12)
        assert step["stride"] == stride and step["n_samples"] == n and step["folds"] == FOLDS
        lo, hi = step["heldout_ci"]
        assert lo <= step["heldout_rmse_deg"] <= hi
        # the model file's own numbers stay beside them
        assert step["file_rmse_deg"] == rep.group("held", "ap").evaluation(label).metrics.rmse_deg


def test_ladder_falls_where_the_effect_is_real(report):
    rep, _ = report
    for data in ("fit", "held"):
        lin, env = [s for s in rep.ladder if s["data"] == data and s["axis"] == "ap"]
        assert (lin["step"], env["step"]) == ("linear", "pi+envelope")
        # the simulated tendon stiffens with the bend: a straight line cannot follow it, the
        # envelope can. The file models already differ by > 20 % (see above); refitted on
        # half a record the gap must survive held out, and be significant.
        assert env["change_pct"] < -20 and env["significant"] is True and env["p_adjusted"] < 0.05
        # the triangle drive is stationary, so the held-out blocks are like the training data and
        # the only systematic difference is the fit's optimism on the samples it was fitted to
        for s in (lin, env):
            assert s["train_rmse_deg"] < s["heldout_rmse_deg"]
    assert any(line.startswith("ladder held, ap") and "-> pi+envelope" in line for line in rep.summary_lines())


def test_planes_figure_scatters_every_measured_sweep_sample(sim, report):
    root, p = sim
    rep, _ = report
    cal = load_planes(p["planes"])
    view = rep.planes_view
    assert cal.residual_source == "measured"
    # before: exactly the frames the planes file says it was fitted on, from the run it names
    recorded = sum(s["frames"] for s in cal.sweeps_used)
    assert view.before.n_points == recorded and view.before.runs == [str(root / "cal" / "planes")]
    # after: the compensated run, found because its refit reproduces the recorded residuals
    seg_after, _ = segment_runs([root / "cal" / "after"], compensated=True)
    assert view.after.n_points == sum(len(s.t_s) for s in seg_after.sweeps) > 0
    assert view.after.runs == [str(root / "cal" / "after")]
    seg, _ = segment_runs([root / "cal" / "planes"])
    first = next(s for s in seg.sweeps if s.half_plane == "y+")
    assert np.array_equal(view.before.tip_xy_mm["y+"][: len(first.t_s)], first.tip_in_base_mm[:, :2])
    # the drawn figure scatters them all, one point per sample
    fig = F.planes_figure(view.before.tip_xy_mm, view.after.tip_xy_mm, cal.deviation_signed_deg,
                          cal.deviation_signed_ci_deg, cal.residual_deviation_signed_deg,
                          {"y+": 90.0, "y-": -90.0, "x+": 0.0, "x-": 180.0}, ("before", "after"), "planes",
                          offset_line=True)
    before_ax, after_ax = fig.axes
    assert sum(len(c.get_offsets()) for c in before_ax.collections) == recorded
    assert sum(len(c.get_offsets()) for c in after_ax.collections) == view.after.n_points
    # and the report's JSON says so
    saved = json.loads((root / "out" / "report.json").read_text())["planes_sweeps"]
    assert saved["before"]["n_points"] == recorded == saved["recorded_frames"]
    assert saved["after"]["n_points"] == view.after.n_points and saved["notes"] == []
    fig_meta = next(f for f in rep.figures if f.id == "planes")
    assert "measured" in fig_meta.caption and "fitted geometry only" not in fig_meta.title


def test_planes_without_their_runs_say_so(sim, tmp_path):
    root, p = sim
    alone = tmp_path / "planes.json"
    shutil.copy(p["planes"], alone)
    rep = build_report([p["linear"]], [root / "held"], planes=alone, out=tmp_path / "r.html", n_boot=0, regime_boot=0)
    assert rep.planes_view.before is None and rep.planes_view.after is None
    assert any("run folder(s) planes named in" in n and "were not found" in n for n in rep.notes)
    assert any("does not name the runs" in n for n in rep.notes)
    fig = next(f for f in rep.figures if f.id == "planes")
    assert fig.title.endswith("(fitted geometry only)")
    html = (tmp_path / "r.html").read_text()
    assert "were not found" in html and "(fitted geometry only)" in html
    saved = json.loads((tmp_path / "r.json").read_text())["planes_sweeps"]
    assert saved["before"] is None and saved["after"] is None
