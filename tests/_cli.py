"""Running the real `endocal` command as a user would, and checking its one-line errors."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def endocal(*args, timeout: float = 600, env: dict | None = None):
    """``python -m endocal ARGS`` from the project root; the CompletedProcess (text).

    ``env`` adds to (or overrides) this process's environment.
    """
    return subprocess.run([sys.executable, "-m", "endocal", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT, timeout=timeout, env={**os.environ, **env} if env else None)


def one_line_exit_2(proc, *fragments):
    """Exit code 2 and exactly one line on stderr, holding every fragment; no traceback."""
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for f in fragments:
        assert f in lines[0], lines[0]
