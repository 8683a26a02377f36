"""Every promise kept: the refit `validate` prints delivers the fall it promised (issue 33).

`validate` says "missing: rate: -45 % validation RMSE (2.45 -> 1.33 deg)" and prints the
`endocal fit hysteresis ...` that adds it. Here that command is run as printed, the model it
writes is validated on the same records, and the error must fall by at least 75 % of the
promised fall (the bar the issue sets: a refit fits every sample where the scan fitted a
subsample, and under rolling origin the new model's own folds start from its own values).

The records: a real-shaped linear-drive log (a tendon pulled by a stage, in mm; the bench of
tests/test_linear_drive.py) cut in two, fitted on the first half with the duodenoscope paper's
modified PI (`pi` + `envelope`, whose `weights="auto"` the refit must keep as the fit resolved
it) and validated on the second; the real piezo recording (data_samples/piezo); and, marked
slow, the simulator's records of every hidden-effect case of tests/test_validation_hidden.py.
"""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import pandas as pd
import pytest

from endocal.models import load_model
from tests._cli import endocal
from tests.test_linear_drive import tendon_log

ROOT = Path(__file__).resolve().parents[1]
PIEZO = ROOT / "data_samples" / "piezo" / "piezo_aligned.csv"
#: Share of the promised fall the printed refit must deliver (issue 33's bar).
KEPT = 0.75


def _validate(model: Path, data: list[Path], out: Path) -> tuple[dict, str]:
    proc = endocal("validate", model, *data, "--json-out", out)
    assert proc.returncode == 0, proc.stderr
    return json.loads(out.read_text()), proc.stdout


def keep_promises(model: Path, data: list[Path], tmp: Path, first_only: bool = False) -> list[tuple]:
    """Validate ``model``, run each suggestion's printed command, validate what it wrote: (effect,
    promised %, delivered %, new RMSE, expected range) per suggestion; asserts each is kept."""
    d, stdout = _validate(model, data, tmp / "v.json")
    assert d["suspects"], [(s["effect"], round(s["gain_pct"], 1)) for s in d["scan"]["tested"]]
    # the command printed is the JSON's: the first suggestion's, or the base change's that comes first
    bases = [b for b in d["scan"].get("bases", []) if b["significant"]]
    first = bases[0] if d["scan"]["base_first"] else d["suspects"][0]
    assert "  " + first["command"] in stdout.splitlines(), stdout
    kept = []
    for s in d["suspects"][:1] if first_only else d["suspects"]:
        argv = shlex.split(s["command"])
        assert argv[:3] == ["endocal", "fit", "hysteresis"] and s["refit"]["out_path"] == argv[-1]
        proc = endocal(*argv[1:], "--force")
        assert proc.returncode == 0, (s["command"], proc.stderr)
        new = Path(s["refit"]["out_path"])
        # the same resolved structure as the model validated: its settings, "auto" resolved as its fit did
        old_m, new_m = load_model(model), load_model(new)
        for k in ("weights", "offset"):
            if k in old_m.structure_:
                assert new_m.structure_[k] == old_m.structure_[k], (k, s["command"])
        d2, _ = _validate(new, data, tmp / f"v-{s['effect'].replace(':', '-')}.json")
        c = d2["compare"]
        assert c is not None and c["path"] == str(model), c
        promised, delivered = s["gain_pct"], -c["change_pct"]
        kept.append((s["effect"], promised, delivered, c["new_heldout_rmse_deg"], s["refit"]["expected_rmse_deg"]))
        assert delivered >= KEPT * promised, kept[-1]
    return kept


@pytest.fixture(scope="module")
def tendon(tmp_path_factory):
    """A linear drive's log cut in two, as a user does with one recording: the first half (damped
    sweeps) to fit on, the second (a chirp of varying amplitude) to validate on; 30 s each at 50 Hz."""
    tmp = tmp_path_factory.mktemp("promise-tendon")
    parts = {"fit": tendon_log(1, "damped", duration_s=30.0), "check": tendon_log(2, "chirp", duration_s=30.0)}
    for name, df in parts.items():
        pd.DataFrame({"t_s": df["Time"], "ap_cmd_mm": df["Tendon Disp."], "ap_meas_deg": df["Angle y"]}).to_csv(
            tmp / f"{name}.csv", index=False)
    proc = endocal("fit", "hysteresis", tmp / "fit.csv", "--axis", "ap", "--model", "pi", "--effects", "envelope",
                   "--out", tmp / "s-pi.json")
    assert proc.returncode == 0, proc.stderr
    return tmp


