"""Registers every subcommand on the root app (kept apart so importing the app stays cheap).

Every module imported here is imported by every command's ``--help``: what a command needs
beyond typer and rich it imports inside its function (tests/test_cli_startup.py holds this).
"""

from endocal.cli import Group, app
from endocal.cli import emulate as _emulate
from endocal.cli import export as _export
from endocal.cli import fit as _fit
from endocal.cli import imports as _imports
from endocal.cli import protocols as _protocols
from endocal.cli.check import check
from endocal.cli.effects import effects
from endocal.cli.excite import excite
from endocal.cli.history import history
from endocal.cli.info import info
from endocal.cli.report import report
from endocal.cli.ros import import_ros
from endocal.cli.validate import validate

app.command("excite")(excite)
app.command("info")(info)
app.command("effects")(effects)
app.command("validate")(validate)
app.command("report")(report)
app.command("check")(check)
app.command("history")(history)
app.command("import-ros")(import_ros)
app.add_typer(_protocols.app, name="protocols", cls=Group)
app.add_typer(_fit.app, name="fit", cls=Group)
app.add_typer(_imports.app, name="import", cls=Group)
app.add_typer(_emulate.app, name="emulate", cls=Group)
app.add_typer(_export.app, name="export", cls=Group)
