"""Hysteresis models of the tendon-sheath drive: knob command (deg) -> bending angle (deg), and back.

Bases: :class:`LinearModel` (``linear``), :class:`BSplineModel` (``bspline``),
:class:`PIModel` (``pi``), with return-point memory, and the smooth friction laws without it,
:class:`BoucWenModel` (``bouc-wen``) and :class:`DahlModel` (``dahl``); effects from
:mod:`endocal.models.effects` compose onto any of them (``PIModel(effects=["envelope"])`` is the duodenoscope paper's modified PI).
Every model fits, predicts, inverts (feedforward compensation), prints as its
equation and saves to versioned JSON (:func:`load_model`).
"""

from endocal.models.base import FitReport, HysteresisModel, OutOfRangeWarning
from endocal.models.boucwen import BoucWenModel
from endocal.models.bspline import BSplineModel
from endocal.models.compensator import StreamingCompensator
from endocal.models.dahl import DahlModel
from endocal.models.data import HysteresisData, as_data
from endocal.models.effects import EFFECTS, make_effect
from endocal.models.io import load_model, model_from_dict, model_to_dict, save_model
from endocal.models.linear import LinearModel
from endocal.models.pi import PIModel
from endocal.models.registry import BASES, make_model

__all__ = [
    "BASES", "BSplineModel", "BoucWenModel", "DahlModel", "EFFECTS", "FitReport", "HysteresisData", "HysteresisModel", "LinearModel",
    "OutOfRangeWarning", "PIModel", "StreamingCompensator", "as_data", "load_model", "make_effect", "make_model",
    "model_from_dict", "model_to_dict", "save_model",
]
