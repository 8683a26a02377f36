"""``endocal protocols`` end to end through Typer's test runner (endocal/cli/protocols.py)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from endocal.cli.protocols import app

REPO = Path(__file__).resolve().parents[1]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def runner():
    return CliRunner()


def test_listing_without_subcommand(runner):
    res = runner.invoke(app, [])
    assert res.exit_code == 0, res.output
    lines = res.stdout.splitlines()
    rows = {line.split()[0]: line for line in lines[1:] if line.strip() and not line.startswith("Show")}
    for name in ("sine-set", "sine-varying", "damped-sine", "triangle", "chirp", "chirp-log", "random",
                 "staircase", "circle", "lissajous", "planes"):
        assert name in rows
    assert re.search(r"damped-sine\s+140 s\s+axis1\s+Duodenoscope", rows["damped-sine"])
    assert re.search(r"planes\s+[\d.]+ s\s+axis1, axis2\s", rows["planes"])


def test_show_prints_parameters_overrides_and_source(runner):
    res = runner.invoke(app, ["show", "damped-sine", "--set", "amplitude_deg=40", "--probe", "duodenoscope"])
    assert res.exit_code == 0, res.output
    out = res.stdout
    assert re.search(r"amplitude_deg = 40\.0\s+#.*\(override\)", out)
    assert re.search(r"frequency_hz = 0\.05\s+#", out) and "(override)" not in out.split("frequency_hz")[1].splitlines()[0]
    assert str(REPO / "protocols" / "damped-sine.toml") in out
    assert "duration  140 s (14001 samples at 100 Hz)" in out
    assert "axis1 -> ud (probe duodenoscope)" in out


def test_show_json(runner):
    res = runner.invoke(app, ["show", "random", "--set", "seed=4", "--set", "axes=ml", "--json"])
    assert res.exit_code == 0, res.output
    info = json.loads(res.stdout)
    assert info["name"] == "random" and info["params"]["seed"] == 4 and info["params"]["axes"] == ["ml"]
    assert info["overrides"] == {"seed": 4, "axes": "ml"}
    assert info["duration_s"] == pytest.approx(120.0) and info["dofs"] == ["ml"] and len(info["sha256"]) == 64


def test_plot_writes_a_png(runner, tmp_path):
    out = tmp_path / "planes.png"
    res = runner.invoke(app, ["plot", "planes", "--out", str(out), "--probe", "duodenoscope"])
    assert res.exit_code == 0, res.output
    assert out.read_bytes()[:8] == PNG_MAGIC and out.stat().st_size > 10_000
    assert "moving: ud, lr" in res.stdout


def test_plot_beyond_limits_warns_but_draws(runner, tmp_path):
    out = tmp_path / "s.png"
    res = runner.invoke(app, ["plot", "staircase", "--out", str(out), "--set", "amplitude_deg=95"])
    assert res.exit_code == 0, res.output
    assert "warning:" in res.stderr and "beyond the max limit 90 deg" in res.stderr
    assert out.read_bytes()[:8] == PNG_MAGIC


@pytest.mark.parametrize(
    "args,message",
    [
        (["show", "no-such-protocol"], "unknown protocol 'no-such-protocol'"),
        (["show", "damped-sine", "--set", "amp=3"], "unknown parameter(s) 'amp'"),
        (["show", "damped-sine", "--set", "amplitude_deg"], "--set expects key=value"),
        (["show", "sine", "--set", "axes=zz"], "unknown axis 'zz' for probe 'tee'"),
        (["show", "sine", "--probe", "endoscope9"], "unknown probe 'endoscope9'"),
        (["plot", "sine", "--out", "x.jpg"], "must be a .png file"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(runner, args, message):
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    assert message in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and res.stderr.startswith("error:")
    assert "Traceback" not in res.output


def test_malformed_file_by_path(runner, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('description = "x"\nsignal = "sine"\namplitude_deg = = 3\n')
    res = runner.invoke(app, ["show", str(bad)])
    assert res.exit_code == 2 and "line 3" in res.stderr and str(bad) in res.stderr


def test_plot_into_missing_folder(runner, tmp_path):
    # made, as every output's folders are; a path through a file is refused in one line
    res = runner.invoke(app, ["plot", "sine", "--out", str(tmp_path / "no" / "p.png")])
    assert res.exit_code == 0 and (tmp_path / "no" / "p.png").read_bytes().startswith(b"\x89PNG")
    (tmp_path / "f").write_text("")
    res = runner.invoke(app, ["plot", "sine", "--out", str(tmp_path / "f" / "p.png")])
    assert res.exit_code == 2 and "is not a folder" in res.stderr


def test_help_explains_itself(runner):
    for args in ([], ["show"], ["plot"]):
        res = runner.invoke(app, [*args, "--help"])
        assert res.exit_code == 0
    assert "PNG" in runner.invoke(app, ["--help"]).stdout
