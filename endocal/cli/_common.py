"""What every CLI command shares: turning library errors into one line and exit code 2."""

from __future__ import annotations

import functools
import sys
from typing import Callable, TypeVar

import typer
from rich.console import Console
from rich.markup import escape

from endocal.errors import EndocalError

F = TypeVar("F", bound=Callable)

#: Results go to stdout; progress and diagnostics to stderr so ``--json`` output stays clean.
out = Console(highlight=False, soft_wrap=True)
err = Console(stderr=True, highlight=False, soft_wrap=True)


def fail(message: str, code: int = 2) -> None:
    """Print ``error: <message>`` on one line to stderr and exit with ``code``."""
    err.print(f"[bold red]error:[/] {escape(message)}", markup=True)
    raise typer.Exit(code)


def cli_errors(func: F) -> F:
    """Decorate a command so that user errors become one line on stderr and exit code 2.

    :class:`~endocal.errors.EndocalError` (and OS errors on paths the user named) are the
    user's to fix; anything else is a bug and keeps its traceback.
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except EndocalError as exc:
            fail(str(exc))
        except (FileNotFoundError, PermissionError, IsADirectoryError, NotADirectoryError) as exc:
            where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
            fail(f"{exc.strerror or exc}{where}")

    return wrapper  # type: ignore[return-value]


def stdout_is_terminal() -> bool:
    return sys.stdout.isatty()
