"""The catalog of physical effects that compose onto any hysteresis model.

Names as users write them (``--effects envelope,delay,load:sheath_wrap_deg``) map to
classes in :data:`EFFECTS`; ``load:COLUMN`` names an extra numeric column of the data
(``coupling:COLUMN`` optionally names the column with the other axis's position).

Three kinds of term (see :mod:`endocal.models.base`): input transforms of the command
(:class:`InputEffect`: ``delay``, ``rate``, ``load``, ``deadzone``, ``envelope``, ``tension``,
applied in that order), filters on the base's output (:class:`OutputFilter`: ``creep``,
``coupling``) and additive output terms (:class:`OutputEffect`: ``drift``).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import asdict, dataclass, field

from endocal.errors import ModelError
from endocal.models.effects.base import COLUMN, Effect, InputEffect, OutputEffect, OutputFilter
from endocal.models.effects.coupling import Coupling
from endocal.models.effects.creep import Creep
from endocal.models.effects.deadzone import Deadzone
from endocal.models.effects.delay import Delay
from endocal.models.effects.drift import Drift
from endocal.models.effects.envelope import Envelope
from endocal.models.effects.load import Load
from endocal.models.effects.rate import Rate
from endocal.models.effects.tension import Tension

#: Catalog name -> effect class, in the order ``endocal effects`` lists them.
EFFECTS: dict[str, type[Effect]] = {
    "envelope": Envelope, "deadzone": Deadzone, "tension": Tension, "rate": Rate, "delay": Delay, "coupling": Coupling,
    "drift": Drift, "creep": Creep, "load": Load,
}


@dataclass(frozen=True)
class EffectInfo:
    """One catalog entry, as ``endocal effects`` shows it.

    Attributes
    ----------
    name : str
        Catalog name; ``usage`` is how ``--effects`` writes it (``load:COLUMN``).
    kind : str
        ``input`` (transforms the command), ``filter`` (acts on the base's output) or
        ``output`` (additive term).
    cause, signature, protocol : str
        Physical cause, the signature it leaves in residuals, the excitation that reveals it.
    parameters : list of str
        Short parameter names (prefixed by the effect's name in a model).
    needs : list of str
        What the data must carry besides command and measurement (``t_s``, a column).
    streamable : bool
        Whether the streaming compensator can undo it one sample at a time.
    requires : list of str
        What the records must hold to fit it or to tell it from a wider loop, in words
        (``Effect.requires``).
    lookalikes : dict
        Effect name -> the records that separate the two, in words (``Effect.lookalikes``).
    variants : dict
        Other forms ``validate`` tries as candidates of their own, as ``--effects`` writes them, -> their
        kind (``{"deadzone:tip": "filter"}``; ``Effect.variants``).
    """

    name: str
    usage: str
    kind: str
    cause: str
    signature: str
    protocol: str
    parameters: list[str]
    needs: list[str]
    streamable: bool
    requires: list[str] = field(default_factory=list)
    lookalikes: dict[str, str] = field(default_factory=dict)
    variants: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)


_PURPOSE = {"fit": "to fit it", "test": "to tell it from a wider loop", "next": "for the next experiment to test it"}


def catalog() -> list[EffectInfo]:
    """Every effect of :data:`EFFECTS`, in catalog order, with its documentation."""
    out = []
    for name, cls in EFFECTS.items():
        out.append(EffectInfo(
            name=name, usage=cls.usage, kind=cls.kind, cause=cls.cause, signature=cls.signature,
            protocol=cls.protocol, parameters=list(cls.units), needs=list(cls.needs),
            streamable=bool(cls.streamable),
            requires=[f"{r.words} ({_PURPOSE[r.to]})" for r in cls.requires], lookalikes=dict(cls.lookalikes),
            variants={v: make_effect(v).kind for v in cls.variants},
        ))
    return out


def variant_forms(name: str, column: str | None = None) -> list[str]:
    """The other forms of catalog effect ``name`` (``Effect.variants``), as ``--effects`` writes them; a column
    effect's forms are written for ``column`` (``load:friction:sheath_wrap_deg``), and left out without it."""
    out = []
    for v in EFFECTS[name].variants:
        if COLUMN in v.partition(":")[2].split(":"):
            if column is not None:
                out.append(v.replace(COLUMN, column))
        elif column is None:
            out.append(v)
    return out


def plain_form(label: str) -> str | None:
    """The plain effect of which ``label`` is another form (``deadzone:tip`` -> ``deadzone``,
    ``load:friction:sheath_wrap_deg`` -> ``load:sheath_wrap_deg``), or None for a plain form."""
    name, _, arg = label.partition(":")
    if name not in EFFECTS:
        return None
    for v in EFFECTS[name].variants:
        head, sep, _ = v.partition(COLUMN)
        if sep and label.startswith(head) and len(label) > len(head):
            return f"{name}:{label[len(head):]}"
        if label == v:
            return name
    return None


def register(cls: type[Effect]) -> type[Effect]:
    """Add an effect class to the catalog under ``cls.name`` (refuses a second class with one name)."""
    if cls.name in EFFECTS and EFFECTS[cls.name] is not cls:
        raise ModelError(f"an effect named '{cls.name}' is already registered")
    EFFECTS[cls.name] = cls
    return cls


def make_effect(spec: str | Effect) -> Effect:
    """An effect from its catalog name (``"delay"``, ``"load:sheath_wrap_deg"``) or an instance.

    Raises
    ------
    ModelError
        Unknown name, a ``:`` argument for an effect that takes none, or ``load`` without its column.
    """
    if isinstance(spec, Effect):
        return spec
    if not isinstance(spec, str) or not spec.strip():
        raise ModelError(f"an effect is a name or an Effect instance, got {spec!r}")
    name, sep, arg = spec.strip().partition(":")
    if name not in EFFECTS:
        raise ModelError(f"unknown effect '{spec}'; known effects: {', '.join(sorted(EFFECTS))}")
    cls = EFFECTS[name]
    if sep:
        if not arg.strip():
            raise ModelError(f"effect '{spec}': nothing after ':' (write {name}:COLUMN)")
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


__all__ = ["EFFECTS", "Coupling", "Creep", "Deadzone", "Delay", "Drift", "Effect", "EffectInfo", "Envelope", "InputEffect",
           "Load", "OutputEffect", "OutputFilter", "Rate", "catalog", "make_effect", "register", "resolve_effects"]
