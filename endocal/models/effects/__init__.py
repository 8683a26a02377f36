"""The catalog of physical effects that compose onto any hysteresis model.

Names as users write them (``--effects envelope,delay,load:sheath_wrap_deg``) map to
classes in :data:`EFFECTS`; ``load:COLUMN`` names an extra numeric column of the data.
"""

from __future__ import annotations

from collections.abc import Iterable

from endocal.errors import ModelError
from endocal.models.effects.base import Effect, InputEffect, OutputEffect
from endocal.models.effects.drift import Drift
from endocal.models.effects.envelope import Envelope

EFFECTS: dict[str, type[Effect]] = {"envelope": Envelope, "drift": Drift}


def register(cls: type[Effect]) -> type[Effect]:
    """Add an effect class to the catalog under ``cls.name`` (refuses a second class with one name)."""
    if cls.name in EFFECTS and EFFECTS[cls.name] is not cls:
        raise ModelError(f"an effect named '{cls.name}' is already registered")
    EFFECTS[cls.name] = cls
    return cls


def make_effect(spec: str | Effect) -> Effect:
    """An effect from its catalog name (``"delay"``, ``"load:sheath_wrap_deg"``) or an instance."""
    if isinstance(spec, Effect):
        return spec
    if not isinstance(spec, str) or not spec.strip():
        raise ModelError(f"an effect is a name or an Effect instance, got {spec!r}")
    name, _, arg = spec.strip().partition(":")
    if name not in EFFECTS:
        raise ModelError(f"unknown effect '{spec}'; known effects: {', '.join(sorted(EFFECTS))}")
    cls = EFFECTS[name]
    if arg:
        return cls.from_argument(arg) if hasattr(cls, "from_argument") else _no_argument(spec)
    return cls()


def _no_argument(spec: str) -> Effect:
    raise ModelError(f"effect '{spec.partition(':')[0]}' takes no ':' argument (got '{spec}')")


def resolve_effects(specs: Iterable[str | Effect] | None) -> list[Effect]:
    """Effect instances for a model; two effects with one parameter prefix is an error."""
    if specs is None:
        return []
    if isinstance(specs, (str, Effect)):
        specs = [specs]
    out = [make_effect(s) for s in specs]
    seen: dict[str, Effect] = {}
    for e in out:
        if e.prefix in seen:
            raise ModelError(f"effect '{e.label}' is given twice (both claim the parameters '{e.prefix}_*')")
        seen[e.prefix] = e
    return out


__all__ = ["EFFECTS", "Drift", "Effect", "Envelope", "InputEffect", "OutputEffect", "make_effect", "register", "resolve_effects"]
