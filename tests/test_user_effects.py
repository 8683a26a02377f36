"""A user's own effects (issue 31, parts 2 and 3): loaded from a file, checked, used by the loop.

`endocal/models/userfile.py` loads `--effects-file FILE.py` and the `endocal.effects` entry points;
every bad input is one line naming the file and the effect, exit code 2, nothing written. Model
files record each user effect's file and SHA-256. The worked example of the how-to
(examples/effects/tendon_wear.py: the knob's gain falls with its cumulative travel) is hidden in
the simulator by the same file, recorded as a user records, named by `validate`, and its refit
brings the validation error to the tracker noise.
"""

from __future__ import annotations

import functools
import json
import shutil
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from endocal.errors import ConfigError, ModelError
from endocal.models import EFFECTS, load_model, make_model, save_model
from endocal.models.data import HysteresisData
from endocal.models.registry import BASES
from endocal.models.userfile import (EffectFileError, EffectFileWarning, file_sha256, forget_user_classes,
                                     load_effects_files, source_of)
from endocal.sim import SimConfig
from tests._cli import ROOT, endocal, one_line_exit_2

WEAR = ROOT / "examples" / "effects" / "tendon_wear.py"
PLANT = ROOT / "examples" / "effects" / "wear-plant.toml"
#: the worked examples: effect name -> (its file, the sim config that hides it, its true parameter)
EXAMPLES = {"wear": (WEAR, PLANT, ("wear_per_kdeg", 0.08)),
            "stickslip": (ROOT / "examples" / "effects" / "stick_slip.py",
                          ROOT / "examples" / "effects" / "stickslip-plant.toml", ("stickslip_deg", 10.0))}
#: the worked example's fits see every FIT_STRIDE-th sample (:func:`_recorded`)
FIT_STRIDE = 4


@pytest.fixture(autouse=True)
def _catalogue_as_shipped():
    """Every test starts and ends with the catalogue as shipped (user classes are process-wide)."""
    forget_user_classes()
    yield
    forget_user_classes()


# A complete effect of one's own; the bad inputs below each change one thing.
GOOD = '''
import numpy as np
from endocal.models.effects.base import InputEffect
from endocal.models.params import Parameter


class Gain(InputEffect):
    name = "mygain"
    cause = "a pulley of another radius"
    signature = "residual proportional to the command"
    protocol = "large slow cycles"
    units = {"k": ""}
    requires = ()
    residual = ()
    lookalikes = {}

    def initial(self, data, u):
        return [Parameter(f"{self.prefix}_k", 1.0, 0.5, 2.0)]

    def apply(self, p, u, data):
        return p["k"] * u

    def invert(self, p, v, data):
        return v / p["k"]

    def describe(self, p, se):
        return "mygain" + self._bracket(p, se)
'''

BAD = {
    "syntax error": (GOOD.replace("def apply(self, p, u, data):", "def apply(self, p, u, data)"), "syntax error at line"),
    "a missing declaration": (GOOD.replace("    residual = ()\n", ""), "no 'residual'"),
    "a name of the catalogue's": (GOOD.replace('name = "mygain"', 'name = "delay"'), "clashes with the catalogue's 'delay'"),
    "parameters without bounds": (GOOD.replace("Parameter(f\"{self.prefix}_k\", 1.0, 0.5, 2.0)",
                                               "Parameter(f\"{self.prefix}_k\", 1.0)"), "parameters without bounds: k"),
    "a predict of NaN": (GOOD.replace("return p[\"k\"] * u", "return p[\"k\"] * u * np.nan"), "NaN"),
    "a predict of the wrong length": (GOOD.replace("return p[\"k\"] * u", "return p[\"k\"] * u[1:]"), "shape"),
    "an inverse that does not invert": (GOOD.replace("return v / p[\"k\"]", "return v / p[\"k\"] + 1.0"), "does not invert"),
    "an implausible() that is not words": (GOOD.replace("    def describe(self, p, se):",
                                                       "    def implausible(self, p, data):\n        return None\n\n"
                                                       "    def describe(self, p, se):"), "not a string"),
    "a file that raises": (GOOD + "\nraise RuntimeError('lab path not set')\n", "RuntimeError: lab path not set"),
}


