"""A lab whose drive is linear: a tendon pulled by a linear stage, logged in mm.

The log is shaped as such benches write it (``Time, Tendon Disp., Motor Curr., Pos x, Pos y,
Pos z, Angle x, Angle y, Angle z``) and simulated with known physics: tendon slack (a dead band
of +-0.4 mm around neutral), sheath friction (a play of half-width 0.5 mm) and a bend of 11 deg
per mm pulled (a tendon 5.2 mm off the bending section's axis: 180 / (pi 5.2)), measured with
0.08 deg of noise. A user drafts the map, fixes only what it marks CHECK or FILL IN, imports,
fits, validates and reports; the drive stays in mm throughout (endocal/runs/aligned.py,
endocal/models/base.py), and a model of it is refused on a knob's record.
"""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from endocal.errors import ModelError
from endocal.models import HysteresisData, load_model, make_model
from endocal.models.io import model_to_dict
from endocal.runs.aligned import load_aligned
from tests._cli import endocal, one_line_exit_2

SLACK_MM, PLAY_HALF_MM, GAIN_DEG_PER_MM, NOISE_DEG = 0.4, 0.5, 11.0, 0.08
COLUMNS = ["Time", "Tendon Disp.", "Motor Curr.", "Pos x", "Pos y", "Pos z", "Angle x", "Angle y", "Angle z"]


