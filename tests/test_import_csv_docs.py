"""What a user of `import csv` reads is what happens: the how-to's output, the rate, the next step.

- the how-to (docs/how-to/import-csv.md) shows the output of its commands: they are run on the
  logs scripts/make_example_logs.py writes, in the folder it writes them to, and compared line
  for line;
- the example scripts write outside the repository unless told where;
- one log has one sample rate, whichever command states it (import, info, fit:
  :func:`endocal.runs.format.sample_rate_hz`);
- after an import, the next step names the axis the log commands and measures.
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import re
import shlex
import subprocess
import traceback
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from tests._cli import endocal

ROOT = Path(__file__).resolve().parents[1]
HOWTO = ROOT / "docs" / "how-to" / "import-csv.md"


def _in(folder: Path, command: str) -> str:
    """``command`` (an `endocal ...` line of the how-to) run in ``folder``, in-process as the console
    script runs it: what a terminal shows (stdout and stderr, in the order written)."""
    from endocal.cli import app
    from endocal.cli import commands  # noqa: F401  (registers the subcommands)

    argv = shlex.split(command)[1:]
    with contextlib.chdir(folder):
        res = CliRunner().invoke(app, argv)
    assert res.exception is None or isinstance(res.exception, SystemExit), "".join(
        traceback.format_exception(res.exception))
    return res.output


def _console_blocks(text: str) -> list[list[tuple[str, list[str]]]]:
    """The how-to's console blocks that run only `endocal` and show output: ``[(command, lines)]`` each."""
    blocks = []
    for body in re.findall(r"```console\n(.*?)```", text, flags=re.S):
        steps: list[tuple[str, list[str]]] = []
        for line in body.splitlines():
            if line.startswith("$ "):
                steps.append((line[2:], []))
            elif steps:
                steps[-1][1].append(line)
        if steps and all(c.startswith("endocal ") for c, _ in steps) and any(out for _, out in steps):
            blocks.append(steps)
    return blocks


@pytest.fixture(scope="module")
def examples(tmp_path_factory) -> Path:
    from scripts.make_example_logs import EXCITE, write_logs

    out = tmp_path_factory.mktemp("examples")
    proc = endocal(*EXCITE, "--out", out / "example-run")  # what the script runs, in-process
    assert proc.returncode == 0, proc.stderr
    write_logs(out / "example-run", out)
    return out


def test_the_howtos_commands_print_what_it_shows(examples):
    blocks = _console_blocks(HOWTO.read_text())
    assert len(blocks) >= 3, "the how-to's draft, import and angles examples"
    ran = 0
    for steps in blocks:
        for command, shown in steps:
            printed = [ln for ln in _in(examples, command).splitlines() if ln.strip()]
            assert printed == shown, f"`{command}` prints\n" + "\n".join(printed) + "\nthe how-to shows\n" + "\n".join(
                shown)
            ran += 1
    assert ran >= 5


def test_the_example_scripts_write_outside_the_repository_by_default(tmp_path):
    from scripts.make_example_logs import default_dir

    spec = importlib.util.spec_from_file_location("make_samples", ROOT / "data_samples" / "make_samples.py")
    samples = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(samples)
    for where in (default_dir(), samples.default_dir()):
        assert not where.resolve().is_relative_to(ROOT.resolve()), where
    # the demo, run by hand without a folder: into TMPDIR/endocal-demo (a stub `endocal` records
    # where the first command writes, and stops the script)
    stub = tmp_path / "bin" / "endocal"
    stub.parent.mkdir()
    stub.write_text('#!/bin/sh\necho "$@" > "$(dirname "$0")/args"\nexit 3\n')
    stub.chmod(0o755)
    proc = subprocess.run(["bash", str(ROOT / "scripts" / "demo.sh")], cwd=tmp_path, capture_output=True, text=True,
                          env={**os.environ, "PATH": f"{stub.parent}:{os.environ['PATH']}", "TMPDIR": str(tmp_path)},
                          timeout=60)
    assert proc.returncode == 3, proc.stderr
    assert f"--out {tmp_path}/endocal-demo/planes" in (stub.parent / "args").read_text()
    assert f"into {tmp_path}/endocal-demo" in proc.stdout


def _jittery_log(path: Path, rate_hz: float = 500.0, seconds: float = 6.0, drop_every: int = 37) -> None:
    """A bench log on a 500 Hz clock with jitter, one row in ``drop_every`` lost (a USB logger)."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, seconds, 1.0 / rate_hz)
    t = t + rng.normal(0.0, 2e-5, t.size)
    keep = np.arange(t.size) % drop_every != 5
    cmd = 30.0 * np.sin(2 * np.pi * 0.5 * t)
    pd.DataFrame({"time_ms": 1000.0 * t, "motor_rad": np.radians(cmd), "joint_deg": 0.8 * cmd,
                  "sheath_deg": 180.0})[keep].to_csv(path, index=False)


def test_one_log_has_one_sample_rate_in_import_info_and_fit(tmp_path):
    _jittery_log(tmp_path / "log.csv")
    table = tmp_path / "log.parquet"
    imp = endocal("import", "csv", tmp_path / "log.csv", "--map", ROOT / "configs" / "csv-map.angles.example.toml",
                  "--out", table)
    assert imp.returncode == 0, imp.stderr
    info = endocal("info", table)
    fit = endocal("fit", "hysteresis", table, "--axis", "ap", "--model", "linear", "--out", tmp_path / "m.json")
    assert info.returncode == 0 and fit.returncode == 0, (info.stderr, fit.stderr)
    rates = [re.search(r"([\d.]+) Hz", p.stdout).group(1) for p in (imp, info, fit)]
    # the clock's rate: 500 Hz to the jitter's 2e-5 s in 2e-3 s; the 1 row in 37 lost does not count
    assert rates[0] == rates[1] == rates[2], rates
    assert abs(float(rates[0]) - 500.0) < 0.5, rates


def test_after_an_import_the_next_step_names_the_axis(tmp_path):
    _jittery_log(tmp_path / "log.csv")
    proc = endocal("import", "csv", tmp_path / "log.csv", "--map", ROOT / "configs" / "csv-map.angles.example.toml",
                   "--out", tmp_path / "t.parquet")
    assert proc.returncode == 0, proc.stderr
    table = tmp_path / "t.parquet"
    assert proc.stderr.splitlines()[-1] == f"next: endocal fit hysteresis {table} --axis ap --out MODEL.json"