def _write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


@pytest.fixture(scope="module")
def small_table(tmp_path_factory) -> Path:
    """A 30 s aligned table of one axis (a damped sine through a 3 deg play): enough to fit a line."""
    t = np.arange(3000) / 100.0
    cmd = 40.0 * np.exp(-t / 20.0) * np.sin(2 * np.pi * 0.2 * t)
    y, meas = 0.0, np.empty_like(cmd)
    for i, c in enumerate(cmd):
        y = min(max(y, c - 3.0), c + 3.0)
        meas[i] = 0.8 * y
    path = tmp_path_factory.mktemp("records") / "sine.csv"
    pd.DataFrame({"t_s": t, "ap_cmd_deg": cmd, "ap_meas_deg": meas}).to_csv(path, index=False)
    return path


# ---------------------------------------------------------------------------------------------- loading
def test_a_file_registers_its_effect_as_the_users():
    (cls,) = load_effects_files([WEAR])
    assert EFFECTS["wear"] is cls and cls.name == "wear"
    src = source_of(cls)
    assert src.path == str(WEAR.resolve()) and src.sha256 == file_sha256(WEAR) and src.given
    assert source_of(EFFECTS["delay"]) is None  # the catalogue's own are not the user's
    assert load_effects_files([WEAR]) == [cls]  # the same file again registers nothing new
    forget_user_classes()
    assert "wear" not in EFFECTS


def test_a_file_that_changed_replaces_its_classes(tmp_path):
    path = _write(tmp_path, "mine.py", GOOD)
    (old,) = load_effects_files([path])
    path.write_text(textwrap.dedent(GOOD).replace("a pulley of another radius", "a larger pulley"))
    (new,) = load_effects_files([path])
    assert new is not old and EFFECTS["mygain"] is new and new.cause == "a larger pulley"


def test_effects_lists_the_users_marked(tmp_path):
    proc = endocal("effects", "--effects-file", WEAR)
    assert proc.returncode == 0, proc.stderr
    assert f"wear (input term, yours: {WEAR.resolve()})" in proc.stdout
    assert "delay (input term)" in proc.stdout
    proc = endocal("effects", "--json", "--effects-file", WEAR)
    entries = {e["name"]: e for e in json.loads(proc.stdout)["effects"]}
    assert entries["wear"]["source"]["sha256"] == file_sha256(WEAR) and entries["delay"]["source"] is None


def test_an_entry_point_registers_a_packaged_effect(tmp_path, monkeypatch):
    """A lab's package lists its effects under the `endocal.effects` entry-point group."""
    (tmp_path / "labfx.py").write_text(textwrap.dedent(GOOD))
    info = tmp_path / "labfx-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: labfx\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[endocal.effects]\nmygain = labfx\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    load_effects_files([])
    src = source_of(EFFECTS["mygain"])
    assert src.module == "labfx" and src.path == str((tmp_path / "labfx.py").resolve()) and not src.given
    t = np.arange(1000) / 100.0
    cmd = 30.0 * np.sin(2 * np.pi * 0.5 * t)
    path = tmp_path / "m.json"
    save_model(make_model("linear", ["mygain"], axis="ap").fit(HysteresisData(cmd_deg=cmd, meas_deg=0.8 * cmd, t_s=t)),
               path)
    assert load_model(path).effects_[0].name == "mygain"
    # the installed package changed since the fit: refused, unless its file is given
    (tmp_path / "labfx.py").write_text(textwrap.dedent(GOOD) + "\n# version 2\n")
    monkeypatch.delitem(sys.modules, "labfx")
    forget_user_classes()
    with pytest.raises(EffectFileError, match="changed since .*m.json was fitted .*and was not given: give it with "
                                              "--effects-file"):
        load_model(path)
    load_effects_files([tmp_path / "labfx.py"])
    with pytest.warns(EffectFileWarning, match="labfx.py changed since"):
        load_model(path)
    monkeypatch.delitem(sys.modules, "labfx")


