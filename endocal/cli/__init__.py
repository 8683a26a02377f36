"""The ``endocal`` command line: a thin layer over the library.

Each command parses its arguments, calls one library function that returns a result
object, and renders it. Library errors become one line on stderr and exit code 2.
"""

from __future__ import annotations

import sys

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
    """The command line, run in this process (it raises SystemExit with the command's exit code)."""
    from endocal.cli import commands  # noqa: F401  (registers the subcommands on ``app``)

    app()


def run() -> None:
    """Console-script entry point (``endocal``, ``python -m endocal``): :func:`main`, then a quick exit
    (:func:`_exit_now`)."""
    try:
        main()
    except SystemExit as exc:
        _exit_now(exc)
        raise


def _exit_now(exc: SystemExit) -> None:
    """End the process at once with ``exc``'s code, skipping the interpreter's teardown.

    Tearing down numba's and LLVM's compiled functions and every module takes 0.15 s after a bare
    import of the numerical stack and 0.35 s after ``validate`` (bench/bench_loop.py), on every
    command. Nothing is left for the teardown to do: a command closes what it writes before it
    returns (its ``with`` blocks; torque off in the hardware's ``finally``), the atexit handlers run
    here, and the standard streams are flushed. The process exits normally instead when a thread
    other than the main one is still running (the teardown waits for it) or the code is a message.
    """
    import atexit
    import os
    import threading

    code = exc.code
    if not (code is None or isinstance(code, int)) or any(
            t is not threading.main_thread() and not t.daemon and t.is_alive() for t in threading.enumerate()):
        return
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe (`endocal ... | head`): nothing more can reach it
            pass
    os._exit(code or 0)
