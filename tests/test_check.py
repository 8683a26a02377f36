"""`endocal check`, `endocal history`, the Dask batch and `ec.history` end to end on the simulator (issue 34).

Checks are real: the built-in check protocol on the simulator (86 s of rig time, a third of a
second of computing each), scored against the fixture models (tests/fixtures/check). Every bad
input of the issue is refused in one line with exit code 2, and the history folder is left byte
for byte as it was: no row appended, nothing half-written.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from endocal.check.run import check_probe
from tests._cli import endocal, one_line_exit_2

FIXTURES = Path(__file__).parent / "fixtures" / "check"


def _models_of_probe(folder: Path, tag: str) -> list[Path]:
    """The fixture models as another probe's own files (same numbers, its own provenance: another SHA-256)."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for axis in ("ap", "ml"):
        d = json.loads((FIXTURES / f"{axis}.json").read_text())
        d["provenance"]["command"] += f"  # probe {tag}"
        p = folder / f"{axis}.json"
        p.write_text(json.dumps(d))
        out.append(p)
    return out


def _snapshot(folder: Path) -> dict:
    """Every file under ``folder`` with its size and bytes' hash: what a refused command must leave alone."""
    import hashlib

    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """Probes A and B, two checks each, in one history; and a later check run of each recorded elsewhere."""
    root = tmp_path_factory.mktemp("fleet")
    models = {"A": _models_of_probe(root / "models-A", "A"), "B": _models_of_probe(root / "models-B", "B")}
    history = root / "history"
    for k, pid in enumerate(["A", "A", "B", "B"]):
        check_probe(models[pid], pid, history, seed=100 + k)
    elsewhere = root / "rig-history"  # the rigs' own folders, whose runs a central batch scores
    later = {pid: check_probe(models[pid], pid, elsewhere, seed=200 + k).run_dir for k, pid in enumerate("AB")}
    return {"root": root, "models": models, "history": history, "later": later}


def _copy(fleet, tmp_path) -> Path:
    h = tmp_path / "history"
    shutil.copytree(fleet["history"], h)
    return h


def _rows(history: Path):
    import pyarrow.dataset as ds

    return ds.dataset(history, format="parquet", partitioning="hive").to_table().to_pandas()


# ------------------------------------------------------------------ one check
def test_check_prints_one_line_appends_one_row_and_keeps_the_run_beside_it(fleet, tmp_path):
    h = _copy(fleet, tmp_path)
    m = fleet["models"]["A"]
    res = endocal("check", "--model", m[0], "--model", m[1], "--probe-id", "A", "--history", h, "--seed", "7")
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().splitlines() == ["A: baseline, 3 of 10 checks since calibration (the control limits "
                                               "come from the first 10)"]
    rows = _rows(h)  # any engine reads the history as one hive-partitioned dataset
    assert sorted(rows["probe"].astype(str)) == ["A", "A", "A", "B", "B"]
    last = rows[rows["probe"] == "A"].sort_values("checked_utc").iloc[-1]
    assert str(last["month"]) == last["checked_utc"][:7] and last["state"] == "baseline"
    run = h / last["run"]
    meta = json.loads((run / "run.json").read_text())
    assert meta["protocol"]["name"] == "check" and meta["protocol"]["check"]["probe_id"] == "A"
    assert meta["planned_duration_s"] <= 90  # the check's rig time
    # the figures, each in its unit and plausible for the simulated probe (about 45 deg of knob each way)
    for axis in ("ap", "ml"):
        assert 0 < last[f"{axis}_rmse_deg"] < 3 and 3 < last[f"{axis}_loop_width_deg"] < 10
        assert 5 < last[f"{axis}_dead_band_deg"] < 15
        assert 20 < last[f"{axis}_bend_pos_deg"] < 40 and 20 < last[f"{axis}_bend_neg_deg"] < 40
    # no temporary folder left behind
    assert not [p for p in h.iterdir() if p.name.startswith(".") and p.name != ".lock"]


