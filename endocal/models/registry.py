"""Model names as the command line writes them, and :func:`make_model`."""

from __future__ import annotations

from endocal.errors import ModelError
from endocal.models.base import HysteresisModel
from endocal.models.boucwen import BoucWenModel
from endocal.models.bspline import BSplineModel
from endocal.models.dahl import DahlModel
from endocal.models.linear import LinearModel
from endocal.models.pi import PIModel

#: Base name -> class; a user's bases join it from their files (:mod:`endocal.models.userfile`).
BASES: dict[str, type[HysteresisModel]] = {"linear": LinearModel, "bspline": BSplineModel, "pi": PIModel,
                                            "bouc-wen": BoucWenModel, "dahl": DahlModel}


def register_base(cls: type[HysteresisModel]) -> type[HysteresisModel]:
    """Add a base class under ``cls.base_name`` (refuses a second class with one name).

    A user's base comes from an effects file, checked first (:func:`endocal.models.userfile.load_effects_files`).
    """
    name = getattr(cls, "base_name", "")
    if not (isinstance(name, str) and name):
        raise ModelError(f"base class {cls.__name__} has no base_name to be registered under")
    if name in BASES and BASES[name] is not cls:
        raise ModelError(f"a base named '{name}' is already registered")
    BASES[name] = cls
    return cls


def make_model(base: str, effects=(), **settings) -> HysteresisModel:
    """A model from its base name and effect names (what ``endocal fit hysteresis`` builds).

    Parameters
    ----------
    base : str
        ``linear``, ``bspline``, ``pi``, ``bouc-wen``, ``dahl``, or a base registered from a user's file.
    effects : sequence of str or Effect
        E.g. ``["envelope"]`` (``pi`` + ``envelope`` is the paper's modified PI),
        ``["delay", "load:sheath_wrap_deg"]``; a comma-separated string is accepted.
    **settings
        The base model's settings and ``fixed``, ``axis``, ``out_of_range``.

    Raises
    ------
    ModelError
        Unknown base, effect or setting.
    """
    if base not in BASES:
        raise ModelError(f"unknown model '{base}'; choose one of {', '.join(BASES)}")
    if isinstance(effects, str):
        effects = [s for s in (x.strip() for x in effects.split(",")) if s]
    try:
        return BASES[base](**settings, effects=list(effects))
    except TypeError as exc:
        raise ModelError(f"model '{base}': {exc}") from None
