"""The ``endocal`` command line: a thin layer over the library.

Each command parses its arguments, calls one library function that returns a result
object, and renders it. Library errors become one line on stderr and exit code 2.
"""

from __future__ import annotations

import typer
from typer.core import TyperGroup


class Group(TyperGroup):
    """A command group whose ``--help`` flag is ``False`` when not given (Typer leaves it ``None``).

    Typer 0.29 converts every parameter value that is not already of its type through
    pydantic, so a ``None`` help flag on the way to a subcommand (``endocal fit planes
    --help``, ``endocal excite RUN``) imported pydantic: a tenth of a second on every
    command's start, for nothing. Every group of the command line uses this class (root
    here, the others in :mod:`endocal.cli.commands`).
    """

    def get_help_option(self, ctx):
        option = super().get_help_option(ctx)
        if option is not None and option.default is None:
            option.default = False
        return option


app = typer.Typer(
    name="endocal",
    cls=Group,
    help="Calibration and experiment toolkit for robot-driven, tendon-driven flexible endoscopes.\n\n"
    "The loop: `excite` a probe (simulated by default) -> `fit` bending planes and hysteresis -> "
    "`validate` the model against measurements -> `report`.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # help in Click's plain format: paragraphs reflow to the terminal and `[angles.AXIS]` prints as
    # written; Typer's rich help imports rich's console, Markdown and traceback renderers, half of
    # the start-up (tests/test_cli_startup.py, bench/bench_startup.py)
    rich_markup_mode=None,
)


def _version(value: bool) -> None:
    if value:
        from endocal._version import __version__

        typer.echo(f"endocal {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Print the version and exit."),
) -> None:
    """Calibration and experiment toolkit for tendon-driven endoscopes."""


def main() -> None:
    """Console-script entry point."""
    from endocal.cli import commands  # noqa: F401  (registers the subcommands on ``app``)

    app()