def test_the_api_takes_the_class_itself(small_table):
    import endocal as ec
    from endocal.models.userfile import register_user_class

    ns: dict = {}
    exec(compile(textwrap.dedent(GOOD), "<notebook>", "exec"), ns)  # a class a notebook defines
    cls = ns["Gain"]
    m = ec.fit([small_table], axis="ap", model="linear", effects=[cls])
    assert m.effects == ["mygain"] and EFFECTS["mygain"] is cls
    assert register_user_class(cls) is cls  # again: nothing new
    m = ec.fit([small_table], axis="ap", model="linear", effects=["wear"], effects_file=WEAR)
    assert m.effects == ["wear"] and source_of(EFFECTS["wear"]).path == str(WEAR.resolve())


# ---------------------------------------------------------------------------------------------- bad input
def test_a_missing_effects_file_is_one_line(tmp_path, small_table):
    out = tmp_path / "m.json"
    proc = endocal("fit", "hysteresis", small_table, "--axis", "ap", "--model", "linear", "--out", out,
                   "--effects-file", tmp_path / "nowhere.py")
    one_line_exit_2(proc, "nowhere.py does not exist")
    assert not out.exists()


@pytest.mark.parametrize("case", list(BAD))
def test_a_bad_effect_file_is_one_line_naming_the_file_and_the_effect(case, tmp_path, small_table):
    text, fragment = BAD[case]
    path = _write(tmp_path, "mine.py", text)
    out = tmp_path / "m.json"
    proc = endocal("fit", "hysteresis", small_table, "--axis", "ap", "--model", "linear", "--out", out,
                   "--effects-file", path)
    named = () if case in ("syntax error", "a file that raises") else ("effect '",)
    one_line_exit_2(proc, str(path), fragment, *named)
    assert not out.exists()
    assert "mygain" not in EFFECTS  # nothing half registered


def test_two_files_with_one_name_clash(tmp_path, small_table):
    a = _write(tmp_path, "a.py", GOOD)
    b = _write(tmp_path, "b.py", GOOD.replace("a pulley of another radius", "another cause"))
    out = tmp_path / "m.json"
    proc = endocal("fit", "hysteresis", small_table, "--axis", "ap", "--model", "linear", "--out", out,
                   "--effects-file", a, "--effects-file", b)
    one_line_exit_2(proc, str(b), "effect 'mygain' clashes with the effect 'mygain' of", str(a.resolve()))
    assert not out.exists()


def test_a_base_whose_inverse_does_not_converge_is_refused(tmp_path):
    text = '''
    from endocal.models.linear import LinearModel

    class Broken(LinearModel):
        base_name = "brokenline"

        def _base_inverse(self, structure, p, y, run_starts, v_range):
            return y * 0.0 + v_range[0]
    '''
    path = _write(tmp_path, "base.py", text)
    with pytest.raises(EffectFileError, match="base 'brokenline': its inverse does not converge on a sweep"):
        load_effects_files([path])
    assert "brokenline" not in BASES
    good = _write(tmp_path, "base2.py", text.replace("brokenline", "myline").split("        def _base_inverse")[0])
    load_effects_files([good])
    assert BASES["myline"].__name__ == "Broken" and make_model("myline").base_name == "myline"


# ---------------------------------------------------------------------------------------------- model files
def _wear_model(path: Path):
    """A model with the user's wear effect, fitted on a short record of a plant that has it."""
    load_effects_files([path])
    t = np.arange(4000) / 100.0
    cmd = 40.0 * np.sin(2 * np.pi * 0.5 * t)
    travel = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(cmd)))])
    meas = 0.8 * cmd * (1.0 - 0.05 * travel / 1000.0)
    return make_model("linear", ["wear"], axis="ap").fit(HysteresisData(cmd_deg=cmd, meas_deg=meas, t_s=t))


