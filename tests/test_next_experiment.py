"""`endocal validate ... --next NEXT.toml` (endocal/validation/next_experiment.py): the protocol that settles
what validate could not, written as an ordinary protocol file, run by `excite` on the simulator and the
emulated rig.

The records are the user's of the closed loop (tests/test_validation_closed_loop.py), shortened: the
duodenoscope paper's damped sine and a chirp to fit on, a band-limited random run to validate on, all
moving one knob on the default simulated probe, whose sheath wrap (180 deg) is logged constant. Such
data cannot show coupling (the other knob never moves), load (no condition varies) or creep (no holds),
and validate says so in words; --next must turn each into a segment or a condition.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from endocal.models import HysteresisData, load_model, make_model
from endocal.probe import PRESETS
from endocal.protocols import read_protocol_file
from endocal.runs.aligned import load_aligned, read_stream
from endocal.validation.next_experiment import (
    CONDITION,
    LIMIT_SHARE,
    MIN_AMPLITUDE_DEG,
    design_next,
    motion_range,
)
from endocal.validation.power import units_for_power
from tests._cli import ROOT, endocal, one_line_exit_2

TEE = PRESETS["tee"]
RECORDS = {
    "est1": ["damped-sine", "--set", "period_s=10", "--seed", "0"],
    "est2": ["chirp", "--amplitude", "50", "--set", "duration_s=60", "--seed", "0"],
    "val": ["random", "--amplitude", "60", "--set", "duration_s=60", "--seed", "0"],
}


@pytest.fixture(scope="module")
def loop(tmp_path_factory):
    """The user's records, a B-spline with the rig's lag fitted on the estimation pair, and validate --next."""
    tmp = tmp_path_factory.mktemp("next")
    for name, args in RECORDS.items():
        assert endocal("excite", *args, "--out", tmp / name, "-q").returncode == 0
    fit = endocal("fit", "hysteresis", tmp / "est1", tmp / "est2", "--axis", "ap", "--model", "bspline", "--effects",
                  "delay", "--out", tmp / "m.json")
    assert fit.returncode == 0, fit.stderr
    proc = endocal("validate", tmp / "m.json", tmp / "val", "--next", tmp / "next.toml", "--json-out", tmp / "v.json")
    assert proc.returncode == 0, proc.stderr
    return tmp, proc


def test_validate_writes_a_protocol_for_what_the_records_cannot_show(loop):
    tmp, proc = loop
    proto = read_protocol_file(tmp / "next.toml")
    assert proto.signal == "sequence" and proto.design["axis"] == "ap"
    suspects = proto.design["suspects"]
    assert {"coupling", "creep", "load:sheath_wrap_deg"} <= set(suspects), suspects
    by_effect = {t["effect"]: t for t in proto.design["tests"]}
    segments = proto.params["segments"]
    # coupling: both knobs at once; creep: moves with a hold after each; load: the whole run at a new condition
    assert segments[by_effect["coupling"]["segment"] - 1]["signal"] == "lissajous"
    assert segments[by_effect["coupling"]["segment"] - 1]["axes"] == ["ap", "ml"]
    creep = segments[by_effect["creep"]["segment"] - 1]
    assert creep["signal"] == "staircase" and creep["steps"] == 1 and creep["hold_s"] >= 5.0
    assert "segment" not in by_effect["load:sheath_wrap_deg"]
    assert proto.conditions["sheath_wrap_deg"]["recorded"] == [180.0]
    # each test sized by the power calculation: the paired test at alpha / m with 80 % power when the
    # effect lowers every half-cycle's error by the same share, the model's spread at least CV 1
    n_min = units_for_power(1.0, 1.0, 0.05, 8)
    assert all(t["half_cycles"] >= n_min for t in proto.design["tests"]), proto.design["tests"]
    assert f"{n_min} half-cycles" in by_effect["coupling"]["sized"]
    # the validate output says what it tests and how to record it, twice
    assert "Next experiment written to" in proc.stdout and "coupling (untestable)" in proc.stdout
    # (the run folders beside the protocol file)
    assert f"endocal excite {tmp / 'next.toml'} --out {tmp / 'next-fit'} --set sheath_wrap_deg=VALUE" in proc.stdout
    assert f"--out {tmp / 'next-val'} --seed 1 --set sheath_wrap_deg=VALUE" in proc.stdout


def test_every_goal_stays_inside_the_fitted_range_and_the_probe_limits(loop):
    tmp, _ = loop
    model = load_model(tmp / "m.json")
    lo, hi = model.cmd_range_deg_
    proto = read_protocol_file(tmp / "next.toml")
    traj = proto.trajectory(TEE)
    traj.check_limits(TEE)  # what excite checks before anything moves
    ap, ml = traj.goal["ap"], traj.goal["ml"]
    assert lo - 1e-6 <= ap.min() and ap.max() <= hi + 1e-6
    # the full fitted range is swept (envelope), and the other knob moves for coupling
    assert ap.max() >= hi - 1e-3 and ap.min() <= lo + 1e-3 and np.ptp(ml) > 2 * MIN_AMPLITUDE_DEG
    speed = np.abs(np.diff(ap)) * traj.sample_rate_hz
    assert speed.max() <= LIMIT_SHARE * TEE.max_knob_speed_dps * (1 + 1e-6)


def test_excite_asks_for_the_condition_then_logs_it(loop):
    tmp, _ = loop
    one_line_exit_2(endocal("excite", tmp / "next.toml", "--out", tmp / "nope", "-q"),
                    "asks for the condition 'sheath_wrap_deg'", "earlier records hold 180",
                    "--set sheath_wrap_deg=VALUE")
    assert not (tmp / "nope").exists()
    proc = endocal("excite", tmp / "next.toml", "--out", tmp / "next-fit", "--set", "sheath_wrap_deg=120", "-q")
    assert proc.returncode == 0, proc.stderr
    table = load_aligned(tmp / "next-fit").table
    # the simulator models the condition: its wrap is the one given, and it logs it
    assert np.allclose(table["sheath_wrap_deg"], 120.0)
    meta = json.loads((tmp / "next-fit" / "run.json").read_text())
    assert meta["protocol"]["conditions"]["sheath_wrap_deg"]["value"] == 120.0
    assert meta["protocol"]["design"]["suspects"] == read_protocol_file(tmp / "next.toml").design["suspects"]
    assert meta["status"] == "complete"


def test_the_protocol_plays_on_the_emulated_rig(loop):
    """The whole protocol is limit-checked by excite on the rig's backend before torque goes on; its first
    seconds are played through the real dynamixel-sdk and Aurora SDK (it lasts minutes in real time), then
    Ctrl-C stops it cleanly: the condition is logged as a column by excite, the rig does not log it."""
    pytest.importorskip("sksurgerynditracker")
    from endocal.emulate.rig import EmulatedRig

    tmp, _ = loop
    events = []
    with EmulatedRig(TEE, seed=1, on_event=events.append) as rig:
        cfg = rig.write_config(tmp / "rig.toml")
        child = subprocess.Popen([sys.executable, "-m", "endocal", "excite", str(tmp / "next.toml"), "--backend",
                                  "hardware", "--hardware-config", str(cfg), "--out", str(tmp / "rig-run"),
                                  "--set", "sheath_wrap_deg=120", "-q"], cwd=ROOT, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 60
        while "servo 2 torque on" not in events and time.monotonic() < deadline and child.poll() is None:
            time.sleep(0.1)
        time.sleep(3.0)
        child.send_signal(signal.SIGINT)
        _, stderr = child.communicate(timeout=60)
        torque = rig.bus.torque()
    assert child.returncode == 130, stderr
    assert torque == {1: False, 2: False}
    meta = json.loads((tmp / "rig-run" / "run.json").read_text())
    assert meta["status"] == "interrupted" and meta["protocol"]["conditions"]["sheath_wrap_deg"]["value"] == 120.0
    motor = read_stream(tmp / "rig-run", "motor")
    assert len(motor) > 100 and np.allclose(motor["sheath_wrap_deg"], 120.0)


def test_a_load_condition_no_column_logs_is_asked_for_by_name(loop, tmp_path):
    tmp, _ = loop
    # the same records as a lab's CSV tables: no sheath wrap logged
    for name in RECORDS:
        table = load_aligned(tmp / name).table
        table.drop(columns=[c for c in table.columns if c == "sheath_wrap_deg"]).to_csv(tmp_path / f"{name}.csv",
                                                                                        index=False)
    proc = endocal("validate", tmp / "m.json", tmp_path / "val.csv", "--train", tmp_path / "est1.csv", "--train",
                   tmp_path / "est2.csv", "--next", tmp_path / "next.toml")
    assert proc.returncode == 0, proc.stderr
    proto = read_protocol_file(tmp_path / "next.toml")
    assert list(proto.conditions) == [CONDITION] and proto.conditions[CONDITION]["recorded"] == []
    assert "log it as a column of every record" in proto.conditions[CONDITION]["instruction"]
    assert f"--set {CONDITION}=VALUE" in proc.stdout
    one_line_exit_2(endocal("excite", tmp_path / "next.toml", "--out", tmp_path / "run", "-q"),
                    f"asks for the condition '{CONDITION}'", f"--set {CONDITION}=VALUE")


def test_a_fitted_range_no_motion_fits_in_is_refused_before_validating(loop, tmp_path):
    tmp, _ = loop
    # a lab's table cut to where the knob swings about 35 deg: the model never saw the knob at rest
    table = load_aligned(tmp / "val").table
    for name in ("off", "off-val"):
        t = table.copy()
        t["ap_cmd_deg"] = 35.0 + 0.3 * t["ap_cmd_deg"]
        t.to_csv(tmp_path / f"{name}.csv", index=False)
    assert endocal("fit", "hysteresis", tmp_path / "off.csv", "--axis", "ap", "--model", "bspline",
                   "--out", tmp_path / "m.json").returncode == 0
    lo, hi = load_model(tmp_path / "m.json").cmd_range_deg_
    start = time.monotonic()
    proc = endocal("validate", tmp_path / "m.json", tmp_path / "off-val.csv", "--next", tmp_path / "next.toml")
    one_line_exit_2(proc, f"fitted on commands in [{lo:.4g}, {hi:.4g}] deg", "rest position 0")
    assert not (tmp_path / "next.toml").exists() and proc.stdout == ""  # refused before any validation
    assert time.monotonic() - start < 30


def test_a_fitted_range_too_narrow_is_refused_naming_it():
    t = np.arange(0, 60, 0.01)
    u = 3.0 * np.sin(2 * np.pi * 0.1 * t)
    model = make_model("bspline", axis="ap").fit(HysteresisData(cmd_deg=u, meas_deg=0.5 * u, t_s=t))
    with pytest.raises(ValueError, match=r"fitted on commands in \[-3, 3\] deg.*too narrow for a sweep of \+-5 deg"):
        motion_range(model, TEE)
    with pytest.raises(ValueError, match="axis 'ap', which probe 'duodenoscope' does not have"):
        motion_range(model, PRESETS["duodenoscope"])



# ---------------------------------------------------------------------------- what --json and the API carry
#: The keys `validate --json` had before --next added its own (issue 27: add, never rename)
JSON_KEYS = {"axis", "model", "data", "metrics", "heldout_rmse_deg", "regimes", "residuals", "suspects", "scan",
             "scheme", "estimation", "pointers", "shift", "clean", "unexplained", "beyond_samples", "notes", "note_keys",
             "compare"}


def test_the_json_says_what_was_designed_and_how_to_record_it(loop):
    tmp, proc = loop
    d = json.loads((tmp / "v.json").read_text())
    assert set(d) == JSON_KEYS | {"next"}
    nx = d["next"]
    proto = read_protocol_file(tmp / "next.toml")
    assert nx["path"] == str(tmp / "next.toml") and nx["written"] and nx["nothing_suspected"] is None
    assert nx["suspects"] == proto.design["suspects"] and nx["probe"] == "tee"
    assert nx["duration_s"] == pytest.approx(proto.duration_s)
    # each effect: the half-cycles it gets, and what the paired test needs at the gain validate saw
    tested = {t["effect"]: t for t in d["scan"]["tested"]}
    for t in nx["tests"]:
        assert {"effect", "status", "half_cycles", "gain_pct", "needed_half_cycles", "needed"} <= set(t)
        seen = tested.get(t["effect"])
        if seen is None:  # coupling, load: these records cannot test them, so no gain was seen
            assert t["gain_pct"] is None and t["needed_half_cycles"] is None and t["needed"].startswith("no gain seen")
            continue
        assert t["gain_pct"] == pytest.approx(seen["gain_pct"])
        units = seen["power"]["units_needed"]
        if seen["gain_pct"] >= d["scan"]["cv"]["min_gain_pct"] and units is not None:
            assert t["needed_half_cycles"] == units and t["needed"] == (
                f"about {units} half-cycles would make it significant at this gain (80 % power)")
        else:  # under the bar, or not lowering the error on average
            assert t["needed_half_cycles"] is None and t["needed"].startswith("no length will"), t
    assert {t["effect"] for t in nx["tests"] if t["gain_pct"] is None} >= {"coupling", "load:sheath_wrap_deg"}
    # the excite command lines, as printed
    assert nx["excite"][0] == ["endocal", "excite", str(tmp / "next.toml"), "--out", str(tmp / "next-fit"), "--set",
                               "sheath_wrap_deg=VALUE"]
    for line in nx["excite_commands"]:
        assert f"  {line}\n" in proc.stdout
    assert nx["excite_commands"][1].endswith(f"--out {tmp / 'next-val'} --seed 1 --set sheath_wrap_deg=VALUE")


def test_the_api_designs_the_same_experiment(loop, tmp_path):
    import endocal as ec

    tmp, _ = loop
    v = ec.validate(tmp / "m.json", tmp / "val", next=tmp_path / "next.toml")
    cli = json.loads((tmp / "v.json").read_text())["next"]
    ours = v.to_dict()["next"]
    assert v.next.written and v.next.path == tmp_path / "next.toml" and ours["path"] == str(tmp_path / "next.toml")
    proto = {k: v for k, v in read_protocol_file(tmp_path / "next.toml").to_dict().items() if k != "source"}
    assert proto == {k: v for k, v in read_protocol_file(tmp / "next.toml").to_dict().items() if k != "source"}
    def strip(d):
        return {k: v for k, v in d.items() if k not in ("path", "excite", "excite_commands")}

    assert strip(ours) == strip(cli)
    def beside(args, folder):  # the run folders, relative to the protocol file's folder
        return [str(Path(x).relative_to(folder)) if prev == "--out" else x for prev, x in zip(["", *args], args)]

    # the same runs, another file, the runs beside it
    assert [beside(a[3:], tmp_path) for a in v.next.excite] == [beside(a[3:], tmp) for a in cli["excite"]]
    assert f"next: {tmp_path / 'next.toml'} written (" in repr(v) and "; .next.excite records it" in repr(v)
    assert v.next.experiment.tests[0].needed  # the object, not only its dict


def test_nothing_suspected_writes_nothing_and_says_so_in_the_json(loop, tmp_path, monkeypatch):
    """When validate leaves nothing to settle, --next says so in one line, writes nothing, exits 2; the
    validation is printed, and its JSON object says why no file was written."""
    import endocal.validation.next_experiment as nx

    tmp, _ = loop
    monkeypatch.setattr(nx, "_targets", lambda *a, **k: {})
    proc = endocal("validate", tmp / "m.json", tmp / "val", "--next", tmp_path / "next.toml", "--json-out",
                   tmp_path / "v.json")
    one_line_exit_2(proc, "nothing is suspected", "no protocol written")
    assert not (tmp_path / "next.toml").exists() and "validation RMSE" in proc.stdout  # the validation was printed
    d = json.loads((tmp_path / "v.json").read_text())
    assert set(d) == JSON_KEYS | {"next"}
    assert d["next"]["written"] is False and d["next"]["path"] is None and d["next"]["tests"] == []
    assert d["next"]["nothing_suspected"].startswith("nothing is suspected")
    assert d["next"]["excite_commands"] == []

def test_the_summary_points_at_next_when_only_untested_effects_remain(loop, monkeypatch):
    """No suggestion, but effects these records cannot test (coupling, load): the summary's next command
    is this validation with --next, within the summary's 15 lines."""
    import dataclasses

    from endocal.views import SUMMARY_MAX_LINES
    from endocal.validation import offline

    tmp, _ = loop
    real = offline.validate_offline

    def no_suggestion(*args, **kwargs):  # the scan as it is, its suggestions withheld
        r = real(*args, **kwargs)
        return dataclasses.replace(r, scan=dataclasses.replace(r.scan, suspects=()))

    monkeypatch.setattr(offline, "validate_offline", no_suggestion)
    proc = endocal("validate", tmp / "m.json", tmp / "val")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert len(lines) <= SUMMARY_MAX_LINES, proc.stdout
    nexts = [ln for ln in lines if ln.startswith("next:")]
    assert len(nexts) == 1 and "coupling" in nexts[0] and "load" in nexts[0], proc.stdout
    assert nexts[0].endswith(f"endocal validate {tmp / 'm.json'} {tmp / 'val'} --next next.toml"), nexts[0]


