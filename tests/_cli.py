"""Running the `endocal` command as a user would, and checking its one-line errors."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import traceback
from pathlib import Path

from typer.testing import CliRunner

ROOT = Path(__file__).resolve().parents[1]
_runner = CliRunner()


def endocal(*args, timeout: float = 600, env: dict | None = None, process: bool = False):
    """``endocal ARGS`` run from the project root; a CompletedProcess (text).

    By default the command runs in this process through the real root app (the same
    parsing, error handling and exit codes as the console script, without a Python start
    and a numba cache load per call, which made the CLI tests spend most of their time
    starting up). ``process=True``, or an ``env`` (which a running process cannot take in
    full: the temporary folder is read once), runs ``python -m endocal`` in a child
    process; ``env`` adds to (or overrides) this process's environment there.
    """
    argv = [str(a) for a in args]
    if process or env:
        return subprocess.run([sys.executable, "-m", "endocal", *argv], capture_output=True, text=True,
                              cwd=ROOT, timeout=timeout, env={**os.environ, **env} if env else None)
    from endocal.cli import app
    from endocal.cli import commands  # noqa: F401  (registers the subcommands, as the console script does)

    with contextlib.chdir(ROOT):
        res = _runner.invoke(app, argv)
    stderr = res.stderr
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        # what the console script would print for an uncaught exception
        stderr += "".join(traceback.format_exception(res.exception))
    return subprocess.CompletedProcess([sys.executable, "-m", "endocal", *argv], res.exit_code, res.stdout, stderr)


def one_line_exit_2(proc, *fragments):
    """Exit code 2 and exactly one line on stderr, holding every fragment; no traceback."""
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for f in fragments:
        assert f in lines[0], lines[0]
