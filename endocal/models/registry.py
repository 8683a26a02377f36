"""Model names as the command line writes them, and :func:`make_model`."""

from __future__ import annotations

from endocal.errors import ModelError
from endocal.models.base import HysteresisModel
from endocal.models.boucwen import BoucWenModel
from endocal.models.bspline import BSplineModel
from endocal.models.dahl import DahlModel
from endocal.models.linear import LinearModel
from endocal.models.pi import PIModel

BASES: dict[str, type[HysteresisModel]] = {"linear": LinearModel, "bspline": BSplineModel, "pi": PIModel,
                                            "bouc-wen": BoucWenModel, "dahl": DahlModel}


def make_model(base: str, effects=(), **settings) -> HysteresisModel:
    """A model from its base name and effect names (what ``endocal fit hysteresis`` builds).

    Parameters
    ----------
    base : {"linear", "bspline", "pi", "bouc-wen", "dahl"}
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