@pytest.mark.slow  # two validations of a 21-weight PI: ~30 s of CPU
def test_a_linear_drive_logs_suggestion_delivers_what_validate_promised(tendon):
    # the bench's tendon slack is what pi + envelope lacks: deadzone, -42 % promised
    kept = keep_promises(tendon / "s-pi.json", [tendon / "check.csv"], tendon, first_only=True)
    assert kept[0][0] == "deadzone", kept


@pytest.mark.slow
def test_every_suggestion_on_a_longer_linear_drive_log_delivers_what_validate_promised(tmp_path):
    # 100 Hz sweeps for 80 s: the scan fits 1 estimation sample in 2, and each promise gives the range to expect
    parts = {"fit": tendon_log(3, "damped", rate_hz=100.0, duration_s=80.0),
             "check": tendon_log(4, "chirp", rate_hz=50.0, duration_s=60.0)}
    for name, df in parts.items():
        pd.DataFrame({"t_s": df["Time"], "ap_cmd_mm": df["Tendon Disp."], "ap_meas_deg": df["Angle y"]}).to_csv(
            tmp_path / f"{name}.csv", index=False)
    proc = endocal("fit", "hysteresis", tmp_path / "fit.csv", "--axis", "ap", "--model", "linear", "--out",
                   tmp_path / "m.json")
    assert proc.returncode == 0, proc.stderr
    kept = keep_promises(tmp_path / "m.json", [tmp_path / "check.csv"], tmp_path)
    assert json.loads((tmp_path / "v.json").read_text())["scan"]["cv"]["stride"] > 1
    assert all(expected is not None for *_, expected in kept), kept


def test_the_real_piezo_recordings_suggestion_delivers_what_validate_promised(tmp_path):
    # a straight-line base misses the piezo loop's rounded ends (test_validation_hidden's real-data case);
    # fitted on the very record, validate scores it by rolling origin, and so does the refit's validation
    proc = endocal("fit", "hysteresis", PIEZO, "--axis", "piezo", "--model", "linear", "--out", tmp_path / "m.json")
    assert proc.returncode == 0, proc.stderr
    keep_promises(tmp_path / "m.json", [PIEZO], tmp_path, first_only=True)


def test_a_base_changes_printed_refit_delivers_its_promise_and_its_validate_shows_the_fall(tmp_path):
    """The loop's other turn: a base change. On the Bouc-Wen plant of tests/test_validation_bases.py (no
    return-point memory) a B-spline fitted on the sweeps misses the validation record's minor loops;
    `validate` puts the base change first and prints its refit (`M-BASE.json`, started from `M.json`: its
    effects at their values, the base afresh, as the scan fitted it). That command run as printed, `validate`
    of what it wrote finds `M.json`, shows the error falling from it, and the fall is at least 75 % of the
    promise."""
    from tests.test_validation_bases import _plant, _records

    est, val = _records(_plant("bouc-wen"))
    for name, d in (("fit", est), ("check", val)):
        pd.DataFrame({"t_s": d.t_s, "ap_cmd_deg": d.cmd_deg, "ap_meas_deg": d.meas_deg}).to_csv(
            tmp_path / f"{name}.csv", index=False)
    proc = endocal("fit", "hysteresis", tmp_path / "fit.csv", "--axis", "ap", "--model", "bspline", "--out",
                   tmp_path / "m.json")
    assert proc.returncode == 0, proc.stderr
    d, stdout = _validate(tmp_path / "m.json", [tmp_path / "check.csv"], tmp_path / "v.json")
    assert d["scan"]["base_first"], stdout
    change = next(b for b in d["scan"]["bases"] if b["significant"])
    assert "  " + change["command"] in stdout.splitlines(), stdout
    argv = shlex.split(change["command"])
    assert argv[argv.index("--start-from") + 1] == str(tmp_path / "m.json")
    assert argv[-1] == str(tmp_path / f"m-{change['base']}.json")
    proc = endocal(*argv[1:], "--force")
    assert proc.returncode == 0, proc.stderr
    d2, stdout2 = _validate(Path(argv[-1]), [tmp_path / "check.csv"], tmp_path / "v2.json")
    c = d2["compare"]
    assert c is not None and c["path"] == str(tmp_path / "m.json"), c
    promised, delivered = change["gain_pct"], -c["change_pct"]
    assert delivered >= KEPT * promised, (promised, delivered)
    assert stdout2.splitlines()[1].startswith(f"error fell {delivered:.0f} % since bspline (m.json)"), stdout2
    # the API: the same change, its refit the printed command's fit, and validate compares with the model it replaces
    import endocal as ec

    v = ec.validate(tmp_path / "m.json", tmp_path / "check.csv")
    assert v.base_first and v.base_changes[0].command == change["command"]
    assert json.loads(v.base_changes[0].to_json()) == change and repr(v.base_changes[0]).startswith(f"BaseChange: base: {change['base']} ")
    new = v.base_changes[0].refit()
    assert new.params == pytest.approx(ec.load_model(argv[-1]).params, rel=1e-9)
    v2 = ec.validate(new, tmp_path / "check.csv")
    assert v2.compare.change_pct == pytest.approx(c["change_pct"], rel=1e-9) and v2.base_changes == []


