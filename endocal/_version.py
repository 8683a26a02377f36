"""The version of endocal: the one place it is written (pyproject.toml reads it from here).

A plain string, so that ``endocal --version`` and every command's start need not import
:mod:`importlib.metadata` (tens of milliseconds) to learn it.
"""

__version__ = "0.1.0"