def test_model_files_record_the_users_file_and_refuse_it_missing_or_changed(tmp_path, small_table):
    mine = tmp_path / "wear.py"
    shutil.copy(WEAR, mine)
    model = _wear_model(mine)
    assert model.params_["wear_per_kdeg"] == pytest.approx(0.05, rel=0.02)
    path = tmp_path / "m.json"
    save_model(model, path)
    entry = json.loads(path.read_text())["effects"][0]
    assert entry["source"] == {"path": str(mine.resolve()), "module": "wear", "sha256": file_sha256(mine)}
    again = load_model(path)  # the file is registered: the same model back
    assert again.params_ == model.params_

    forget_user_classes()  # a new session, without the file
    with pytest.raises(EffectFileError, match=f"effect 'wear' comes from {mine.resolve()}: give the file"):
        load_model(path)
    proc = endocal("validate", path, small_table)
    one_line_exit_2(proc, str(path), f"--effects-file {mine.resolve()}")

    mine.write_text(mine.read_text() + "\n# retuned\n")  # the file changed since the fit
    proc = endocal("validate", path, small_table)
    one_line_exit_2(proc, "which changed since the model was fitted", f"--effects-file {mine.resolve()}")
    load_effects_files([mine])  # given anyway: a warning naming the change
    with pytest.warns(EffectFileWarning, match=r"effect 'wear': .*wear.py changed since .*m.json was fitted"):
        load_model(path)

    mine.unlink()
    forget_user_classes()
    with pytest.raises(EffectFileError, match="which does not exist"):
        load_model(path)


def test_a_users_base_is_recorded_and_needed_like_an_effect(tmp_path, small_table):
    mine = _write(tmp_path, "mybase.py", '''
    from endocal.models.linear import LinearModel

    class MyLine(LinearModel):
        base_name = "myline"
    ''')
    load_effects_files([mine])
    path = tmp_path / "m.json"
    out = endocal("fit", "hysteresis", small_table, "--axis", "ap", "--model", "myline", "--out", path,
                  "--effects-file", mine)
    assert out.returncode == 0, out.stderr
    assert json.loads(path.read_text())["base_source"]["sha256"] == file_sha256(mine)
    forget_user_classes()
    with pytest.raises(EffectFileError, match=f"base 'myline' comes from {mine.resolve()}: give the file"):
        load_model(path)
    one_line_exit_2(endocal("validate", path, small_table), f"base 'myline' comes from {mine.resolve()}")


def test_export_reads_the_model_with_the_file(tmp_path):
    path = tmp_path / "m.json"
    save_model(_wear_model(WEAR), path)
    forget_user_classes()
    one_line_exit_2(endocal("export", "c", path, "--out", tmp_path / "c"), "effect 'wear' comes from")
    # with the file the model loads, and the C export says what it covers
    one_line_exit_2(endocal("export", "c", path, "--out", tmp_path / "c", "--effects-file", WEAR),
                    "effect 'wear' streams in Python but has no C code generator")
    assert not (tmp_path / "c").exists()


def test_the_inverse_compensates_with_the_users_effect(tmp_path):
    model = _wear_model(WEAR)
    t = np.arange(3000) / 100.0
    desired = 25.0 * np.sin(2 * np.pi * 0.3 * t)
    cmd = model.inverse(desired, t_s=t)
    assert np.max(np.abs(model.predict(cmd, t_s=t) - desired)) < 1e-6  # the travel the inverse adds is its own


def test_compensation_refuses_an_effect_without_inverse(tmp_path):
    load_effects_files([EXAMPLES["stickslip"][0]])
    t = np.arange(2000) / 100.0
    cmd = 30.0 * np.sin(2 * np.pi * 0.4 * t)
    model = make_model("linear", ["stickslip"], axis="ap").fit(HysteresisData(cmd_deg=cmd, meas_deg=0.8 * cmd, t_s=t))
    with pytest.raises(ModelError, match="effect 'stickslip' has no inverse"):
        model.inverse(0.5 * cmd, t_s=t)