def test_a_refits_previous_model_is_found_by_the_refit_commands_naming(tmp_path):
    """`validate M-EFFECT.json` compares with `M.json`, and so does `validate M-BASE.json` (a base change) and
    `M-BASE-EFFECT.json` (a base change with an effect beside it); a name that only looks like one, or a
    file that is not there, finds nothing."""
    from endocal.validation.offline import previous_model_path

    for name in ("m.json", "m-deadzone.json", "m-linear.json", "m-linear-deadzone.json", "m-linear-load-col-all.json"):
        (tmp_path / name).write_text("{}")
    found = lambda name, effects, base=None: previous_model_path(tmp_path / name, effects, base)  # noqa: E731
    assert found("m-deadzone.json", ["envelope", "deadzone"], "pi") == tmp_path / "m.json"
    assert found("m-linear.json", ["envelope"], "linear") == tmp_path / "m.json"
    assert found("m-linear.json", ["envelope"], "pi") is None  # not this model's base
    # the effect's naming first: M-linear-deadzone.json is an effect refit of M-linear.json where that exists
    assert found("m-linear-deadzone.json", ["envelope", "deadzone"], "linear") == tmp_path / "m-linear.json"
    (tmp_path / "m-linear.json").unlink()
    assert found("m-linear-deadzone.json", ["envelope", "deadzone"], "linear") == tmp_path / "m.json"
    assert found("m-linear-load-col-all.json", ["load:col"], "linear") == tmp_path / "m.json"
    assert found("m.json", ["envelope"], "pi") is None and found("x-pi.json", [], "pi") is None  # no x.json


def test_a_subsampled_scan_promises_the_range_its_refit_on_every_sample_lands_in():
    """The scan fits its candidates on 1 estimation sample in N; the refit fits every sample. The
    promise then gives a range (the candidate fitted on two interleaved subsamples, widened by half
    their gap), and the refit the suggestion names, fitted on every sample, lands in it, give or
    take 2 % (the noise of one fit's end point: two draws pin a spread only roughly)."""
    import numpy as np

    from endocal.models import HysteresisData, make_model
    from endocal.validation.offline import validate_offline
    from endocal.validation.predict import predict_errors

    def data(seed, kind):
        df = tendon_log(seed, kind, duration_s=40.0)
        return HysteresisData(cmd_deg=df["Tendon Disp."].to_numpy(), meas_deg=df["Angle y"].to_numpy(),
                              t_s=df["Time"].to_numpy(), drive_unit="mm")

    fit, check = data(5, "damped"), data(6, "chirp")
    model = make_model("linear", axis="ap").fit(fit)
    result = validate_offline(model, check, train=fit, max_scan_samples=700, model_path="m.json")
    assert result.scan.stride == 3, result.scan.stride
    s = result.suspects[0]
    lo, hi = s.refit.expected_rmse_deg
    assert s.refit.scan_stride == 3 and lo <= s.rmse_heldout_deg <= hi
    p = s.refit
    refit = make_model(p.base, list(p.effects), **p.settings, axis=p.axis).fit_from(model, fit)
    rmse = float(np.sqrt(np.mean(predict_errors(refit, check) ** 2)))
    assert 0.98 * lo <= rmse <= 1.02 * hi, (rmse, lo, hi, s.rmse_heldout_deg)
    # the promise in words: the subsampled note says what to expect
    note = next(n for n in result.notes if getattr(n, "key", "") == "subsampled")
    assert f"{lo:.3g} .. {hi:.3g} deg" in note, note


