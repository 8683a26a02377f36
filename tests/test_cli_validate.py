"""`endocal validate` end to end: JSON contract, the refit command, the error falling, bad input (exit 2)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import typer
from typer.testing import CliRunner

from endocal.models import HysteresisData, make_model, save_model
from endocal.sim import SimConfig
from endocal.validation.data import axis_data
from tests.test_validation_hidden import simulate

runner = CliRunner()


def _app():
    """The real root app when `validate` is registered there, else the same function on its own app."""
    from endocal.cli import app
    from endocal.cli import commands  # noqa: F401  (registers the subcommands)

    if any(c.name == "validate" for c in app.registered_commands):
        return app
    from endocal.cli.validate import validate

    local = typer.Typer()
    local.command("validate")(validate)

    @local.callback()
    def _root() -> None:
        """endocal (test harness)."""

    return local


def _invoke(*args):
    return runner.invoke(_app(), ["validate", *map(str, args)])


@pytest.fixture(scope="module")
def drifting(tmp_path_factory):
    """A sine run with a zero drift the model lacks, as CSV, and the model without drift."""
    tmp = tmp_path_factory.mktemp("validate")
    cfg = SimConfig.default().replace(deadzone={"enabled": False}, drift={"enabled": True, "rate_deg_per_min": [3.0, -1.0]})
    aligned, noise = simulate(cfg, "sine", {"cycles": 6})
    csv = tmp / "run.csv"
    aligned.table[["t_s", "ap_cmd_deg", "ap_meas_deg", "ml_cmd_deg", "ml_meas_deg", "sheath_wrap_deg"]].to_csv(csv, index=False)
    model = make_model("bspline", axis="ap").fit(axis_data(aligned, "ap"))
    save_model(model, tmp / "m.json")
    return tmp, csv, aligned, noise


def test_json_names_the_missing_effect_and_the_command_to_refit(drifting):
    tmp, csv, _, noise = drifting
    res = _invoke(tmp / "m.json", csv, "--json")
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    for k in ("rmse_deg", "mae_deg", "max_deg", "median_deg", "median_pct"):
        assert np.isfinite(d["metrics"][k]) and k in d["metrics"]["ci"]
    assert d["regimes"] and "whiteness" in d["residuals"]
    top = d["suspects"][0]
    assert top["effect"] == "drift" and top["column"] is None
    assert top["gain_pct"] >= 50 and top["p_value"] < 0.05
    assert top["command"] == (f"endocal fit hysteresis {csv} --axis ap --model bspline --effects drift "
                              f"--start-from {tmp / 'm.json'} --out {tmp / 'm-drift.json'}")
    assert any("rate cannot be identified" in n for n in d["notes"])


def test_refitted_model_shows_the_error_falling(drifting):
    tmp, csv, aligned, noise = drifting
    # what the printed command does (the fit is the library's; the CLI command is the lead's)
    save_model(make_model("bspline", ["drift"], axis="ap").fit(axis_data(aligned, "ap")), tmp / "m-drift.json")
    res = _invoke(tmp / "m-drift.json", csv, "--json-out", tmp / "v.json")
    assert res.exit_code == 0, res.output
    d = json.loads(_invoke(tmp / "m-drift.json", csv, "--json").stdout)
    c = d["compare"]
    # the summary: the model by its label (not the file's stem), the error falling from the model it was
    # refitted from (found by the refit command's naming), nothing missing, the next command
    lines = res.stdout.splitlines()
    # fitted on this record: no "validation RMSE", but the rolling origin's held-out one
    assert lines[0].startswith(f"bspline+drift on axis ap: RMSE {d['metrics']['rmse_deg']:.3g} deg (95 % CI ") and \
        f"held-out {d['heldout_rmse_deg']:.3g} deg (rolling origin)" in lines[0], res.stdout
    assert lines[1] == (f"error fell {abs(c['change_pct']):.0f} % since bspline (m.json): held-out RMSE "
                        f"{c['old_heldout_rmse_deg']:.3g} -> {c['new_heldout_rmse_deg']:.3g} deg"), res.stdout
    assert any(ln.startswith("nothing missing: no catalog effect lowers") for ln in lines), res.stdout
    assert lines[-2] == (f"next: compare the models on these records, with figures: endocal report {tmp / 'm.json'} "
                         f"{tmp / 'm-drift.json'} --data {csv} --out report.html"), res.stdout
    # what a fitted-on-itself record cannot test (rate, coupling, ...): the experiment that would, beside it
    assert lines[-3].startswith("next: write the experiment that tests ") and lines[-3].endswith(
        f"endocal validate {tmp / 'm-drift.json'} {csv} --next next.toml"), res.stdout
    assert len(lines) <= 15
    full = _invoke(tmp / "m-drift.json", csv, "--explain")
    assert "Watch the error fall" in full.stdout and "bspline -> " not in full.stdout
    assert "bspline+drift" in full.stdout and "Which effect is missing: nothing" in full.stdout
    # --json-out keeps the terminal view and writes the same object --json prints (what scripts parse)
    assert json.loads((tmp / "v.json").read_text()) == d
    assert c["old_label"] == "bspline" and c["new_label"] == "bspline+drift"
    assert c["new_heldout_rmse_deg"] <= 0.5 * c["old_heldout_rmse_deg"]
    assert c["new_heldout_rmse_deg"] <= 1.5 * noise
    assert d["suspects"] == []


def _one_line_exit_2(res, match):
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and match in lines[0], res.output


def test_bad_input_is_one_line_and_exit_2(drifting, tmp_path):
    tmp, csv, aligned, _ = drifting
    # a model of another axis than the data has
    piezo = tmp_path / "piezo.csv"
    pd.DataFrame({"t_s": aligned.table["t_s"], "piezo_cmd_deg": aligned.table["ap_cmd_deg"],
                  "piezo_meas_deg": aligned.table["ap_meas_deg"]}).to_csv(piezo, index=False)
    _one_line_exit_2(_invoke(tmp / "m.json", piezo), "the model is for axis 'ap'")
    # an unknown effect name in the model file
    d = json.loads((tmp / "m.json").read_text())
    d["effects"] = [{"name": "warp", "settings": {}}]
    (tmp_path / "bad.json").write_text(json.dumps(d))
    _one_line_exit_2(_invoke(tmp_path / "bad.json", csv), "unknown effect 'warp'")
    # --json-out under a file (a folder that cannot be made): refused before the validation runs
    _one_line_exit_2(_invoke(tmp / "m.json", csv, "--json-out", csv / "v.json"), "is not a folder")
    # data too short for cross-validation, with no estimation data: the metrics, regimes and
    # residual tests still run; the scan says why it cannot and what to give it
    short = tmp_path / "short.csv"
    pd.read_csv(csv).iloc[:300].to_csv(short, index=False)
    res = _invoke(tmp / "m.json", short, "--explain")
    assert res.exit_code == 0, res.output
    assert "rmse_deg" in res.stdout and "not tested" in res.stdout and "--train" in res.stdout
    res = _invoke(tmp / "m.json", short)  # the summary: the error, and why nothing was tested, what to give
    assert res.exit_code == 0 and res.stdout.startswith("bspline on axis ap: RMSE "), res.output
    assert any(ln.startswith("missing: not tested: ") and "--train" in ln for ln in res.stdout.splitlines())
    # estimation data that never reverses: nothing can be fitted, one line, exit 2
    _one_line_exit_2(_invoke(tmp / "m.json", csv, "--train", short), "never reverses")
    # nothing to validate on
    _one_line_exit_2(_invoke(tmp / "m.json"), "nothing to validate on")
    # a previous model of the other axis to compare with (its error would be scored against this axis' angle)
    save_model(make_model("linear", axis="ml").fit(axis_data(aligned, "ap")), tmp_path / "ml.json")  # a label is enough
    _one_line_exit_2(_invoke(tmp / "m.json", csv, "--compare", tmp_path / "ml.json", "--json-out", tmp_path / "v.json"),
                     "is a model of axis 'ml'")
    assert not (tmp_path / "v.json").exists()


def test_load_on_a_missing_or_constant_column_is_refused(drifting, tmp_path):
    _, csv, aligned, _ = drifting
    t = aligned.table["t_s"].to_numpy()
    wrap = 180 + 60 * np.sin(2 * np.pi * t / 40)
    data = HysteresisData(cmd_deg=aligned.table["ap_cmd_deg"], meas_deg=aligned.table["ap_meas_deg"], t_s=t,
                          extras={"wrap_deg": wrap})
    save_model(make_model("bspline", ["load:wrap_deg"], axis="ap").fit(data), tmp_path / "load.json")
    _one_line_exit_2(_invoke(tmp_path / "load.json", csv), "no column 'wrap_deg'")
    const = tmp_path / "const.csv"
    pd.read_csv(csv).assign(wrap_deg=180.0).to_csv(const, index=False)
    _one_line_exit_2(_invoke(tmp_path / "load.json", const), "constant")
