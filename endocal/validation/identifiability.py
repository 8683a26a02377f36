"""Which effects a record can reveal at all, and why not when it cannot.

Each effect declares what the records must hold (``Effect.requires``,
:mod:`endocal.models.effects.requirements`): to be fitted at all (time stamps, the other knob
moving, a condition that varies) and to be told from a wider loop (several speeds, holds after
moves). :func:`untestable_reason` asks them in order and returns the first reason, in words
with the experiment that would show the effect; nothing here names an effect.
"""

from __future__ import annotations

from endocal.errors import ModelError
from endocal.models import EFFECTS, HysteresisData
from endocal.models.effects import Effect, make_effect


def _effect(effect: str | Effect | type) -> tuple[type, Effect | None]:
    if isinstance(effect, Effect):
        return type(effect), effect
    if isinstance(effect, type):
        return effect, None
    cls = EFFECTS[effect.partition(":")[0]]
    try:
        return cls, make_effect(effect)
    except ModelError:  # a name without its column (``load``): the class alone
        return cls, None


def untestable_reason(effect: str | Effect | type, data: HysteresisData, *, to: tuple[str, ...] = ("fit",),
                      where: str = "", **context) -> str | None:
    """Why ``data`` cannot fit (``to=("fit",)``) or test (``("fit", "test")``) ``effect``; None: it can.

    Parameters
    ----------
    effect : str, Effect or effect class
        As ``--effects`` writes it (``"load:sheath_wrap_deg"``), an instance or a class.
    data : HysteresisData
    to : tuple of str
        The purposes of :class:`~endocal.models.effects.requirements.Requirement` checked, in
        the effect's order.
    where : str
        The part of the data the effect would be fitted on (its reasons say it cannot be fitted there).
    context
        Passed to requirements that take it (``span_deg``: the range the model was fitted on).
    """
    cls, inst = _effect(effect)
    for req in cls.requires:
        if req.to in to:
            why = req.reason(data, name=cls.name, where=where, effect=inst, **context)
            if why is not None:
                return why
    return None


def requirement_reasons(effect: str | Effect | type, data: HysteresisData, to: str, **context) -> list[tuple[str, str]]:
    """``(key, reason)`` of every requirement of purpose ``to`` that ``data`` does not hold."""
    cls, inst = _effect(effect)
    out = []
    for req in cls.requires:
        if req.to == to and (why := req.reason(data, name=cls.name, effect=inst, **context)) is not None:
            out.append((req.key, why))
    return out


def unheld_cautions(effect: Effect, train: HysteresisData, val: HysteresisData) -> list[str]:
    """Cautions of ``effect``'s requirements that neither the estimation nor the validation data hold
    (:attr:`~endocal.models.effects.requirements.Requirement.caution`): a fit there may stand for something else."""
    out = []
    for req in type(effect).requires:
        if req.caution and req.check(train, effect=effect) is not None and req.check(val, effect=effect) is not None:
            out.append(req.caution)
    return out