def test_check_json_and_a_new_calibration_starts_a_new_baseline(fleet, tmp_path):
    h = _copy(fleet, tmp_path)
    new = _models_of_probe(tmp_path / "recal", "A recalibrated")
    res = endocal("check", "--model", new[0], "--model", new[1], "--probe-id", "A", "--history", h, "--json")
    assert res.returncode == 0, res.stderr
    d = json.loads(res.stdout)
    assert d["state"] == "baseline" and d["n_since_calibration"] == 1 and d["exit_code"] == 0
    assert set(d["figures"]) == {f"{a}_{f}" for a in ("ap", "ml") for f in
                                 ("rmse_deg", "loop_width_deg", "dead_band_deg", "bend_pos_deg", "bend_neg_deg")}


# ------------------------------------------------------------------ bad input: one line, exit 2, nothing written
def _refused(h: Path, *args, fragments=()):
    before = _snapshot(h)
    res = endocal(*args)
    one_line_exit_2(res, *fragments)
    assert _snapshot(h) == before
    return res


def test_a_check_run_of_another_probe_is_refused(fleet, tmp_path):
    h = _copy(fleet, tmp_path)
    m = fleet["models"]["B"]
    _refused(h, "check", "--run", fleet["later"]["A"], "--model", m[0], "--model", m[1], "--probe-id", "B",
             "--history", h, fragments=("is a check of probe A, not B",))


def test_a_run_of_another_protocol_is_refused(fleet, tmp_path):
    h = _copy(fleet, tmp_path)
    m = fleet["models"]["A"]
    triangle = Path(__file__).parents[1] / "data_samples" / "sim-triangle"
    _refused(h, "check", "--run", triangle, "--model", m[0], "--model", m[1], "--probe-id", "A", "--history", h,
             fragments=("played protocol 'triangle' at 45 deg, not the check at 45 deg",))


def test_a_model_of_another_probe_is_refused(fleet, tmp_path):
    h = _copy(fleet, tmp_path)
    m = fleet["models"]["A"]
    _refused(h, "check", "--model", m[0], "--model", m[1], "--probe-id", "B", "--history", h,
             fragments=("is probe A's model", "give B's own model"))


def test_a_history_folder_with_foreign_files_is_refused(fleet, tmp_path):
    h = _copy(fleet, tmp_path)
    (h / "probe=A" / "notes.txt").write_text("calibrated by Bob")
    m = fleet["models"]["A"]
    _refused(h, "check", "--model", m[0], "--model", m[1], "--probe-id", "A", "--history", h,
             fragments=("notes.txt", "not part of a check history"))
    _refused(h, "history", h, fragments=("notes.txt",))
    _refused(h, "history", h, "--sql", "SELECT count(*) FROM checks", fragments=("notes.txt",))


