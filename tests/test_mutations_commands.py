"""No command can be crashed by a mutated input file: the commands themselves, on a sample.

The bulk of the mutated inputs runs the readers directly (tests/test_mutations.py); here a
sample of them goes through the real commands, in-process as tests/_cli.py runs them:
`validate` and `excite --model` on model files, `protocols show` on protocols, `import csv`
on logs, `fit hysteresis` on aligned tables, `info` and `fit hysteresis` on run folders with
one file mutated. Each ends with exit code 0, or 2 with one line and nothing written.
``ENDOCAL_MUTATIONS=K`` multiplies the counts.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from tests import _mutate
from tests._mutate import written as _written

REPO = Path(__file__).resolve().parents[1]
SCALE = _mutate.SCALE
COUNTS: dict[str, int] = {}


@pytest.fixture(scope="module")
def linear_model(tmp_path_factory) -> Path:
    from endocal.models import make_model, save_model
    from endocal.runs.aligned import load_aligned
    from endocal.validation.data import axis_data

    path = tmp_path_factory.mktemp("model") / "linear.json"
    data = axis_data(load_aligned(REPO / "data_samples" / "sim-triangle"), "ap")
    save_model(make_model("linear", ["drift"], axis="ap").fit(data), path)
    return path


def test_mutated_model_files_through_the_commands(linear_model, tmp_path):
    """`validate` and `excite --model`: exit 0, or 2 with one line and nothing written."""
    from tests._cli import endocal, one_line_exit_2

    raw = linear_model.read_bytes()
    run = REPO / "data_samples" / "sim-triangle"
    n = 0
    for path, label in _written(tmp_path, "m.json", _mutate.json_mutations, raw, 2, 12 * SCALE):
        out = tmp_path / f"run{n}"
        for args in (["excite", "triangle", "--model", path, "--set", "cycles=1", "--amplitude", "10",
                      "--out", out, "-q"], ["validate", path, run, "--json"]):
            proc = endocal(*args)
            assert proc.returncode in (0, 2), (label, args[0], proc.stderr[-2000:])
            if proc.returncode == 2:
                one_line_exit_2(proc)
                assert not out.exists(), (label, "half-written run folder")
            n += 1
        shutil.rmtree(out, ignore_errors=True)
    COUNTS["model JSON (commands)"] = n


def test_mutated_protocols_through_the_command(tmp_path):
    from tests._cli import endocal, one_line_exit_2

    raw = (REPO / "protocols" / "damped-sine.toml").read_bytes()
    n = 0
    for path, label in _written(tmp_path, "p.toml", _mutate.toml_mutations, raw, 6, 60 * SCALE):
        proc = endocal("protocols", "show", path)
        assert proc.returncode in (0, 2), (label, proc.stderr[-2000:])
        if proc.returncode == 2:
            one_line_exit_2(proc)
        n += 1
    COUNTS["protocol TOML (commands)"] = n


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


def test_zz_the_count():
    """Every command test above ran its cases (printed for the evidence page)."""
    print("\nmutated inputs through the commands:", sum(COUNTS.values()), COUNTS)
    assert sum(COUNTS.values()) >= 600 * SCALE or len(COUNTS) < 8, COUNTS


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