# ---------------------------------------------------------------------------------------------- simulator
def test_a_sim_config_hiding_an_effect_needs_its_file():
    with pytest.raises(ConfigError, match=r"\[user_effects.wear\] names an effect no --effects-file provides"):
        SimConfig.from_toml(PLANT)
    load_effects_files([WEAR])
    cfg = SimConfig.from_toml(PLANT)
    assert cfg.user_effects == {"wear": {"per_kdeg": 0.08, "axes": ["axis1"]}}
    assert "wear" in cfg.effects_enabled()
    with pytest.raises(ConfigError, match="unknown key 'user_effects.wear.k'"):
        cfg.replace(user_effects={"wear": {"k": 1.0}})
    assert SimConfig.default().config_hash() == SimConfig.from_dict({}).config_hash()


def test_the_simulator_hides_an_effect_by_its_simulate_hook(tmp_path):
    """An effect that says how the plant produces it (``simulate(data, rng)``): here a 2 deg offset of the angle."""
    from endocal.probe import load_probe
    from endocal.protocols import load_protocol
    from endocal.sim import Simulator

    path = _write(tmp_path, "offset.py", '''
    from endocal.models.effects.base import OutputEffect
    from endocal.models.params import Parameter


    class Offset(OutputEffect):
        name = "offsetfx"
        depends_on_command = False
        cause = "a tracker sensor glued askew"
        signature = "a constant residual"
        protocol = "any record"
        units = {"deg": "deg"}
        requires = ()
        residual = ()
        lookalikes = {}

        def initial(self, data, u):
            return [Parameter(f"{self.prefix}_deg", 0.0, -10.0, 10.0)]

        def term(self, p, cmd, data):
            return p["deg"] + 0.0 * cmd

        def describe(self, p, se):
            return "offsetfx" + self._bracket(p, se)

        def simulate(self, data, rng):
            return data.meas_deg + 2.0
    ''')
    load_effects_files([path])
    tee = load_probe("tee")
    traj = load_protocol("sine", overrides={"cycles": 1, "amplitude_deg": 20.0}).trajectory(tee, seed=0)
    cfg = SimConfig.default().replace(deviation_deg={"y+": 0.0, "y-": 0.0, "x+": 0.0, "x-": 0.0})  # in-plane bends
    hidden = cfg.replace(user_effects={"offsetfx": {"deg": 0.0, "axes": ["axis1"]}})
    a = Simulator(hidden, tee, seed=0).execute(traj.t_s, traj.goal).truth
    b = Simulator(cfg, tee, seed=0).execute(traj.t_s, traj.goal).truth
    # an in-plane bend: the eq.-1 angle is half the bend, so 2 deg of angle is 4 deg of bend, read back as 2
    assert np.allclose(a["ap_true_deg"] - b["ap_true_deg"], 2.0, atol=1e-6)
    assert np.allclose(a["ml_true_deg"], b["ml_true_deg"], atol=1e-9)  # the other axis untouched (rounding of 1e-15)


def test_the_simulator_hides_the_effect_the_same_in_chunks():
    from endocal.probe import load_probe
    from endocal.protocols import load_protocol
    from endocal.sim import Simulator

    load_effects_files([WEAR])
    tee = load_probe("tee")
    cfg = SimConfig.from_toml(PLANT)
    traj = load_protocol("sine", overrides={"cycles": 3}).trajectory(tee, seed=0)
    whole = Simulator(cfg, tee, seed=0).execute(traj.t_s, traj.goal)
    sim, parts = Simulator(cfg, tee, seed=0), []
    for sl in (slice(0, 700), slice(700, None)):
        parts.append(sim.execute(traj.t_s[sl], {k: v[sl] for k, v in traj.goal.items()}))
    a = whole.truth["ap_true_deg"]
    assert np.array_equal(a, np.concatenate([p.truth["ap_true_deg"] for p in parts]))
    without = SimConfig.from_dict({k: v for k, v in cfg.to_dict().items() if k != "user_effects"})
    plain = Simulator(without, tee, seed=0).execute(traj.t_s, traj.goal)
    # the goal is logged as written; the bend answers a knob whose gain has fallen by 8 % per 1000 deg travelled
    assert np.array_equal(whole.motor["ap_goal_deg"], plain.motor["ap_goal_deg"])
    late = slice(-200, None)
    ratio = np.max(np.abs(a[late])) / np.max(np.abs(plain.truth["ap_true_deg"][late]))
    travel = np.abs(np.diff(traj.goal["ap"])).sum()
    assert ratio == pytest.approx(1.0 - 0.08 * travel / 1000.0, abs=0.03)