def _corrupt_month(h: Path, probe: str) -> Path:
    f = next((h / f"probe={probe}").glob("month=*/checks.parquet"))
    f.write_bytes(f.read_bytes()[: len(f.read_bytes()) // 2])  # a copy cut short
    return f


def test_a_corrupt_month_file_is_named_and_the_rest_still_read(fleet, tmp_path):
    h = _copy(fleet, tmp_path)
    bad = _corrupt_month(h, "B")
    res = _refused(h, "history", h, fragments=(str(bad), "not a readable Parquet file"))
    assert res.stdout.split("\n")[1].split()[:2] == ["A", res.stdout.split("\n")[1].split()[1]]  # A's row is shown
    assert "B " not in res.stdout
    res = _refused(h, "history", h, "--sql", "SELECT probe, count(*) AS n FROM checks GROUP BY probe",
                   fragments=(str(bad),))
    assert res.stdout.split() == ["probe", "n", "A", "2"]
    mb = fleet["models"]["B"]
    _refused(h, "check", "--model", mb[0], "--model", mb[1], "--probe-id", "B", "--history", h,
             fragments=(str(bad), "no row appended"))
    # another probe's checks go on
    ma = fleet["models"]["A"]
    assert endocal("check", "--model", ma[0], "--model", ma[1], "--probe-id", "A", "--history", h).returncode == 0


@pytest.mark.parametrize("sql, fragment", [
    ("COPY (SELECT * FROM checks) TO 'out.csv'", "a COPY statement; the history is read-only"),
    ("DELETE FROM checks", "a DELETE statement"),
    ("CREATE TABLE t AS SELECT 1", "a CREATE statement"),
    ("SELECT 1; SELECT 2", "2 statements"),
    ("SELECT no_such_column FROM checks", "no_such_column"),
    ("SELEKT 1", "syntax error"),
])
def test_sql_that_writes_or_fails_is_refused(fleet, tmp_path, sql, fragment):
    h = _copy(fleet, tmp_path)
    _refused(h, "history", h, "--sql", sql, fragments=("--sql", fragment))


def test_a_bad_probe_id_is_refused(fleet, tmp_path):
    h = _copy(fleet, tmp_path)
    m = fleet["models"]["A"]
    _refused(h, "check", "--model", m[0], "--probe-id", "../A", "--history", h, fragments=("probe ID '../A'",))


# ------------------------------------------------------------------ history
def test_history_table_sql_plot_and_the_python_api(fleet, tmp_path):
    import endocal as ec

    h = fleet["history"]
    res = endocal("history", h)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.strip().splitlines()
    assert lines[0].split()[:3] == ["probe", "last_check_utc", "state"]
    assert [ln.split()[0] for ln in lines[1:]] == ["A", "B"] and all(" baseline " in ln for ln in lines[1:])
    res = endocal("history", h, "--sql", "SELECT probe, count(*) AS n, max(month) AS m FROM checks GROUP BY probe "
                  "ORDER BY probe")
    assert res.returncode == 0, res.stderr
    assert res.stdout.split()[3:5] == ["A", "2"]
    png = tmp_path / "charts.png"
    res = endocal("history", h, "--probe", "A", "--plot", png)
    assert res.returncode == 0, res.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    one_line_exit_2(endocal("history", h, "--probe", "A", "--plot", png), "already exists")
    one_line_exit_2(endocal("history", h, "--probe", "Z"), "no checks of probe Z", "A, B")
    hist = ec.history(h)
    assert list(hist.table["probe"]) == ["A", "B"] and len(hist.rows) == 4
    assert set(hist.charts) == {"A", "B"} and hist.charts["A"].n_checks == 2
    assert hist.sql("SELECT count(*) AS n FROM checks")["n"].iloc[0] == 4
    assert "History" in repr(hist) and "A: baseline, 2 checks since calibration" in repr(hist)


def test_report_finds_the_probe_checked_against_its_models(fleet):
    from endocal.check.store import HistoryError
    from endocal.check.summary import report_pages
    from endocal.runs.format import sha256_of

    pages, notes = report_pages(fleet["history"], [sha256_of(fleet["models"]["B"][0])])
    assert [p for p, _ in pages] == ["B"] and not notes
    with pytest.raises(HistoryError, match="no probe in .* was checked against these models"):
        report_pages(fleet["history"], [sha256_of(FIXTURES / "ap.json")])
    one_line_exit_2(endocal("report", FIXTURES / "ap.json", "--data", fleet["later"]["A"], "--out",
                            fleet["root"] / "r.html", "--probe", "A"), "--history")


# ------------------------------------------------------------------ the Dask batch
def test_a_batch_on_a_dask_cluster_equals_the_serial_run(fleet, tmp_path):
    from distributed import LocalCluster

    serial, parallel = tmp_path / "serial", tmp_path / "parallel"
    shutil.copytree(fleet["history"], serial)
    shutil.copytree(fleet["history"], parallel)
    runs = [fleet["later"]["A"], fleet["later"]["B"]]
    res = endocal("check", *[a for r in runs for a in ("--run", r)], "--history", serial, "--scheduler", "synchronous")
    assert res.returncode == 0, res.stderr
    assert [ln.split(":")[0] for ln in res.stdout.strip().splitlines()] == ["A", "B"]
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cluster:
        res = endocal("check", *[a for r in runs for a in ("--run", r)], "--history", parallel,
                      "--scheduler", cluster.scheduler_address)
    assert res.returncode == 0, res.stderr
    a, b = _rows(serial), _rows(parallel)
    figures = [c for c in a.columns if c.endswith("_deg") and c != "amplitude_deg"]
    assert len(a) == len(b) == 6 and len(figures) == 10
    key = ["probe", "checked_utc"]
    a, b = a.sort_values(key, ignore_index=True), b.sort_values(key, ignore_index=True)
    assert (a[figures].to_numpy() == b[figures].to_numpy()).all()  # identical, not close
    assert list(a["state"]) == list(b["state"])


def test_a_batch_is_refused_whole_before_anything_is_appended(fleet, tmp_path):
    h = _copy(fleet, tmp_path)
    a = fleet["later"]["A"]
    _refused(h, "check", "--run", a, "--run", a, "--history", h, "--scheduler", "synchronous",
             fragments=("both checks of probe A",))
    _refused(h, "check", "--run", a, "--run", fleet["later"]["B"], "--probe-id", "A", "--history", h,
             fragments=("--probe-id and --model are for one run",))
    plain = tmp_path / "plain-run"  # a run that names no probe (imported, or recorded by excite)
    shutil.copytree(a, plain)
    meta = json.loads((plain / "run.json").read_text())
    del meta["protocol"]["check"]
    (plain / "run.json").write_text(json.dumps(meta))
    _refused(h, "check", "--run", plain, "--run", fleet["later"]["B"], "--history", h,
             fragments=("names no probe ID",))


def test_a_month_file_changed_by_hand_is_read_not_the_probes_stale_copy(fleet, tmp_path):
    import pyarrow.parquet as pq

    h = _copy(fleet, tmp_path)
    assert (h / "probe=A" / "_checks.parquet").is_file()  # every append keeps it
    f = next((h / "probe=A").glob("month=*/checks.parquet"))
    pq.write_table(pq.read_table(f).slice(0, 1), f)  # a backup restored: one check of A
    res = endocal("history", h, "--sql", "SELECT probe, count(*) AS n FROM checks GROUP BY probe ORDER BY probe")
    assert res.returncode == 0, res.stderr
    assert res.stdout.split()[2:] == ["A", "1", "B", "2"]
    assert endocal("history", h).stdout.splitlines()[1].split()[3:5] == ["1", "1"]


def test_without_the_fleet_extra_the_command_says_how_to_install_it(fleet, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "duckdb", None)  # as if not installed
    one_line_exit_2(endocal("history", fleet["history"], "--sql", "SELECT 1"),
                    "needs duckdb, which is not installed", "pip install 'endocal-toolkit[fleet]'")
    monkeypatch.setitem(sys.modules, "dask", None)
    one_line_exit_2(endocal("check", "--run", fleet["later"]["A"], "--run", fleet["later"]["B"], "--history",
                            fleet["history"]), "needs dask", "[fleet]")


def test_report_with_the_history_adds_the_probes_chart_page(fleet, tmp_path):
    import endocal as ec

    rep = ec.make_report(fleet["models"]["A"][0], fleet["later"]["A"], history=fleet["history"], bootstrap=20,
                         out=tmp_path / "report.html")
    ids = [f.id for f in rep.figures if f.section == "checks"]
    assert ids == ["checks-A"]
    html = (tmp_path / "report.html").read_text()
    assert '<h2 id="checks">Probe checks</h2>' in html and 'id="checks-A"' in html


def test_check_probe_in_python_is_the_command(fleet, tmp_path):
    import endocal as ec

    h = _copy(fleet, tmp_path)
    c = ec.check_probe([str(p) for p in fleet["models"]["B"]], "B", h, seed=9)
    assert repr(c) == "B: baseline, 3 of 10 checks since calibration (the control limits come from the first 10)"
    assert c.state == "baseline" and c.to_dict()["exit_code"] == 0 and len(c.figures) == 10
    unsaved = ec.load_model(fleet["models"]["B"][0])
    unsaved.path = None
    with pytest.raises(ValueError, match="is not saved"):
        ec.check_probe(unsaved, "B", h)
