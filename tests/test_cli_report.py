"""`endocal report` end to end on aligned tables made here (a play-operator drive, not the simulator)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import typer
from typer.testing import CliRunner

from endocal.cli.report import report, split_paths
from endocal.models import make_model, save_model
from endocal.runs.aligned import load_aligned
from endocal.validation.data import axis_data


def _app() -> typer.Typer:
    app = typer.Typer()
    app.command("report")(report)

    @app.callback()
    def _root() -> None:
        """Test root."""

    return app


def _table(path, seed, cycles=6, rate_hz=20.0, period_s=10.0):
    """A triangle command through backlash (play operator, half-width 6 deg) and a stiffening gain, plus 0.2 deg noise."""
    t = np.arange(0.0, cycles * period_s, 1 / rate_hz)
    phase = (t / period_s + 0.25) % 1.0
    cmd = 50.0 * (4 * np.abs(phase - 0.5) - 1.0)
    y = np.empty_like(cmd)
    state = 0.0
    for i, u in enumerate(cmd):
        state = min(max(state, u - 6.0), u + 6.0)
        y[i] = state
    meas = 0.6 * y + 0.002 * y**2 * np.sign(y) + np.random.default_rng(seed).normal(0, 0.2, t.size)
    pd.DataFrame({"t_s": t, "ap_cmd_deg": cmd, "ap_meas_deg": meas}).to_csv(path, index=False)
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("cli_report")
    a = _table(root / "a.csv", 1)
    _table(root / "b.csv", 2)  # a second record for the tests that read it
    data = axis_data(load_aligned(a), "ap")
    for base in ("linear", "bspline"):
        save_model(make_model(base, axis="ap").fit(data), root / f"{base}.json")
    return root


def test_report_writes_html_json_csv_and_prints_the_summary(files):
    out = files / "out1" / "report.html"
    res = CliRunner().invoke(_app(), ["report", str(files / "linear.json"), str(files / "bspline.json"),
                                      "--data", str(files / "a.csv"), str(files / "b.csv"), "--out", str(out),
                                      "--bootstrap", "100", "-q"])
    assert res.exit_code == 0, res.output
    assert out.is_file() and (out.parent / "report.json").is_file() and (out.parent / "report_metrics.csv").is_file()
    saved = json.loads((out.parent / "report.json").read_text())
    # both records evaluated (b.csv came in as a positional after --data), both models on each
    assert sorted({r["data"] for r in saved["metrics"]}) == ["a", "b"]
    assert len(saved["metrics"]) == 4 and saved["not_evaluated"] == []
    # bspline follows the curved, backlashed drive; linear cannot bend: the held-out record says so
    held = next(s for s in saved["summary"] if s["data"] == "b")
    assert held["best"] == "bspline" and held["significant"] is True
    # the summary: one line per record, the best model, by how much, significant or not (the
    # sentences with their tests, and the ladder, with --explain)
    assert res.stdout.splitlines()[1] == (f"b (table), ap: bspline best, RMSE {held['best_rmse_deg']:.3g} deg, "
                                          f"{held['margin_pct']:.0f} % below linear: significant "
                                          f"(p = {held['p_value']:.2g})"), res.stdout
    assert len(res.stdout.splitlines()) == 2 and res.stdout.startswith("a (table), ap [in-sample for linear, bspline]")
    assert res.stderr.splitlines()[-1].startswith(f"next: open {out} in a browser"), res.stderr
    assert saved["provenance"]["command"].startswith("endocal ")
    # the ladder refits each structure on rolling-origin folds of each record: the curve and the
    # backlash are real, so bspline's held-out error is well below linear's, significantly
    for data in ("a", "b"):
        lin, bsp = [s for s in saved["ladder"] if s["data"] == data]
        assert (lin["model"], bsp["model"]) == ("linear", "bspline")
        assert bsp["heldout_rmse_deg"] < 0.8 * lin["heldout_rmse_deg"] and bsp["significant"] is True
    assert "ladder" not in res.stdout  # said by --explain (tests/test_report_build.py checks its sentences)


def test_json_output_carries_the_same_numbers(files):
    out = files / "out2" / "report.html"
    res = CliRunner().invoke(_app(), ["report", str(files / "linear.json"), "--data", str(files / "b.csv"),
                                      "--out", str(out), "--json", "--bootstrap", "50"])
    assert res.exit_code == 0, res.output
    printed = json.loads(res.stdout)
    saved = json.loads((out.parent / "report.json").read_text())
    assert printed["metrics"] == saved["metrics"]
    assert printed["files"]["csv"].endswith("report_metrics.csv")


@pytest.mark.parametrize("case, fragment", [
    ("missing_model", "does not exist"),
    ("missing_data", "does not exist"),
    ("other_axis", "fitted on axis 'ap' but no data has it"),
    ("exists", "already exist"),
])
def test_bad_input_is_one_line_and_exit_2(files, tmp_path, case, fragment):
    t = np.linspace(0, 10, 100)
    pd.DataFrame({"t_s": t, "ud_cmd_deg": t, "ud_meas_deg": t}).to_csv(tmp_path / "ud.csv", index=False)
    (tmp_path / "report.html").write_text("old")
    args = {
        "missing_model": [str(tmp_path / "none.json"), "--data", str(files / "a.csv")],
        "missing_data": [str(files / "linear.json"), "--data", str(tmp_path / "none.csv")],
        "other_axis": [str(files / "linear.json"), "--data", str(tmp_path / "ud.csv")],
        "exists": [str(files / "linear.json"), "--data", str(files / "a.csv")],
    }[case]
    out = tmp_path / ("report.html" if case == "exists" else "new.html")
    res = CliRunner().invoke(_app(), ["report", *args, "--out", str(out)])
    assert res.exit_code == 2, res.output
    lines = [x for x in res.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and fragment in lines[0] and "Traceback" not in res.output
    assert not (tmp_path / "report.json").exists() and not (tmp_path / "new.html").exists()


def test_positional_records_after_data_are_split_from_models(files):
    models, records = split_paths([files / "linear.json", files / "b.csv", files], [files / "a.csv"])
    assert models == [files / "linear.json"]
    assert records == [files / "a.csv", files / "b.csv", files]


def test_two_reports_share_a_folder(files):
    # each page's JSON and metrics CSV are named after it, so a second report does not collide
    for name in ("linear", "bspline"):
        res = CliRunner().invoke(_app(), ["report", str(files / f"{name}.json"), "--data", str(files / "a.csv"),
                                          "--out", str(files / "both" / f"{name}.html"), "--bootstrap", "50", "-q",
                                          *(["--explain"] if name == "bspline" else [])])
        assert res.exit_code == 0, res.output
        saved = json.loads((files / "both" / f"{name}.json").read_text())
        # --explain prints the findings' sentences in full; the summary its verdict
        assert (saved["summary"][0]["sentence"] in res.stdout) == (name == "bspline"), res.stdout
        assert f"{name} best, RMSE" in res.stdout or name == "bspline"
    for name in ("linear", "bspline"):
        saved = json.loads((files / "both" / f"{name}.json").read_text())
        assert [m["model"] for m in saved["metrics"]] == [name]
        assert (files / "both" / f"{name}_metrics.csv").is_file()
