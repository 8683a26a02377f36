"""What the command line imports to print its help: typer alone, not rich nor the numerical stack.

`endocal --help` and `endocal COMMAND --help` must start in at most 0.3 s (issue 26; timed by
bench/bench_startup.py). numpy, scipy, pandas, pyarrow, numba and matplotlib alone take
0.5-1 s to import, so a command imports them inside its function, never at module level; and
typer 0.29 converts a parameter value that is not yet of its type through pydantic (0.1 s),
which :class:`endocal.cli.Group` spares the help path. Help is Click's plain formatting
(``rich_markup_mode=None``): Typer's rich help imports rich's console, Markdown and traceback
renderers (0.1 s, half of the start-up), so rich is loaded only by a command that prints. This test asserts what is imported,
not how long it takes: every help screen of the app, walked from the root, run in one fresh
interpreter, then a look at ``sys.modules``.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Top-level packages a help screen must not import (each costs a tenth of a second or more).
HEAVY = ("numpy", "scipy", "pandas", "pyarrow", "numba", "matplotlib", "pydantic", "importlib.metadata", "rich")

#: Runs in a child: records which endocal line first imported each heavy package, walks the
#: whole command tree and prints every help screen, then reports as JSON on the last line.
CHILD = textwrap.dedent(
    """
    import contextlib, io, json, sys, traceback

    HEAVY = set(sys.argv[1].split(","))
    first_import = {}

    class Spy:
        def find_spec(self, name, path=None, target=None):
            top = name.partition(".")[0]
            if top in HEAVY and top not in first_import:
                frames = [f"{f.filename}:{f.lineno}" for f in traceback.extract_stack()
                          if "/endocal/" in f.filename.replace("\\\\", "/")]
                first_import[top] = frames[-3:]
            return None

    sys.meta_path.insert(0, Spy())

    import typer
    from endocal.cli import app
    from endocal.cli import commands  # noqa: F401  (what the console script's main() imports)

    def walk(cmd, path):
        yield path
        for name, sub in sorted(getattr(cmd, "commands", {}).items()):
            if not getattr(sub, "hidden", False):
                yield from walk(sub, path + [name])

    paths = list(walk(typer.main.get_command(app), []))
    helps = {}
    for path in paths:
        buf = io.StringIO()
        code = 0
        with contextlib.redirect_stdout(buf):
            try:
                app([*path, "--help"], prog_name="endocal")
            except SystemExit as exc:
                code = exc.code or 0
        helps[" ".join(path)] = (code, buf.getvalue())
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        try:
            app(["--version"], prog_name="endocal")
        except SystemExit:
            pass
    loaded = sorted(HEAVY & {m.partition(".")[0] for m in sys.modules})
    print(json.dumps({"helps": helps, "version": buf.getvalue(), "loaded": loaded, "first_import": first_import}))
    """
)


def _run_child() -> dict:
    proc = subprocess.run([sys.executable, "-c", CHILD, ",".join(HEAVY)], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_help_screens_import_nothing_heavy():
    res = _run_child()
    helps = res["helps"]
    # the walk reached every command, including the nested ones
    for path in ("", "excite", "info", "effects", "validate", "report", "import-ros", "protocols", "protocols show",
                 "protocols plot", "fit", "fit planes", "fit hysteresis", "fit force", "import", "import csv",
                 "import ros", "emulate", "emulate rig", "emulate dynamixel", "emulate aurora", "emulate stage"):
        assert path in helps, sorted(helps)
    for path, (code, text) in helps.items():
        assert code == 0 and "Usage" in text, (path, code, text[:400])
    assert res["version"].startswith("endocal "), res["version"]
    why = "; ".join(f"{pkg} first imported from {' <- '.join(reversed(where)) or 'outside endocal'}"
                    for pkg, where in res["first_import"].items())
    assert res["loaded"] == [], f"help screens imported {res['loaded']}: {why}"
