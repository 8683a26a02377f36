"""What every CLI command shares: turning library errors into one line and exit code 2."""

from __future__ import annotations

import contextlib
import functools
import math
import sys
import warnings
from pathlib import Path
from typing import Callable, TypeVar

import typer

from endocal.errors import EndocalError, HardwareError

#: Exit code of a hardware fault (a device failed, is missing or answered wrongly); bad input exits 2.
HARDWARE_EXIT_CODE = 3

F = TypeVar("F", bound=Callable)


class _Console:
    """A :class:`rich.console.Console` made on first use: importing rich's console costs a tenth
    of ``endocal --help``'s start-up, and help never prints through it."""

    def __init__(self, **options) -> None:
        self._options = options
        self._console = None

    @property
    def console(self):
        """The rich console itself (for rich objects that take one: ``Progress(console=...)``)."""
        if self._console is None:
            from rich.console import Console

            self._console = Console(**self._options)
        return self._console

    def __getattr__(self, name: str):
        return getattr(self.console, name)


#: Results go to stdout; progress and diagnostics to stderr so ``--json`` output stays clean.
out = _Console(highlight=False, soft_wrap=True)
err = _Console(stderr=True, highlight=False, soft_wrap=True)


def fail(message: str, code: int = 2) -> None:
    """Print ``error: <message>`` on one line to stderr and exit with ``code``."""
    from rich.markup import escape

    err.print(f"[bold red]error:[/] {escape(message)}", markup=True)
    raise typer.Exit(code)


def cli_errors(func: F) -> F:
    """Decorate a command so that user errors become one line on stderr and exit code 2
    (hardware faults: exit code 3).

    :class:`~endocal.errors.EndocalError` (and OS errors on paths the user named) are the
    user's to fix; anything else is a bug and keeps its traceback. Every command's ``--seed``
    is checked here, before any work: numpy's generators take no negative seed.
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        seed = kwargs.get("seed")
        if isinstance(seed, int) and seed < 0:
            fail(f"--seed must be a non-negative integer, got {seed}")
        try:
            return func(*args, **kwargs)
        except HardwareError as exc:  # a device failed or is missing: exit code 3, not the user's input
            fail(str(exc), code=HARDWARE_EXIT_CODE)
        except EndocalError as exc:
            fail(str(exc))
        except (FileNotFoundError, PermissionError, IsADirectoryError, NotADirectoryError) as exc:
            where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
            fail(f"{exc.strerror or exc}{where}")

    return wrapper  # type: ignore[return-value]


def refuse_input_as_output(flag: str, output: Path | None, inputs) -> None:
    """Refuse to write ``output`` over one of the command's own input files (with or without ``--force``).

    A slip of the shell (``--json-out run.csv``, ``--out log.csv --force``) would otherwise
    replace a recording or a model with the command's result, and nothing could bring it back.

    Raises
    ------
    OutputPathError
    """
    from endocal.errors import OutputPathError

    if output is None:
        return
    target = Path(output).resolve()
    for p in inputs:
        if p is not None and Path(p).resolve() == target:
            raise OutputPathError(f"{flag} {output} is one of this command's inputs; writing there would replace it: "
                                  "choose another path")


def slow_clock_warning(n_samples: int, span_s: float) -> str | None:
    """``warning: ...`` (keyed ``slow-clock``) when records hold under one sample per second, else None
    (:func:`endocal.validation.offline.slow_clock`, which ``validate`` notes too)."""
    from endocal.messages import Message
    from endocal.validation.offline import slow_clock

    text = slow_clock(n_samples, span_s)
    return Message("warning: " + text, text.key) if text else None


def stdout_is_terminal() -> bool:
    return sys.stdout.isatty()


#: Help text of ``--out-of-range`` on every command that plays a model.
OUT_OF_RANGE_HELP = ("A desired angle the model cannot reach within its fitted range is an `error` (nothing moves), "
                     "or is `clamp`ed to the range. Default: the model file's own setting.")


def apply_out_of_range(model, value: str | None) -> None:
    """Set a loaded model's ``out_of_range`` from ``--out-of-range`` (``None`` keeps the file's)."""
    from endocal.errors import ModelError
    from endocal.models.base import OUT_OF_RANGE_CHOICES

    if value is None:
        return
    if value not in OUT_OF_RANGE_CHOICES:
        raise ModelError(f"--out-of-range must be one of {', '.join(OUT_OF_RANGE_CHOICES)}, got {value!r}")
    model.out_of_range = value


@contextlib.contextmanager
def warnings_as_lines():
    """Print the library's warnings raised inside the block as ``warning: ...`` lines on stderr.

    Each distinct message once, after the block, instead of Python's file:line form.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            yield
        finally:
            seen = set()
            for w in caught:
                text = str(w.message)
                if text not in seen:
                    seen.add(text)
                    err.print(f"warning: {text}", markup=False)


def guard_factory(force_model, max_force_n, probe):
    """From ``--force-model``/``--max-force-n``: a function making a fresh contact-force guard, or None.

    Everything is checked here, before anything moves: the force model's file, its probe and
    axis, and the threshold.
    """
    if force_model is None and max_force_n is None:
        return None
    from endocal.errors import ModelError
    from endocal.force import ForceGuard, check_guard_fits, load_force_model

    if force_model is None:
        raise ModelError("--max-force-n needs --force-model force.json (endocal fit force): the guard predicts the force from it")
    fmodel = load_force_model(force_model)
    check_guard_fits(fmodel, probe, max_force_n)
    ForceGuard(fmodel, max_force_n)  # a bad threshold is refused here
    return lambda: ForceGuard(fmodel, max_force_n)


def finite(obj):
    """JSON has no NaN or infinity: write them as null."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite(v) for v in obj]
    return obj


def write_json_file(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (a reader never sees half a file)."""
    from endocal.errors import OutputPathError
    from endocal.runs.format import atomic_write_bytes

    try:
        atomic_write_bytes(path, (text + "\n").encode())
    except OSError as exc:
        raise OutputPathError(f"cannot write {path}: {exc.strerror}") from None


def emit_json(d: dict, as_json: bool, json_out: Path | None) -> bool:
    """Write ``d`` to ``json_out`` (when given) and print it (``--json``); True when printed, so
    the caller skips its terminal view."""
    import json

    text = json.dumps(finite(d), allow_nan=False)
    if json_out is not None:
        write_json_file(json_out, text)
    if as_json:
        out.print_json(text)
    return as_json
