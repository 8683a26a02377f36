"""endocal: calibration and experiment toolkit for tendon-driven flexible endoscopes.

The package is a quiet library (it never prints or exits); the command line in
:mod:`endocal.cli` is a thin layer over it, and so is the Python API of
:mod:`endocal.api`, exported here::

    import endocal as ec
    model = ec.fit(["demo-out/train", "demo-out/chirp"], axis="ap", model="pi", effects=["envelope"])

The API's names are imported on first use (PEP 562), so ``import endocal`` and
``endocal --help`` load no numpy, pandas, scipy or matplotlib.
"""

from endocal._version import __version__  # one source for the package and pyproject (no importlib.metadata: 20 ms)

#: What ``import endocal as ec`` offers besides ``__version__`` (defined in :mod:`endocal.api`).
_API = (
    "BaseChange", "Check", "ForceModel", "History", "Model", "Planes", "Report", "Run", "Suggestion", "Validation",
    "check_probe", "fit", "fit_force", "fit_planes", "history", "load_model", "load_planes", "load_run", "make_report",
    "run_protocol", "use_effects", "validate",
)

__all__ = ["__version__", *_API]


def __getattr__(name: str):
    if name in _API:
        from endocal import api

        value = getattr(api, name)
        globals()[name] = value  # once: later lookups skip this function
        return value
    raise AttributeError(f"module 'endocal' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
