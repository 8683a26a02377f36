"""No command can be crashed by a mutated input file: the commands themselves, on a sample.

The bulk of the mutated inputs runs the readers directly (tests/test_mutations.py); here a
seeded sample goes through the real commands, in-process as tests/_cli.py runs them, each file
through every command that takes one:

- a model file: `validate` (alone and as `--compare`), `excite --model`, `fit hysteresis
  --start-from`, `report`, `export c` and `export mcap --model` (:func:`_export_commands`: an export
  command added later fails there until it says how it takes a model); a quarter to a half of its cases mutate only the fields the loader hands on
  to the commands (provenance, fit report, training records, correlations: ``PASSED_ON``), where
  `validate` once stopped with ``KeyError: 'name'``;
- planes (`excite`, `fit hysteresis`, `validate`, `report` with `--planes`), force models
  (`excite --force-model`), protocols (`protocols show` / `plot`, `excite`, `validate
  --protocol`), rig files (`excite --backend hardware`: no rig here, so a valid file ends in
  exit code 3, one line), simulator files (`excite --sim-config`), CSV maps (`import csv --map`);
- CSV logs (`import csv`), aligned tables (`fit hysteresis`), run folders with one file mutated
  (`info`, `fit hysteresis`), ROS bags (`import-ros`).

Each ends with exit code 0, or 2 with one line and nothing written. ``ENDOCAL_MUTATIONS=K``
multiplies the counts; the seeds are fixed, so a failure's label replays it.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests import _mutate
from tests._mutate import written as _written

REPO = Path(__file__).resolve().parents[1]
SCALE = _mutate.SCALE
COUNTS: dict[str, int] = {}


def _check(proc, label: str, *outputs: Path, codes=(0, 2)) -> None:
    """Exit code 0, or 2 (3: a hardware fault) with one line on stderr and none of ``outputs`` written."""
    from tests._cli import one_line_exit_2

    assert proc.returncode in codes, (label, proc.returncode, proc.stderr[-2000:])
    if proc.returncode != 0:
        if proc.returncode == 2:
            one_line_exit_2(proc)
        else:
            lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
            assert len(lines) == 1 and "Traceback" not in proc.stderr, (label, proc.stderr[-2000:])
        for out in outputs:
            assert not Path(out).exists(), (label, f"half-written {out}")


def _clean(*paths: Path) -> None:
    for p in paths:
        if p.is_dir():
            shutil.rmtree(p)
        else:
            p.unlink(missing_ok=True)


# ----------------------------------------------------------------------------- model files
#: The model's top-level fields the loader hands on to the commands rather than to the model: what
#: `validate` reads of the provenance (estimation data, planes, the probe), what the fit summary and
#: the report print of the fit report, the training records a report marks, the correlations.
PASSED_ON = ("provenance", "fit", "training_data", "correlation", "drive_unit", "cmd_range_deg", "axis")


@pytest.fixture(scope="module")
def models(small_run, tmp_path_factory) -> dict[str, Path]:
    """Model files of three bases fitted on ``small_run`` by `fit hysteresis`, with the provenance it
    writes (its data path and hash, the probe, the working folder)."""
    from tests._cli import endocal

    d = tmp_path_factory.mktemp("models")
    out = {}
    for base, effects in (("linear", "drift"), ("pi", "envelope"), ("bspline", "deadzone")):
        out[base] = d / f"{base}.json"
        proc = endocal("fit", "hysteresis", small_run, "--axis", "ap", "--model", base, "--effects", effects,
                       "--out", out[base])
        assert proc.returncode == 0, proc.stderr
    return out


def test_the_issue_33_case_a_deleted_probe_name_is_one_line_in_every_command(models, other_run, tmp_path):
    """`provenance.probe.name` deleted: `validate` stopped with ``KeyError: 'name'`` and exit code 1."""
    from tests._cli import endocal, one_line_exit_2

    doc = json.loads(models["linear"].read_text())
    del doc["provenance"]["probe"]["name"]
    path = tmp_path / "m.json"
    path.write_text(json.dumps(doc))
    for args in (["validate", path, other_run], ["report", path, "--data", other_run, "--out", tmp_path / "r.html"],
                 ["excite", "triangle", "--model", path, "--out", tmp_path / "run"]):
        one_line_exit_2(endocal(*args), "provenance/probe/name", "restore the file or refit the model")


def _export_commands(model: Path, out: Path, run: Path) -> dict[str, list]:
    """Every `endocal export ...` command that reads a model file, as it takes one: `export c MODEL`,
    `export mcap RUN --model MODEL`. An export command added later that takes a model otherwise fails
    here until it is named (issue 33: a model file goes through every export)."""
    import typer.main

    from endocal.cli import app
    from endocal.cli import commands  # noqa: F401

    export = getattr(typer.main.get_command(app), "commands", {}).get("export")
    if not hasattr(export, "commands"):  # a click group (typer's own Group class is not click.Group's)
        return {}
    argv = {}
    for name, cmd in export.commands.items():
        params = {p.name for p in cmd.params}
        if "model_path" in params:
            argv[f"export {name}"] = ["export", name, model, "--out", out / f"export-{name}"]
        elif {"run", "models"} <= params:
            argv[f"export {name} --model"] = ["export", name, run, "--model", model, "--out", out / f"export-{name}.mcap"]
        else:
            raise AssertionError(f"`endocal export {name}`: say in _export_commands how it takes a model file")
    return argv


#: Cases per model base: (all fields and bytes, fields passed on); `report` (a second a case, for its
#: figures) runs on every case the loader refuses and on the first REPORTED it accepts.
MODEL_CASES = {"linear": (8, 12), "pi": (3, 5), "bspline": (3, 5)}
REPORTED = 1


@pytest.mark.parametrize("base", list(MODEL_CASES))
def test_mutated_model_files_through_every_command_that_reads_one(models, base, other_run, tmp_path):
    """`validate` (alone, and as --compare), `excite --model`, `fit hysteresis --start-from`, `report`
    and every export, on the model file as mutated: exit 0, or 2 with one line and nothing written."""
    from endocal.errors import EndocalError
    from endocal.models import load_model
    from tests._cli import endocal

    raw = models[base].read_bytes()
    effects = ",".join(e["name"] for e in json.loads(raw)["effects"])
    n_all, n_passed = (k * SCALE for k in MODEL_CASES[base])
    cases = [*_mutate.json_mutations(raw, 11, n_all), *_mutate.json_mutations(raw, 12, n_passed, under=PASSED_ON)]
    path, out = tmp_path / "m.json", tmp_path / "out"
    out.mkdir()
    runs, reported = 0, 0
    for i, (label, content) in enumerate(cases):
        path.write_bytes(content)
        label = f"{base} #{i} {label}"
        try:
            load_model(path)
            accepted = True
        except EndocalError:
            accepted = False
        commands = {
            # a PI or B-spline model's effect scan refits each candidate on the estimation data (seconds
            # a case): those two are scored by rolling origin on the record (which says at once that one
            # cycle is too short for it); the linear model's cases read the estimation data its
            # provenance names, as validate does for every base
            "validate": ["validate", path, other_run, "--json", "--json-out", out / "v.json",
                         *(["--cv", "rolling"] if base != "linear" else [])],
            "validate --compare": ["validate", models["linear"], other_run, "--compare", path],
            "excite --model": ["excite", "triangle", "--model", path, "--set", "cycles=1", "--amplitude", "10",
                               "--out", out / "run", "-q"],
            "fit --start-from": ["fit", "hysteresis", other_run, "--axis", "ap", "--model", base, "--effects",
                                 effects, "--start-from", path, "--out", out / "refit.json"],
            **_export_commands(path, out, other_run),
        }
        if not accepted or reported < REPORTED:
            commands["report"] = ["report", path, "--data", other_run, "--out", out / "r.html", "--bootstrap", "20"]
            reported += accepted
        for name, args in commands.items():
            _check(endocal(*args), f"{label} ({name})", *out.iterdir())
            _clean(*out.iterdir())
            runs += 1
    COUNTS[f"{base} model JSON (commands)"] = runs


# ----------------------------------------------------------------------------- planes, force, TOML files
FIXTURES = REPO / "tests" / "fixtures" / "mutate"
PLAY = ["--set", "cycles=1", "--amplitude", "10", "-q"]


def _through(kind: str, name: str, gen, src: Path, seed: int, n: int, commands, tmp_path: Path, codes=(0, 2)) -> None:
    """Each of ``n`` mutations of ``src``, written to ``tmp_path/name``, through every command of
    ``commands(path, out)`` (name -> argv); counted under ``kind``."""
    from tests._cli import endocal

    out = tmp_path / "out"
    out.mkdir(parents=True)
    runs = 0
    for path, label in _written(tmp_path, name, gen, src.read_bytes(), seed, n * SCALE):
        for cmd, args in commands(path, out).items():
            _check(endocal(*args), f"{label} ({cmd})", *out.iterdir(), codes=codes)
            _clean(*out.iterdir())
            runs += 1
    COUNTS[f"{kind} (commands)"] = COUNTS.get(f"{kind} (commands)", 0) + runs


def test_mutated_planes_files_through_the_commands(models, other_run, tmp_path):
    """`excite --planes`, `fit hysteresis --planes`, `validate --planes` and `report --planes`."""
    _through("planes JSON", "planes.json", _mutate.json_mutations, FIXTURES / "planes.json", 21, 14, lambda p, o: {
        "excite": ["excite", "triangle", "--planes", p, *PLAY, "--out", o / "run"],
        "fit": ["fit", "hysteresis", other_run, "--axis", "ap", "--model", "linear", "--planes", p, "--out", o / "m.json"],
        "validate": ["validate", models["linear"], other_run, "--planes", p, "--json"],
    }, tmp_path)
    _through("planes JSON", "planes.json", _mutate.json_mutations, FIXTURES / "planes.json", 22, 2, lambda p, o: {
        "report": ["report", models["linear"], "--data", other_run, "--planes", p, "--out", o / "r.html",
                   "--bootstrap", "20"]}, tmp_path / "r")


def test_mutated_force_models_through_the_commands(tmp_path):
    """`excite --force-model` (the guard on a simulated run) and `validate --protocol --force-model`."""
    _through("force JSON", "force.json", _mutate.json_mutations, FIXTURES / "force.json", 23, 24, lambda p, o: {
        "excite": ["excite", "triangle", "--force-model", p, "--max-force-n", "1", *PLAY, "--out", o / "run"],
    }, tmp_path)


def test_mutated_protocols_through_the_commands(models, tmp_path):
    """`protocols show`, `protocols plot`, `excite` and `validate --protocol` on a protocol file."""
    _through("protocol TOML", "p.toml", _mutate.toml_mutations, REPO / "protocols" / "damped-sine.toml", 6, 24,
             lambda p, o: {"show": ["protocols", "show", p],
                           "excite": ["excite", p, "--set", "duration_s=2", "-q", "--out", o / "run"]}, tmp_path)
    _through("protocol TOML", "p.toml", _mutate.toml_mutations, REPO / "protocols" / "triangle.toml", 7, 8,
             lambda p, o: {"plot": ["protocols", "plot", p, "--out", o / "p.png"],
                           "validate --protocol": ["validate", models["linear"], "--protocol", p, "--set", "cycles=1",
                                                   "--set", "amplitude_deg=10"]}, tmp_path / "v")


def test_mutated_rig_and_simulator_files_through_excite(tmp_path):
    """`excite --backend hardware --hardware-config` (no rig here: a valid file ends in one line and exit
    code 3, the port not found) and `excite --sim-config`."""
    _through("rig TOML", "rig.toml", _mutate.toml_mutations, REPO / "configs" / "hardware-example.toml", 24, 40,
             lambda p, o: {"excite": ["excite", "triangle", "--backend", "hardware", "--hardware-config", p, *PLAY,
                                      "--out", o / "run"]}, tmp_path, codes=(0, 2, 3))
    _through("simulator TOML", "sim.toml", _mutate.toml_mutations, REPO / "configs" / "sim-default.toml", 25, 24,
             lambda p, o: {"excite": ["excite", "triangle", "--sim-config", p, *PLAY, "--out", o / "run"]},
             tmp_path / "s")


def test_mutated_csv_maps_through_import(small_run, tmp_path):
    """`import csv --map` of a mutated map, on the log it maps."""
    import pandas as pd

    a = pd.read_parquet(small_run / "aligned.parquet").iloc[:300]
    log = tmp_path / "log.csv"
    pd.DataFrame({"time_ms": a["t_s"] * 1e3, "motor_rad": np.radians(a["ap_cmd_deg"]), "joint_deg": a["ap_meas_deg"],
                  "sheath_deg": 180.0}).to_csv(log, index=False)
    _through("CSV map TOML", "map.toml", _mutate.toml_mutations, REPO / "configs" / "csv-map.angles.example.toml", 26,
             40, lambda p, o: {"import": ["import", "csv", log, "--map", p, "--out", o / "t.parquet"]}, tmp_path / "m")


# ----------------------------------------------------------------------------- CSV logs and aligned tables
def test_mutated_csv_logs_through_import(small_run, tmp_path):
    """`import csv` of a mutated bench log (the columns of configs/csv-map.angles.example.toml):
    a table, or one line and nothing written."""
    import pandas as pd

    from tests._cli import endocal, one_line_exit_2

    a = pd.read_parquet(small_run / "aligned.parquet").iloc[:400]
    log = pd.DataFrame({"time_ms": a["t_s"] * 1e3, "motor_rad": np.radians(a["ap_cmd_deg"]),
                        "joint_deg": a["ap_meas_deg"], "sheath_deg": 180.0})
    raw = log.to_csv(index=False).encode()
    mapping = REPO / "configs" / "csv-map.angles.example.toml"
    n = 0
    for path, label in _written(tmp_path, "log.csv", _mutate.csv_mutations, raw, 7, 150 * SCALE):
        out = tmp_path / f"imported{n}.parquet"
        proc = endocal("import", "csv", path, "--map", mapping, "--out", out)
        assert proc.returncode in (0, 2), (label, proc.stderr[-2000:])
        if proc.returncode == 2:
            one_line_exit_2(proc)
            assert not out.exists(), (label, "half-written table")
        n += 1
        out.unlink(missing_ok=True)
    COUNTS["CSV log (import csv)"] = n


def test_mutated_aligned_tables_through_fit(tmp_path):
    """A mutated aligned table (the real piezo slice, as CSV) read by `fit hysteresis`."""
    from tests._cli import endocal, one_line_exit_2

    src = REPO / "data_samples" / "piezo" / "piezo_aligned.csv"
    raw = b"".join(src.read_bytes().splitlines(keepends=True)[:600])
    n = 0
    for path, label in _written(tmp_path, "table.csv", _mutate.csv_mutations, raw, 9, 80 * SCALE):
        model = tmp_path / f"m{n}.json"
        proc = endocal("fit", "hysteresis", path, "--axis", "piezo", "--model", "linear", "--out", model)
        assert proc.returncode in (0, 2), (label, proc.stderr[-2000:])
        if proc.returncode == 2:
            one_line_exit_2(proc)
            assert not model.exists(), (label, "half-written model")
        n += 1
    COUNTS["aligned table CSV (fit)"] = n


# ----------------------------------------------------------------------------- run folders
@pytest.fixture(scope="module")
def small_run(tmp_path_factory) -> Path:
    from tests._cli import endocal

    run = tmp_path_factory.mktemp("runs") / "triangle"
    proc = endocal("excite", "triangle", "--set", "cycles=1", "--out", run, "-q", "--seed", 1)
    assert proc.returncode == 0, proc.stderr
    return run


@pytest.fixture(scope="module")
def other_run(tmp_path_factory) -> Path:
    """A second record (another seed): validation data the models were not fitted on."""
    from tests._cli import endocal

    run = tmp_path_factory.mktemp("runs") / "other"
    proc = endocal("excite", "triangle", "--set", "cycles=1", "--out", run, "-q", "--seed", 2)
    assert proc.returncode == 0, proc.stderr
    return run


RUN_PARTS = [("aligned.parquet", _mutate.parquet_mutations, 50), ("run.json", _mutate.json_mutations, 50),
             ("motor/part-000000.parquet", _mutate.parquet_mutations, 40),
             ("tracker/part-000000.parquet", _mutate.parquet_mutations, 40)]


@pytest.mark.parametrize("part,gen,n", RUN_PARTS, ids=[p[0].split("/")[0] for p in RUN_PARTS])
def test_mutated_run_folders_through_info_and_fit(small_run, part, gen, n, tmp_path):
    """`info` and `fit hysteresis` on a run with one file mutated (and, every other case, its
    aligned table gone, so the table is rebuilt from the mutated stream)."""
    from tests._cli import endocal, one_line_exit_2

    raw = (small_run / part).read_bytes()
    cases = 0
    for i, (label, content) in enumerate(gen(raw, 8, n * SCALE)):
        run = tmp_path / f"run{i}"
        shutil.copytree(small_run, run)
        (run / part).write_bytes(content)
        if part != "aligned.parquet" and i % 2:
            (run / "aligned.parquet").unlink()
        model = tmp_path / f"m{i}.json"
        for args in (["info", run], ["fit", "hysteresis", run, "--model", "linear", "--axis", "ap", "--out", model]):
            proc = endocal(*args)
            assert proc.returncode in (0, 2), (f"#{i} {label}", args[0], proc.stderr[-2000:])
            if proc.returncode == 2:
                one_line_exit_2(proc)
                assert not model.exists(), (f"#{i} {label}", "half-written model")
            cases += 1
        shutil.rmtree(run)
    COUNTS[f"run folder {part} (info, fit)"] = cases


def test_mutated_ros_bags_through_import(small_run, tmp_path):
    """`import-ros` of a bag whose database or metadata is damaged: a run, or one line and no folder."""
    pytest.importorskip("rosbags")
    from tests._cli import endocal, one_line_exit_2
    from tests.test_ros_import import write_bag

    bag = tmp_path / "bag"
    write_bag(small_run, bag, extra_joint=False)
    files = sorted(p for p in bag.iterdir() if p.is_file())
    n = 0
    for k, target in enumerate(files):
        raw = target.read_bytes()
        rng = np.random.default_rng(10 + k)
        for i in range(30 * SCALE):
            label, content = _mutate.mutate_bytes(raw, rng)
            copy = tmp_path / f"bag{n}"
            shutil.copytree(bag, copy)
            (copy / target.name).write_bytes(content)
            out = tmp_path / f"run{n}"
            proc = endocal("import-ros", copy, "--out", out, "--joint", "ap=knob_ap_joint", "--joint", "ml=knob_ml_joint")
            assert proc.returncode in (0, 2), (target.name, f"#{i} {label}", proc.stderr[-2000:])
            if proc.returncode == 2:
                one_line_exit_2(proc)
                assert not out.exists(), (target.name, f"#{i} {label}", "half-written run folder")
            n += 1
            shutil.rmtree(copy)
            shutil.rmtree(out, ignore_errors=True)
    COUNTS["ROS bag (import-ros)"] = n


def test_zz_the_count():
    """Every command test above ran its cases (printed for the evidence page), when the whole module ran
    (16 kinds of input; 15 without the rosbags package)."""
    print("\nmutated inputs through the commands:", sum(COUNTS.values()), COUNTS)
    if len(COUNTS) < 15:
        pytest.skip("only part of the module ran")
    assert sum(COUNTS.values()) >= 1000 * SCALE, COUNTS
