"""Data flows one way (STYLE.md): no module imports a layer that sits downstream of it.

protocol -> backend (sim or hardware) -> run on disk -> fit -> model file -> validate -> report,
with the CLI on top of all of them. The simulator, the run format and the models must not
reach back into the backends, and no library module may import the CLI.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "endocal"

# package -> packages it must never import
FORBIDDEN = {
    "sim": ("endocal.backends", "endocal.cli", "endocal.validation", "endocal.report"),
    "runs": ("endocal.backends", "endocal.cli", "endocal.validation", "endocal.report"),
    # a model file is not a run: its atomic write is endocal.files, not the run format's
    "models": ("endocal.backends", "endocal.cli", "endocal.validation", "endocal.report", "endocal.sim", "endocal.runs"),
    "kinematics": ("endocal.backends", "endocal.cli", "endocal.sim", "endocal.models"),
    "planes": ("endocal.backends", "endocal.cli", "endocal.report"),
    "validation": ("endocal.cli", "endocal.report"),
    "report": ("endocal.cli",),
    "protocols": ("endocal.backends", "endocal.cli", "endocal.sim"),
    "force": ("endocal.cli",),
    # probe checks sit beside validate: the report draws their charts (report --history), not the reverse
    "check": ("endocal.cli", "endocal.report"),
    "backends": ("endocal.cli",),
    # exports read runs and models, and never reach into the backends or the command line
    "export": ("endocal.backends", "endocal.cli", "endocal.report"),
}


def _imports(path: Path) -> list[str]:
    names = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
    return names


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_no_import_runs_upstream(package):
    bad = []
    for path in sorted((PKG / package).rglob("*.py")):
        for name in _imports(path):
            if any(name == f or name.startswith(f + ".") for f in FORBIDDEN[package]):
                bad.append(f"{path.relative_to(PKG.parent)} imports {name}")
    assert not bad, "\n".join(bad)
