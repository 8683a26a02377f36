"""The optional ``[fleet]`` extra (DuckDB, Dask): imported when used, refused in one line when missing."""

from __future__ import annotations

import importlib

from endocal.errors import EndocalError

INSTALL = "pip install 'endocal-toolkit[fleet]'"


class ExtraMissingError(EndocalError, ImportError):
    """A feature needs a package of an optional extra that is not installed."""


def require(module: str, what: str):
    """Import ``module`` for ``what``, or raise :class:`ExtraMissingError` saying how to install it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        top = module.split(".")[0]
        raise ExtraMissingError(f"{what} needs {top}, which is not installed: {INSTALL}") from None
