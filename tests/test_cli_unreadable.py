"""Unreadable input files get one line and exit code 2 on every command that reads them.

A text file renamed ``.parquet``, a truncated Parquet part, a CSV that is no table, JSON
that is not JSON or not an endocal file: each must stop the command with one line that
names the file, never a traceback, and nothing half-written.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from endocal.cli import app
from endocal.cli import commands  # noqa: F401  (registers the subcommands)

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "data_samples" / "sim-triangle"
runner = CliRunner()


@pytest.fixture(scope="module")
def bad(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("bad")
    files = {
        "text.parquet": b"hello world\n",
        "random.parquet": bytes(range(256)) * 12,
        "binary.csv": b"\x00\x01\x02binary\xff\xfe\n",
        "broken.json": b"not json {",
        "other.json": b'{"a": 1}',
        "list.json": b"[1, 2, 3]",
    }
    out = {}
    for name, content in files.items():
        (d / name).write_bytes(content)
        out[name] = d / name
    # a run folder whose aligned table is junk, and one whose motor parts are truncated
    junk_aligned = d / "run-junk-aligned"
    shutil.copytree(SAMPLE, junk_aligned)
    (junk_aligned / "aligned.parquet").write_text("garbage")
    out["run-junk-aligned"] = junk_aligned
    truncated = d / "run-truncated-stream"
    shutil.copytree(SAMPLE, truncated)
    (truncated / "aligned.parquet").unlink()
    for part in (truncated / "motor").glob("part-*.parquet"):
        part.write_bytes(part.read_bytes()[:5])
    out["run-truncated-stream"] = truncated
    broken_meta = d / "run-broken-json"
    shutil.copytree(SAMPLE, broken_meta)
    (broken_meta / "run.json").write_text("{")
    out["run-broken-json"] = broken_meta
    return out


def _one_line_exit_2(result, name: str) -> None:
    assert result.exit_code == 2, (result.exit_code, result.output)
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1, result.output
    assert lines[0].startswith("error:") and name in lines[0], lines[0]
    assert "Traceback" not in result.output


@pytest.mark.parametrize("data", ["text.parquet", "random.parquet", "binary.csv", "run-junk-aligned",
                                  "run-truncated-stream", "run-broken-json"])
def test_unreadable_data_is_one_line_on_fit_validate_and_report(bad, data, tmp_path):
    src = bad[data]
    model = tmp_path / "m.json"
    result = runner.invoke(app, ["fit", "hysteresis", str(src), "--model", "linear", "--axis", "ap",
                                 "--out", str(model)])
    _one_line_exit_2(result, src.name)
    assert not model.exists()
    good = tmp_path / "good.json"
    assert runner.invoke(app, ["fit", "hysteresis", str(SAMPLE), "--model", "linear", "--axis", "ap",
                               "--out", str(good)]).exit_code == 0
    _one_line_exit_2(runner.invoke(app, ["validate", str(good), str(src)]), src.name)
    html = tmp_path / "r.html"
    _one_line_exit_2(runner.invoke(app, ["report", str(good), "--data", str(src), "--out", str(html)]), src.name)
    assert not html.exists()


@pytest.mark.parametrize("model", ["broken.json", "other.json", "list.json", "text.parquet"])
def test_a_file_that_is_not_an_endocal_model_is_one_line(bad, model, tmp_path):
    src = bad[model]
    _one_line_exit_2(runner.invoke(app, ["validate", str(src), str(SAMPLE)]), src.name)
    run = tmp_path / "run"
    _one_line_exit_2(runner.invoke(app, ["excite", "triangle", "--model", str(src), "--out", str(run)]), src.name)
    assert not run.exists()


@pytest.mark.parametrize("planes", ["broken.json", "other.json", "list.json"])
def test_a_bad_planes_file_is_one_line(bad, planes, tmp_path):
    src = bad[planes]
    model = tmp_path / "m.json"
    result = runner.invoke(app, ["fit", "hysteresis", str(SAMPLE), "--model", "linear", "--axis", "ap",
                                 "--planes", str(src), "--out", str(model)])
    _one_line_exit_2(result, src.name)
    assert not model.exists()


def test_no_command_writes_over_its_own_inputs(tmp_path):
    """A slip of the shell must not replace a recording or a model with a command's result.

    `--out` / `--json-out` naming one of the command's inputs (the data, the model, the
    estimation data the model file names, the report's side file that is the model) is one
    line and exit 2, with `--force` too, and every input keeps its bytes.
    """
    piezo = REPO / "data_samples" / "piezo" / "piezo_aligned.csv"
    est, val, model = tmp_path / "est.csv", tmp_path / "val.csv", tmp_path / "m.json"
    lines = piezo.read_text().splitlines(keepends=True)
    est.write_text("".join(lines[:801]))
    val.write_text("".join(lines[:1] + lines[801:1601]))
    res = runner.invoke(app, ["fit", "hysteresis", str(est), "--axis", "piezo", "--model", "linear", "--out", str(model)])
    assert res.exit_code == 0, res.output
    before = {p: p.read_bytes() for p in (est, val, model)}
    for args, name in [
        (["fit", "hysteresis", str(est), "--axis", "piezo", "--out", str(est), "--force"], "est.csv"),
        (["validate", str(model), str(val), "--json-out", str(val)], "val.csv"),
        (["validate", str(model), str(val), "--json-out", str(model)], "m.json"),
        (["validate", str(model), str(val), "--json-out", str(est)], "est.csv"),  # the model's recorded estimation data
        (["report", str(model), "--data", str(val), "--out", str(tmp_path / "m.html"), "--force"], "m.json"),
        (["import", "csv", str(val), "--map", str(tmp_path / "map.toml"), "--out", str(val), "--force"], "val.csv"),
        (["import", "csv", str(val), "--draft-map", str(val), "--force"], "val.csv"),
    ]:
        res = runner.invoke(app, args)
        _one_line_exit_2(res, name)
        assert "is one of this command's inputs" in res.output, res.output
    assert {p: p.read_bytes() for p in before} == before
    # nor does --force replace a file of the lab's that is not a table endocal writes
    notes = tmp_path / "notes.csv"
    notes.write_text("date,remark\n2026-11-25,probe 2 re-taped\n")
    (tmp_path / "map.toml").write_text('probe = "tee"\n[time]\ncolumn = "t_s"\n[knobs.ap]\nposition = "piezo_cmd_deg"\n'
                                       '[angles.ap]\ncolumn = "piezo_meas_deg"\n')
    res = runner.invoke(app, ["import", "csv", str(val), "--map", str(tmp_path / "map.toml"), "--out", str(notes),
                              "--force"])
    _one_line_exit_2(res, "notes.csv")
    assert "is not an aligned table" in res.output and notes.read_text().startswith("date,remark")


def test_every_output_makes_the_folders_it_names(tmp_path):
    """`--out results/ap/m.json` works as `excite --out runs/a/b` always did: every command
    creates the missing folders of its outputs (one rule in the atomic writer), and refuses,
    in one line, only a path that cannot become a folder (a file on the way)."""
    piezo = REPO / "data_samples" / "piezo" / "piezo_aligned.csv"
    lines = piezo.read_text().splitlines(keepends=True)
    est, val = tmp_path / "est.csv", tmp_path / "val.csv"
    est.write_text("".join(lines[:801]))
    val.write_text("".join(lines[:1] + lines[801:1601]))
    model, js, html = tmp_path / "models" / "a" / "m.json", tmp_path / "out" / "v.json", tmp_path / "rep" / "r.html"
    for args, made in [
        (["fit", "hysteresis", str(est), "--axis", "piezo", "--model", "linear", "--out", str(model)], [model]),
        (["validate", str(model), str(val), "--json-out", str(js)], [js]),
        (["report", str(model), "--data", str(val), "--out", str(html)], [html, html.with_suffix(".json")]),
        (["import", "csv", str(val), "--draft-map", str(tmp_path / "maps" / "m.toml")], [tmp_path / "maps" / "m.toml"]),
    ]:
        res = runner.invoke(app, args)
        assert res.exit_code == 0, res.output
        assert all(p.is_file() for p in made), (args, res.output)
    json.loads(js.read_text())  # whole files, not stubs
    # with the mode any new file gets (the temporary file of an atomic write is private, 0600,
    # which left every model and run unreadable to the rest of the lab)
    mask = os.umask(0o022)
    os.umask(mask)
    assert {oct(p.stat().st_mode & 0o777) for p in (model, js, html)} == {oct(0o666 & ~mask)}
    res = runner.invoke(app, ["fit", "hysteresis", str(est), "--axis", "piezo", "--out", str(est / "m.json")])
    _one_line_exit_2(res, "est.csv")
