"""Shell text: the command lines endocal suggests, built from a result's data in one place.

The library returns what to do as data: a :class:`~endocal.validation.refit.Refit` (the fit
``validate`` scored), the ``excite`` argument lists of a next experiment
(:class:`~endocal.validation.next_experiment.NextOutcome`), the records and options of a
validation. This module writes them as a POSIX shell takes them (``shlex``: a lab folder with a
space in its name is quoted); the terminal summary, ``validate --json`` and the Python API
(``Suggestion.command``, ``Validation.to_dict``) all call it, and nothing under
``endocal/validation`` or ``endocal/models`` builds shell text.

It imports nothing of the library: the command line's ``--help`` imports it.
"""

from __future__ import annotations

import json
import re
import shlex
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the command line's help must not load the library (numpy, scipy)
    from endocal.validation.refit import Refit


def refit_argv(refit: Refit) -> list[str]:
    """``endocal fit hysteresis DATA... --axis AXIS --model BASE --effects E1,E2 [--planes P] [--set K=V...]
    [--start-from M] [--start-value NAME=V...] --out OUT`` as an argument list.

    Setting values are written as ``--set`` reads them (:func:`setting_value`); start values as the refit
    holds them (already rounded to the digits a start needs, so the command and ``Suggestion.refit()`` agree).
    """
    parts = ["endocal", "fit", "hysteresis", *refit.data_paths]
    if refit.axis:
        parts += ["--axis", refit.axis]
    parts += ["--model", refit.base]
    if refit.effects:
        parts += ["--effects", ",".join(refit.effects)]
    if refit.planes_path:
        parts += ["--planes", refit.planes_path]
    for k, v in refit.settings.items():
        parts += ["--set", f"{k}={setting_value(v)}"]
    if refit.start_from:
        parts += ["--start-from", refit.start_from]
    for k, v in refit.start_values.items():
        parts += ["--start-value", f"{k}={v!r}"]
    return parts + effects_file_args(refit.base, refit.effects) + ["--out", refit.out_path]


def setting_value(v) -> str:
    """A base setting's value as ``--set KEY=VALUE`` reads it back (TOML, else a plain word): a word as it is
    (``exponential``), anything else as JSON (``false``, ``30``, ``"two words"``)."""
    if isinstance(v, str) and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.-]*", v) and v not in _TOML_WORDS:
        return v
    return json.dumps(v)


#: Bare words TOML reads as something other than a string.
_TOML_WORDS = ("true", "false", "inf", "nan")


def effects_file_args(base: str | None = None, effects: Sequence[str] = ()) -> list[str]:
    """``--effects-file PATH`` for each of a user's files a refit of ``base`` + ``effects`` needs; without
    ``base``, for every file this session was given (a command that repeats this one)."""
    from endocal.models.userfile import files_for, given_files

    paths = given_files() if base is None else files_for(base, effects or ())
    return [a for path in paths for a in ("--effects-file", str(path))]


def refit_command(refit: Refit) -> str:
    """:func:`refit_argv` as one shell line."""
    return shlex.join(refit_argv(refit))


def excite_commands(argvs: Sequence[Sequence[str]]) -> list[str]:
    """The ``excite`` argument lists of a next experiment as shell lines."""
    return [shlex.join(list(a)) for a in argvs]


def report_command(models: Sequence[str], data: Sequence[str], out: str = "report.html") -> str:
    """``endocal report MODEL... --data D... --out OUT``: the models compared on the records, with figures."""
    return shlex.join(["endocal", "report", *map(str, models), *(a for d in data for a in ("--data", str(d))),
                       "--out", out])


def validate_command(model: str, data: Sequence[str], *, train: Sequence[str] = (), cv: str = "auto",
                     planes: str | None = None, probe: str = "tee", next_path: str | None = None) -> str:
    """``endocal validate MODEL DATA... [--train T...] [--cv CV] [--planes P] [--probe P] [--next N]``
    (options at their defaults are left out)."""
    return shlex.join(["endocal", "validate", str(model), *map(str, data),
                       *(a for t in train for a in ("--train", str(t))), *(["--cv", cv] if cv != "auto" else []),
                       *(["--planes", str(planes)] if planes is not None else []),
                       *(["--probe", str(probe)] if str(probe) != "tee" else []), *effects_file_args(),
                       *(["--next", str(next_path)] if next_path is not None else [])])