def test_the_summary_points_at_next_only_where_next_can_design(loop):
    """The pointer is a command that works: for a model --next would refuse (an axis no knob of the
    probe drives: the real piezo stack's), the summary says each experiment in words instead."""
    from endocal.errors import EndocalError
    from endocal.validation.data import axis_data
    from endocal.validation.next_experiment import check_next

    tmp, _ = loop
    check_next(load_model(tmp / "m.json"), [load_aligned(tmp / "val")], "tee")  # validate_records: next_possible
    piezo = load_aligned(ROOT / "data_samples" / "piezo" / "piezo_aligned.csv")
    model = make_model("linear", axis="piezo").fit(axis_data([piezo], "piezo"))
    with pytest.raises(EndocalError):  # the summary then says each experiment in words
        check_next(model, [piezo], "tee")


def test_the_load_segment_records_the_same_motion_at_the_earlier_value_and_a_new_one(loop, tmp_path):
    """Issue 32: a condition changed only between records is confounded with them (their motion, their start);
    --next asks for the same motion at the earlier value and at a new one, and with both recorded the
    estimation data can show a load term (before, with differing motions only, they cannot)."""
    from endocal.validation.data import axis_data
    from endocal.validation.identifiability import untestable_reason

    tmp, _ = loop
    proto = read_protocol_file(tmp / "next.toml")
    instruction = proto.conditions["sheath_wrap_deg"]["instruction"]
    assert "the same motion at two values" in instruction and "(180)" in instruction, instruction
    nx = json.loads((tmp / "v.json").read_text())["next"]
    earlier = ["endocal", "excite", str(tmp / "next.toml"), "--out", str(tmp / "next-fit-earlier"), "--set",
               "sheath_wrap_deg=180"]
    assert nx["excite"][2] == earlier
    for name, value in (("old", 180), ("new", 120)):
        proc = endocal("excite", tmp / "next.toml", "--out", tmp_path / name, "--set", f"sheath_wrap_deg={value}", "-q")
        assert proc.returncode == 0, proc.stderr
    records = [load_aligned(tmp / n) for n in ("est1", "est2")]
    differing = axis_data(records + [load_aligned(tmp_path / "new")], "ap")
    assert "constant within each record" in untestable_reason("load:sheath_wrap_deg", differing)
    same = axis_data(records + [load_aligned(tmp_path / n) for n in ("old", "new")], "ap")
    assert untestable_reason("load:sheath_wrap_deg", same) is None