# ---------------------------------------------------------------------------------------------- the worked example
def test_excite_hides_the_effect_from_the_file(tmp_path):
    out = tmp_path / "run"
    proc = endocal("excite", "sine", "--sim-config", PLANT, "--set", "cycles=2", "--out", out, "-q")
    one_line_exit_2(proc, str(PLANT), "[user_effects.wear]", "--effects-file")
    assert not out.exists()
    proc = endocal("excite", "sine", "--sim-config", PLANT, "--set", "cycles=2", "--out", out, "-q",
                   "--effects-file", WEAR)
    assert proc.returncode == 0, proc.stderr
    run = json.loads((out / "run.json").read_text())
    assert run["backend"]["config"]["user_effects"] == {"wear": {"per_kdeg": 0.08, "axes": ["axis1"]}}


@functools.lru_cache(maxsize=2)
def _recorded(example: str):
    """The how-to's plant of ``example`` (its sim config), recorded as a user records: a damped sine and a
    chirp to fit, a random run to validate; and the thesis's B-spline carrying the rig's delay, fitted on
    the first two.

    Kept quick: the chirp and the random run last 60 s (not 120), and the fits see every 4th sample
    (25 Hz, 10 times the fastest motion's bandwidth); validation scores all 6001 samples."""
    from endocal.validation.data import axis_data
    from tests.test_validation_hidden import simulate

    path, plant, _ = EXAMPLES[example]
    load_effects_files([path])
    cfg = SimConfig.from_toml(plant)
    est = [simulate(cfg, "damped-sine", {}, seed=0)[0],
           simulate(cfg, "chirp", {"amplitude_deg": 50.0, "duration_s": 60.0}, seed=0)[0]]
    val, noise = simulate(cfg, "random", {"amplitude_deg": 60.0, "duration_s": 60.0}, seed=0)
    train = axis_data(est, "ap").decimate(FIT_STRIDE)
    return est, train, val, noise, make_model("bspline", ["delay"], axis="ap").fit(train)


def _worked_example(example: str, with_file: bool):
    """validate on the random run, with the user's file loaded or not (the user has not written it yet)."""
    from endocal.validation.offline import validate_offline

    est, train, val, noise, model = _recorded(example)
    forget_user_classes()
    if with_file:
        load_effects_files([EXAMPLES[example][0]])
    res = validate_offline(model, [val], train=est, model_path="m.json", max_scan_samples=2000)
    return res, train, val, noise


def _named_and_refitted(example: str):
    """The example's effect is named first and significant; its refit halves the validation error or brings
    it within 1.15x the noise (the issue's bar); the fitted parameter is the plant's within 10 % (the
    bend's capstan friction is not exactly the B-spline's loop). Returns the numbers."""
    from endocal.validation.data import axis_data
    from endocal.validation.predict import predict_extrapolated

    res, train, val, noise = _worked_example(example, with_file=True)
    first = res.scan.suspects[0]
    assert first.effect == example and first.significant, [(s.effect, round(s.gain_pct, 1)) for s in res.scan.tested]
    refit = make_model("bspline", ["delay", example], axis="ap").fit(train)
    v = axis_data([val], "ap")
    after = float(np.sqrt(np.mean((predict_extrapolated(refit, v)[0] - v.meas_deg) ** 2)))  # as validate scores it
    before = res.scan.baseline_rmse_heldout_deg
    assert after <= 0.5 * before or after <= 1.15 * noise, (before, after, noise)
    name, true = EXAMPLES[example][2]
    assert refit.params_[name] == pytest.approx(true, rel=0.1)
    return before, first.gain_pct, after, noise, refit.params_[name]


