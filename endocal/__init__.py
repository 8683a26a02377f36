"""endocal: calibration and experiment toolkit for tendon-driven flexible endoscopes.

The package is a quiet library (it never prints or exits); the command line in
:mod:`endocal.cli` is a thin layer over it.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("endocal-toolkit")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