def test_a_subsampled_scan_promises_a_base_change_the_range_its_refit_lands_in():
    """The same for a base change: fitted on 1 estimation sample in 3 (the Bouc-Wen plant's records of
    tests/test_validation_bases.py, a B-spline model), the change to a base without return-point memory comes
    with the range to expect, in its line too, and its refit on every sample, from the model as the printed
    --start-from starts it, lands in it give or take 2 %."""
    import numpy as np

    from endocal.models import make_model
    from endocal.validation.offline import validate_offline
    from endocal.validation.predict import predict_errors
    from tests.test_validation_bases import _plant, _records

    est, val = _records(_plant("bouc-wen"))
    model = make_model("bspline", axis="ap").fit(est)
    result = validate_offline(model, val, train=est, max_scan_samples=300, model_path="m.json", n_boot=50)
    change = result.scan.base_suggestions[0]
    lo, hi = change.refit.expected_rmse_deg
    assert change.refit.scan_stride == 3 and lo <= change.rmse_heldout_deg <= hi
    assert change.line().endswith(f", its refit on every sample expected at {lo:.3g} .. {hi:.3g} deg"), change.line()
    refit = make_model(change.base, list(change.refit.effects), axis="ap").fit_from(model, est)
    rmse = float(np.sqrt(np.mean(predict_errors(refit, val) ** 2)))
    assert 0.98 * lo <= rmse <= 1.02 * hi, (rmse, lo, hi, change.rmse_heldout_deg)


def test_the_refit_keeps_the_structure_the_fit_resolved():
    """A `weights="auto"` PI fitted as `exponential` (the paper's law, with the envelope) is refitted as
    `exponential`: the scan's candidates (`template`) and the printed refit (`Refit.settings`, as
    `--set weights=exponential --set offset=false`) take the resolved settings, never "auto" again."""
    from endocal.models import make_model
    from endocal.validation.refit import suggest_refit
    from endocal.validation.structure import resolved_settings, template
    from tests._models_signals import PAPER_TABLE1

    model = make_model("pi", ["envelope"], axis="ap").set_parameters(PAPER_TABLE1)
    assert model.get_settings()["weights"] == "auto" and model.structure_["weights"] == "exponential"
    assert resolved_settings(model) == {"n_operators": 20, "weights": "exponential", "offset": False}
    assert template(model, ["envelope", "delay"]).weights == "exponential"
    refit = suggest_refit(model, "delay", ["fit.csv"], model_path="m.json")
    assert refit.settings == {"weights": "exponential", "offset": False}
    from endocal.shell import refit_argv

    argv = refit_argv(refit)
    assert argv[argv.index("--set") + 1] == "weights=exponential" and "offset=false" in argv
    from endocal.protocols import parse_overrides

    assert parse_overrides([a for a in argv if "=" in a]) == refit.settings  # read back as written


def test_a_setting_the_base_lacks_is_one_line(tmp_path):
    from tests._cli import one_line_exit_2

    df = tendon_log(1, "damped", duration_s=10.0)
    pd.DataFrame({"t_s": df["Time"], "ap_cmd_mm": df["Tendon Disp."], "ap_meas_deg": df["Angle y"]}).to_csv(
        tmp_path / "fit.csv", index=False)
    one_line_exit_2(endocal("fit", "hysteresis", tmp_path / "fit.csv", "--axis", "ap", "--model", "linear", "--set",
                            'weights="exponential"', "--out", tmp_path / "x.json"),
                    "--set weights", "model 'linear' has no such setting")