def test_validate_names_the_users_effect_and_its_refit_reaches_the_noise():
    """Measured (seed 0, 2026-11-28): validation RMSE 0.760 deg, `wear` -56 % (p = 0.00035), the refit 0.333 deg
    against the tracker's 0.331 deg noise (1.01x), wear 0.0809 /kdeg for the plant's 0.08."""
    _named_and_refitted("wear")


@pytest.mark.slow
def test_the_stick_slip_example_is_named_and_refitted():
    """The second worked example (examples/effects/stick_slip.py, a 10 deg stick at every reversal).
    Measured (seed 0, 2026-11-28): validation RMSE 1.10 deg, `stickslip` -68 % (p = 0.00035), the refit
    0.348 deg against the tracker's 0.332 deg noise (1.05x), slip 10.03 deg for the plant's 10. Slow (a minute):
    the scan and the refit run the compiled reversal loop on every evaluation."""
    _named_and_refitted("stickslip")


def test_without_the_file_the_summary_says_the_residual_follows_the_loop():
    res, _, _, _ = _worked_example("wear", with_file=False)
    assert "wear" not in {s.effect for s in res.scan.tested}
    assert not any(s.significant for s in res.scan.suspects)
    assert "follows the loop" in res.unexplained and "docs/how-to/add-effect.md" in res.unexplained


def test_next_designs_the_users_segment_or_says_its_experiment_in_words(tmp_path):
    """Estimation data that cannot show either example (one cycle: two reversals, 160 deg of travel): `--next`
    designs the stick-slip's own segment (small sines) and says the wear's experiment in words (it has none)."""
    from endocal.validation.data import axis_data
    from endocal.validation.next_experiment import write_next
    from endocal.validation.offline import validate_offline
    from tests.test_validation_hidden import simulate

    load_effects_files([WEAR, EXAMPLES["stickslip"][0]])
    cfg = SimConfig.default().replace(deadzone={"enabled": False})
    est = [simulate(cfg, "sine", {"cycles": 1, "amplitude_deg": 40.0}, seed=0)[0]]
    val = simulate(cfg, "random", {"amplitude_deg": 40.0, "duration_s": 30.0}, seed=0)[0]
    model = make_model("linear", ["delay"], axis="ap").fit(axis_data(est, "ap"))
    res = validate_offline(model, [val], train=est, model_path="m.json", max_scan_samples=1000)
    assert "travel" in res.scan.untestable["wear"] and "reverse the knob" in res.scan.untestable["stickslip"]
    out = write_next(model, res, [val], est, None, tmp_path / "next.toml", model_path="m.json")
    tests = {t.effect: t for t in out.experiment.tests}
    seg = out.experiment.protocol.to_dict()["params"]["segments"][tests["stickslip"].segment - 1]
    assert seg["signal"] == "sine" and seg["amplitude_deg"] == pytest.approx(10.0)
    assert any(n.startswith("wear: no segment of its own; record a long record of large cycles")
               for n in out.experiment.notes), out.experiment.notes


def test_the_commands_validate_prints_give_the_users_file_again():
    from endocal.shell import effects_file_args
    from endocal.shell import refit_command
    from endocal.validation.refit import Refit

    load_effects_files([WEAR])
    refit = Refit(data_paths=("runs/train",), axis="ap", base="bspline", effects=("delay", "wear"),
                  out_path="m-wear.json", start_from="m.json")
    assert f"--effects-file {WEAR.resolve()} --out m-wear.json" in refit_command(refit)
    catalogue_only = Refit(data_paths=("runs/train",), axis="ap", base="bspline", effects=("delay",), out_path="x.json")
    assert "--effects-file" not in refit_command(catalogue_only)
    assert effects_file_args() == ["--effects-file", str(WEAR.resolve())]  # validate ... --next repeats them