def tendon_log(seed: int, kind: str = "damped", rate_hz: float = 50.0, duration_s: float = 40.0) -> pd.DataFrame:
    """A tendon-displacement bench's log: the stage's travel (mm), its motor current (A), and the
    tip's pose from a camera (mm, deg), the bend being ``Angle y``."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    if kind == "damped":  # estimation: a damped sine from +-6 mm
        x = 6.0 * np.exp(-t / 40.0) * np.sin(2 * np.pi * 0.25 * t)
    else:  # validation: a chirp of slowly varying amplitude, never seen by the fit
        x = (3.0 + 2.5 * np.sin(2 * np.pi * 0.03 * t)) * np.sin(2 * np.pi * (0.2 * t + 0.004 * t ** 2))
    u = np.where(x > SLACK_MM, x - SLACK_MM, np.where(x < -SLACK_MM, x + SLACK_MM, 0.0))  # slack taken up
    p, s = np.empty_like(u), 0.0
    for i, v in enumerate(u):  # friction: a play operator
        s = min(max(s, v - PLAY_HALF_MM), v + PLAY_HALF_MM)
        p[i] = s
    theta = GAIN_DEG_PER_MM * p
    th = np.radians(theta) + 1e-12
    return pd.DataFrame({
        "Time": np.round(t, 3),
        "Tendon Disp.": np.round(x, 4),
        "Motor Curr.": np.round(0.15 + 0.08 * np.abs(x) + 0.1 * np.sign(np.gradient(x)) + rng.normal(0, 0.01, t.size),
                                4),
        "Pos x": np.round(rng.normal(0, 0.05, t.size), 3),
        "Pos y": np.round(40.0 * (1 - np.cos(th)) / th, 3),
        "Pos z": np.round(40.0 * np.sin(th) / th, 3),
        "Angle x": np.round(rng.normal(0, 0.3, t.size), 3),
        "Angle y": np.round(theta + rng.normal(0, NOISE_DEG, t.size), 3),
        "Angle z": np.round(0.02 * theta + rng.normal(0, 0.2, t.size), 3),
    })[COLUMNS]


#: What a user who knows the bench answers for each line a draft may mark: (table, key) -> value
TRUTH = {("time", "unit"): "s", ("knobs.ap", "position"): "Tendon Disp.", ("knobs.ap", "unit"): "mm",
         ("knobs.ap", "current"): "Motor Curr.", ("knobs.ap", "current_unit"): "A",
         ("angles.ap", "column"): "Angle y", ("angles.ap", "unit"): "deg"}


def review(text: str) -> tuple[str, list[str], list[str]]:
    """A user's pass over a drafted map: every line marked CHECK or FILL IN is checked against
    what they know of the bench (TRUTH) and fixed when wrong; nothing else is touched. Returns the
    map, the lines marked, and the lines fixed."""
    table, out, marked, fixed = "", [], [], []
    for line in text.splitlines():
        m = re.match(r"^\[(.+?)\]", line)
        if m:
            table = m.group(1)
        kv = re.match(r'^(\w+) = (".*?"|\S+)', line)
        if kv and ("CHECK" in line or "FILL IN" in line):
            key = (table, kv.group(1))
            marked.append(f"[{table}] {kv.group(1)}")
            want = TRUTH.get(key)
            if want is not None and tomllib.loads(f"v = {kv.group(2)}")["v"] != want:
                line = f'{kv.group(1)} = "{want}"'
                fixed.append(marked[-1])
        out.append(line)
    return "\n".join(out) + "\n", marked, fixed


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    """The two logs, the reviewed map and the imported tables (the drafting is asserted below)."""
    tmp = tmp_path_factory.mktemp("linear")
    tendon_log(1).to_csv(tmp / "sweep.csv", index=False)
    tendon_log(2, "chirp").to_csv(tmp / "chirp.csv", index=False)
    return tmp


def test_a_tendon_displacement_log_is_drafted_imported_fitted_validated_and_reported(bench):
    tmp = bench
    # the draft: the drive is the displacement, in mm, each guess marked; the current never a position
    proc = endocal("import", "csv", tmp / "sweep.csv", "--draft-map", tmp / "draft.toml", "--force")
    assert proc.returncode == 0, proc.stderr
    assert "knob ap <- Tendon Disp." in proc.stdout, proc.stdout
    assert "CHECK [knobs.ap] position: named like a linear drive's travel (disp)" in proc.stdout, proc.stdout
    assert "CHECK [knobs.ap] unit: a travel of" in proc.stdout and "read as millimetres" in proc.stdout
    draft = tomllib.loads((tmp / "draft.toml").read_text())
    assert draft["knobs"]["ap"]["position"] == "Tendon Disp." and draft["knobs"]["ap"]["unit"] == "mm"
    assert draft["knobs"]["ap"]["current"] == "Motor Curr." and draft["angles"]["ap"]["column"] == "Angle y"
    assert "Motor Curr." not in [t.get("position") for t in draft["knobs"].values()]
    assert "extras" not in draft  # the tip's pose components are what the model predicts, no covariates
    text, marked, fixed = review((tmp / "draft.toml").read_text())
    assert {"[knobs.ap] position", "[knobs.ap] unit", "[angles.ap] column"} <= set(marked), marked
    assert fixed == [], fixed  # every guess was right: the user only read them
    (tmp / "map.toml").write_text(text)

    # the import keeps the drive in mm: the command column and the table's metadata say so
    for name in ("sweep", "chirp"):
        proc = endocal("import", "csv", tmp / f"{name}.csv", "--map", tmp / "map.toml", "--out",
                       tmp / f"{name}.parquet", "--explain")  # --explain: the column each role was read from
        assert proc.returncode == 0, proc.stderr
        assert "ap (mm) <- Tendon Disp." in proc.stdout, proc.stdout
    a = load_aligned(tmp / "sweep.parquet")
    log = pd.read_csv(tmp / "sweep.csv")
    assert a.drive_units == {"ap": "mm"} and "ap_cmd_deg" not in a.table
    np.testing.assert_allclose(a.cmd("ap"), log["Tendon Disp."], atol=1e-12)
    np.testing.assert_allclose(a.meas_deg("ap"), log["Angle y"], atol=1e-12)
    np.testing.assert_allclose(a.table["ap_current_ma"], 1000.0 * log["Motor Curr."], rtol=1e-12)
    import pyarrow.parquet as pq

    meta = json.loads(pq.read_schema(tmp / "sweep.parquet").metadata[b"endocal"])
    assert meta["drive_units"] == {"ap": "mm"}
    info = endocal("info", tmp / "sweep.parquet")
    assert info.returncode == 0 and "command (mm)" in info.stdout, info.stdout

    # the fit finds the bench's physics in mm: slack, play and gain. Tolerances: the angle's noise
    # (0.08 deg) over the gain (11 deg/mm) is 0.007 mm per sample, averaged over thousands
    proc = endocal("fit", "hysteresis", tmp / "sweep.parquet", "--axis", "ap", "--model", "linear", "--effects",
                   "deadzone", "--out", tmp / "m.json")
    assert proc.returncode == 0, proc.stderr
    assert "slack = deadzone[slack_mm=" in proc.stdout and "_deg" not in proc.stdout.split(";")[1], proc.stdout
    model = load_model(tmp / "m.json")
    assert model.drive_unit_ == "mm" and json.loads((tmp / "m.json").read_text())["drive_unit"] == "mm"
    p = model.params_
    assert abs(p["deadzone_slack_deg"] - SLACK_MM) < 0.01, p
    assert abs(p["linear_up_slope"] - GAIN_DEG_PER_MM) < 0.05 and abs(p["linear_down_slope"] - GAIN_DEG_PER_MM) < 0.05
    # the play's half-width, as the branches' offsets over the gain
    assert abs((p["linear_down_offset_deg"] - p["linear_up_offset_deg"]) / 2 / GAIN_DEG_PER_MM - PLAY_HALF_MM) < 0.01
    assert NOISE_DEG * 0.9 < model.fit_report_.rmse_deg < NOISE_DEG * 1.25, model.fit_report_.rmse_deg

    # validated on the chirp (estimation data: the sweep, found by its hash): the noise floor
    proc = endocal("validate", tmp / "m.json", tmp / "chirp.parquet", "--json-out", tmp / "v.json")
    assert proc.returncode == 0, proc.stderr
    v = json.loads((tmp / "v.json").read_text())
    assert v["scheme"]["name"] == "estimation/validation" and v["metrics"]["rmse_deg"] < NOISE_DEG * 1.25, v["metrics"]
    assert "slack_mm=" in v["model"]["equation"] and v["model"]["drive_unit"] == "mm"
    assert any(" mm after)" in r["name"] for r in v["regimes"]), v["regimes"]
    proc = endocal("report", tmp / "m.json", "--data", tmp / "chirp.parquet", "--out", tmp / "r.html")
    assert proc.returncode == 0, proc.stderr
    assert "slack_mm=" in (tmp / "r.html").read_text()
    assert json.loads((tmp / "r.json").read_text())["models"][0]["drive_unit"] == "mm"

    # a knob's record (the same numbers, commanded in deg) is refused by every command, in one line
    t = a.table.rename(columns={"ap_cmd_mm": "ap_cmd_deg"})
    t.to_csv(tmp / "knob.csv", index=False)
    for args in (("validate", tmp / "m.json", tmp / "knob.csv"),
                 ("report", tmp / "m.json", "--data", tmp / "knob.csv", "--out", tmp / "r2.html"),
                 ("fit", "hysteresis", tmp / "knob.csv", "--axis", "ap", "--model", "linear", "--effects", "deadzone",
                  "--start-from", tmp / "m.json", "--out", tmp / "m2.json")):
        one_line_exit_2(endocal(*args), "fitted on a drive commanded in mm", "command it in deg")
    assert not (tmp / "r2.html").exists() and not (tmp / "m2.json").exists()
    one_line_exit_2(endocal("fit", "hysteresis", tmp / "knob.csv", tmp / "sweep.parquet", "--axis", "ap", "--model",
                            "linear", "--out", tmp / "m3.json"),
                    "commands the ap drive in deg", "in mm", "give records of one drive")
    # nor is it played on a probe's knobs
    one_line_exit_2(endocal("validate", tmp / "m.json", "--protocol", "triangle"),
                    "commanded in mm", "not played")


@pytest.mark.parametrize("edit, fragments", [
    # mm for an angle column: a length is no bending angle
    (lambda t: t.replace('unit = "deg"', 'unit = "mm"'),
     ("[angles.ap]: unit = 'mm', but a bending angle is measured in deg or rad", "[knobs.AXIS] unit")),
    # deg for the displacement: its name says so
    (lambda t: t.replace('unit = "mm"', 'unit = "deg"', 1),
     ("[knobs.ap]: unit = \"deg\" reads column 'Tendon Disp.' as an angle", "named like a displacement (disp)",
      'unit = "mm"')),
    # metres for a travel in mm: 1000 times any tendon's
    (lambda t: t.replace('unit = "mm"', 'unit = "m"', 1),
     ("column 'Tendon Disp.' read as m", "far beyond any tendon's travel", "[knobs.ap] unit right?")),
])
def test_a_map_with_a_drive_or_angle_unit_its_log_contradicts_is_one_line(bench, edit, fragments):
    tmp = bench
    proc = endocal("import", "csv", tmp / "sweep.csv", "--draft-map", tmp / "bad-draft.toml", "--force")
    assert proc.returncode == 0, proc.stderr
    text = (tmp / "bad-draft.toml").read_text()
    bad = edit(text)
    assert bad != text
    (tmp / "bad.toml").write_text(bad)
    one_line_exit_2(endocal("import", "csv", tmp / "sweep.csv", "--map", tmp / "bad.toml", "--out",
                            tmp / "bad.parquet"), *fragments)
    assert not (tmp / "bad.parquet").exists()


def test_a_column_named_in_degrees_read_as_millimetres_is_one_line(tmp_path):
    log = tendon_log(3, duration_s=10.0).rename(columns={"Tendon Disp.": "pulley_deg"})
    log.to_csv(tmp_path / "knob.csv", index=False)
    (tmp_path / "map.toml").write_text('[time]\ncolumn = "Time"\n\n[knobs.ap]\nposition = "pulley_deg"\nunit = "mm"\n\n'
                                       '[angles.ap]\ncolumn = "Angle y"\n')
    one_line_exit_2(endocal("import", "csv", tmp_path / "knob.csv", "--map", tmp_path / "map.toml", "--out",
                            tmp_path / "t.parquet"), "reads column 'pulley_deg' as a length, but its name says deg",
                    'unit = "deg"')
    assert not (tmp_path / "t.parquet").exists()


def test_a_displacement_whose_numbers_do_not_say_mm_is_left_to_fill_in(tmp_path):
    """A travel of 0.012 (metres, or millimetres of a tiny stage?) is not plainly mm: the draft
    leaves the unit FILL IN, and the import refuses it naming the key."""
    log = tendon_log(4, duration_s=10.0)
    log["Tendon Disp."] /= 1000.0
    log.to_csv(tmp_path / "m.csv", index=False)
    proc = endocal("import", "csv", tmp_path / "m.csv", "--draft-map", tmp_path / "d.toml")
    assert proc.returncode == 0, proc.stderr
    assert "CHECK [knobs.ap] unit: a travel of 0.011" in proc.stdout and "mm or m?" in proc.stdout, proc.stdout
    assert tomllib.loads((tmp_path / "d.toml").read_text())["knobs"]["ap"]["unit"] == "FILL IN"
    one_line_exit_2(endocal("import", "csv", tmp_path / "m.csv", "--map", tmp_path / "d.toml", "--out",
                            tmp_path / "t.parquet"), "[knobs.ap]: the unit is still 'FILL IN'", "mm")


def test_a_model_records_its_drive_unit_prints_in_it_and_refuses_another():
    """The hysteresis maths is unit-free: the same numbers fitted as mm or deg give the same model,
    printed and saved in its unit; data stated in another unit is refused, arrays are taken as given."""
    x = 6.0 * np.sin(np.linspace(0, 6 * np.pi, 600))
    y = GAIN_DEG_PER_MM * np.where(np.abs(x) > SLACK_MM, x - np.sign(x) * SLACK_MM, 0.0)
    mm = make_model("linear", effects=["deadzone"], axis="ap").fit(HysteresisData(x, y, drive_unit="mm"))
    deg = make_model("linear", effects=["deadzone"], axis="ap").fit(x, y)
    assert (mm.drive_unit_, deg.drive_unit_) == ("mm", "deg")
    assert mm.params_ == pytest.approx(deg.params_, rel=1e-9, abs=1e-12)
    eq = mm.equation()
    assert "slack_mm=" in eq and "band_mm=" in eq and "_deg" not in eq.split(";")[1], eq
    assert eq.startswith("ap_deg = ")  # the bend stays in degrees
    assert mm.parameter_labels()["deadzone_slack_deg"] == "deadzone_slack_mm"
    assert model_to_dict(mm)["drive_unit"] == "mm" and model_to_dict(deg)["drive_unit"] == "deg"
    np.testing.assert_allclose(mm.predict(HysteresisData(x, drive_unit="mm")), mm.predict(x))
    with pytest.raises(ModelError, match=r"fitted on a drive commanded in mm .* command it in deg"):
        mm.predict(HysteresisData(x, drive_unit="deg"))
    with pytest.raises(ModelError, match="out of range|outside the fitted command range .* mm"):
        mm.predict(np.array([10.0]))
    with pytest.raises(ModelError, match="different units"):
        HysteresisData.from_runs([HysteresisData(x, drive_unit="mm"), HysteresisData(x, drive_unit="deg")])
    # a model file written before drives had units is a knob's
    d = model_to_dict(deg)
    del d["drive_unit"]
    from endocal.models import model_from_dict

    assert model_from_dict(d).drive_unit_ == "deg"
    with pytest.raises(ModelError, match="unknown drive_unit 'inch'"):
        model_from_dict({**d, "drive_unit": "inch"})


def test_an_aligned_table_names_its_drive_unit_in_its_command_column(tmp_path):
    """A lab may write the aligned table itself: ``ap_cmd_mm`` is read as a linear drive; a
    command in both units for one axis is refused in one line."""
    a = load_aligned(Path(__file__).resolve().parents[1] / "data_samples" / "piezo" / "piezo_aligned.csv")
    t = pd.DataFrame({"t_s": a.t_s, "ap_cmd_mm": a.cmd("piezo") / 10, "ap_meas_deg": a.meas_deg("piezo")})
    t.to_csv(tmp_path / "lin.csv", index=False)
    b = load_aligned(tmp_path / "lin.csv")
    assert b.axes == ["ap"] and b.drive_unit("ap") == "mm" and b.extras == []
    with pytest.raises(Exception, match="cmd"):
        b.cmd_deg("ap")
    t.assign(ap_cmd_deg=1.0).to_csv(tmp_path / "both.csv", index=False)
    one_line_exit_2(endocal("info", tmp_path / "both.csv"), "axis 'ap' has a command in deg and one in mm")


def _imported(bench, tmp_path) -> dict:
    """The two logs imported as the user does it (draft, review, import): name -> aligned table."""
    assert endocal("import", "csv", bench / "sweep.csv", "--draft-map", tmp_path / "draft.toml").returncode == 0
    (tmp_path / "map.toml").write_text(review((tmp_path / "draft.toml").read_text())[0])
    out = {}
    for name in ("sweep", "chirp"):
        proc = endocal("import", "csv", bench / f"{name}.csv", "--map", tmp_path / "map.toml", "--out",
                       tmp_path / f"{name}.parquet")
        assert proc.returncode == 0, proc.stderr
        out[name] = tmp_path / f"{name}.parquet"
    return out


def test_the_api_prints_a_linear_drives_commands_in_mm_and_next_is_refused(bench, tmp_path):
    """The Validation repr of a model of a linear drive names the drive's unit, and every command
    quantity it prints (the regimes' bounds and speeds) is in mm; the angle errors stay in deg.
    `--next` (knob protocols in deg) is refused for it, by the CLI and the API alike."""
    import endocal as ec

    runs = _imported(bench, tmp_path)
    model = ec.fit(runs["sweep"], axis="ap", model="linear", effects=["deadzone"])
    model.save(tmp_path / "m.json")
    v = ec.validate(model, runs["chirp"])
    text = repr(v)
    assert text.splitlines()[0].startswith("linear+deadzone on axis ap (drive commanded in mm): "), text
    worst = next(ln for ln in text.splitlines() if "worst regime" in ln)
    assert re.search(r" mm(/s)?\)?: RMSE [\d.]+ deg", worst) and "deg/s" not in worst and " deg)" not in worst, worst
    assert "RMSE" in text and re.search(r"RMSE [\d.]+ deg \(95 % CI", text)  # the angle's error: deg

    # --next designs knob protocols in deg, which no linear stage runs: refused before the validation,
    # in one line, nothing written (the CLI and the API share the check)
    one_line_exit_2(endocal("validate", tmp_path / "m.json", runs["chirp"], "--next", tmp_path / "next.toml"),
                    "ap drive is commanded in mm (a linear drive)", "nothing written", "validate --explain")
    with pytest.raises(ValueError, match="commanded in mm"):
        ec.validate(model, runs["chirp"], next=tmp_path / "next.toml")
    assert not (tmp_path / "next.toml").exists()


def test_fit_planes_on_a_linear_drive_says_planes_need_knobs(tmp_path):
    """A planes run whose drive is linear: one line naming the linear drive's column, not a missing ap_cmd_deg."""
    import pyarrow.parquet as pq

    run = tmp_path / "planes"
    assert endocal("excite", "planes", "--out", run, "--set", "sample_rate_hz=20", "--set", "repetitions=1",
                   "-q").returncode == 0
    table = pq.read_table(run / "aligned.parquet")
    pq.write_table(table.rename_columns(["ap_cmd_mm" if c == "ap_cmd_deg" else c for c in table.column_names]),
                   run / "aligned.parquet")
    meta = json.loads((run / "run.json").read_text())
    (run / "run.json").write_text(json.dumps({**meta, "drive_units": {"ap": "mm"}}))
    one_line_exit_2(endocal("fit", "planes", run, "--out", tmp_path / "p.json"),
                    "the ap drive is linear (column ap_cmd_mm, in mm)", "bending planes need knob drives commanded in deg")
    assert not (tmp_path / "p.json").exists()