@pytest.mark.slow
@pytest.mark.parametrize("hidden", ["drift", "delay", "rate", "creep", "load", "deadzone", "envelope", "coupling"])
def test_every_hidden_effect_suggestion_delivers_what_validate_promised(hidden, tmp_path):
    from tests.test_validation_hidden import CASES, NO_SLACK, SimConfig, simulate

    sections, protocol, overrides, n_runs, base, effects = CASES[hidden]
    cfg = SimConfig.default().replace(**NO_SLACK).replace(**sections)
    paths = []
    for seed in range(n_runs):
        aligned, _ = simulate(cfg, protocol, overrides, seed=seed)
        paths.append(tmp_path / f"{protocol}-{seed}.csv")
        aligned.table.to_csv(paths[-1], index=False)
    proc = endocal("fit", "hysteresis", *paths, "--axis", "ap", "--model", base,
                   *(["--effects", ",".join(effects)] if effects else []), "--out", tmp_path / "m.json")
    assert proc.returncode == 0, proc.stderr
    keep_promises(tmp_path / "m.json", paths, tmp_path)


def test_a_searched_starts_refit_keeps_its_promise_and_its_second_start_never_loses(tmp_path):
    """The stress run's broken promise (scripts/stress_promises.py seed 30, 2026-12-05): a linear drive whose tip
    lags through one smooth friction element, fitted with `bouc-wen`. `validate` suggests `deadzone:tip` (-11 %,
    fitted on 1 sample in 3). Its refit on every sample, searching the slack's start afresh, picked another start
    and stopped in a worse minimum: 0.171 deg training RMSE against the 0.158 of the scan's values, -7 % on the
    validation record, under 75 % of the promise. The printed command gives the scan candidate's values as a
    second start (`--start-value`), kept where it ends lower: the promise is kept, and without those options the
    same command broke it. On 2026-12-07 (and already at abd3083, before the friction forms) the case differs:
    `deadzone:tip` gains the same -11 % at p = 0.063 (Holm), so it is listed with its refit, not suggested, and the
    refit's own search now reaches the scan's minimum too (both deliver -11.4 %). What still holds, and is asserted:
    the printed refit keeps the promise, and the second start never leaves it worse than the search alone (the fit
    keeps the lower of the two: tests/test_cli_fit_hysteresis.py)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("stress_promises", ROOT / "scripts" / "stress_promises.py")
    stress = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(stress)
    case = stress.make_case(30, tmp_path)
    assert case["base"] == "bouc-wen" and not case["effects"]  # the case as the stress run drew it
    model = tmp_path / "m.json"
    assert endocal("fit", "hysteresis", *case["fit"], "--axis", "ap", "--model", "bouc-wen",
                   "--out", model).returncode == 0
    d, _ = _validate(model, case["check"], tmp_path / "v.json")
    s = next(x for x in d["scan"]["tested"] if x["effect"] == "deadzone:tip")
    assert set(s["refit"]["start_values"]) == {"deadzone_tip_slack_deg", "deadzone_tip_band_deg",
                                               "deadzone_tip_center_deg"}
    # an effect without a start search (the envelope's start is its hinge fit, on either side) gets none
    assert all(x["refit"]["start_values"] == {} for x in d["suspects"] if x["effect"] in ("envelope", "envelope:tip"))
    argv = shlex.split(s["command"])
    delivered = {}
    for how, args in (("printed", argv), ("own search only", [a for i, a in enumerate(argv) if not (
            a == "--start-value" or (i > 0 and argv[i - 1] == "--start-value"))])):
        assert endocal(*args[1:], "--force").returncode == 0
        d2, _ = _validate(Path(argv[-1]), case["check"], tmp_path / "v2.json")
        delivered[how] = -d2["compare"]["change_pct"]
    assert delivered["printed"] >= KEPT * s["gain_pct"], (s["gain_pct"], delivered)
    # on the validation record, within the rounding of the two fits' ends (0.1 % of the RMSE)
    assert delivered["printed"] >= delivered["own search only"] - 0.1, (s["gain_pct"], delivered)
