"""``--effects-file``: the option every command that fits, validates, reports, plays back or lists effects takes.

The command loads the files first (:func:`use_effects_files`), so a model file that records a
user's effect finds it registered, and a refit command the command prints gives the same files.
"""

from __future__ import annotations

from pathlib import Path

import typer

HELP = ("A Python file of your own effects (and bases), repeatable: loaded, checked and registered before anything "
        "else (docs/how-to/add-effect.md). It runs as Python, as a conftest.py does: give only files you trust.")


def effects_file_option():
    """The ``--effects-file FILE.py`` option (repeatable)."""
    return typer.Option([], "--effects-file", help=HELP)


def use_effects_files(paths: list[Path]) -> None:
    """Load ``paths`` and the installed ``endocal.effects`` entry points; a model fitted with a file that
    changed since, given here anyway, prints ``warning: ...`` on stderr when it loads.

    Raises
    ------
    EffectFileError
        One line naming the file and the effect.
    """
    import warnings

    from endocal.cli._common import err
    from endocal.models.userfile import EffectFileWarning, load_effects_files

    previous = warnings.showwarning
    if not getattr(previous, "endocal_effects_file", False):  # once per process, however many commands run

        def show(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, EffectFileWarning):
                err.print(f"warning: {message}", markup=False)
            else:
                previous(message, category, filename, lineno, file, line)

        show.endocal_effects_file = True
        warnings.showwarning = show
    load_effects_files(paths)
