"""Protocol parameters: a typed, bounded, documented value, and the parameters signals share.

Every parameter of a signal is a :class:`Param` with a default, a kind and bounds; values
from files and overrides are coerced and checked here, naming the file and the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from endocal.errors import ProtocolError

#: Samples per second of the motor clock unless a protocol says otherwise.
DEFAULT_SAMPLE_RATE_HZ = 100.0


@dataclass(frozen=True)
class Param:
    """One protocol parameter: name (with its unit), default, type and range.

    ``kind`` is ``float``, ``int``, ``floats`` (a list of numbers), ``axes`` (a list of
    axis names), ``choice`` (one of ``choices``) or ``seed`` (an int >= 0, or unset).
    ``lo`` bounds numbers from below (``lo_open``: strictly); ``length`` fixes a list length.
    """

    name: str
    default: Any
    kind: str
    doc: str
    lo: float | None = None
    lo_open: bool = False
    length: int | None = None
    choices: tuple[str, ...] = ()

    def coerce(self, value: Any, where: str) -> Any:
        """Check ``value`` and return it normalised (floats as float, lists as lists).

        Raises
        ------
        ProtocolError
            Naming the parameter, ``where`` it was set, and what it must be.
        """

        def bad(what: str) -> ProtocolError:
            return ProtocolError(f"{where}: parameter '{self.name}' must be {what}, got {value!r}")

        def number(x: Any, what: str) -> float:
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                raise bad(what)
            if self.lo is not None and (x <= self.lo if self.lo_open else x < self.lo):
                raise bad(what)
            return float(x)

        bound = "" if self.lo is None else (f" > {self.lo:g}" if self.lo_open else f" >= {self.lo:g}")
        if self.kind == "float":
            return number(value, f"a number{bound}")
        if self.kind == "int":
            if isinstance(value, bool) or not isinstance(value, int):
                raise bad(f"an integer{bound}")
            number(value, f"an integer{bound}")
            return int(value)
        if self.kind == "seed":
            if value is None:
                return None
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise bad("an integer >= 0")
            return int(value)
        if self.kind == "choice":
            if value not in self.choices:
                raise bad("one of " + ", ".join(repr(c) for c in self.choices))
            return str(value)
        if self.kind == "floats":
            n = f"{self.length} numbers" if self.length else "a non-empty list of numbers"
            if not isinstance(value, (list, tuple)) or not value or (self.length and len(value) != self.length):
                raise bad(f"{n}{bound}")
            return [number(x, f"{n}{bound}") for x in value]
        if self.kind == "axes":
            if isinstance(value, str):
                value = [value]
            n = f"a list of {self.length} axis names" if self.length else "a non-empty list of axis names"
            if (
                not isinstance(value, (list, tuple))
                or not value
                or not all(isinstance(a, str) and a for a in value)
                or (self.length and len(value) != self.length)
            ):
                raise bad(n + " (e.g. ['axis1', 'axis2'])")
            if len(set(value)) != len(value):
                raise bad("a list of different axes")
            return list(value)
        raise AssertionError(f"unknown parameter kind {self.kind!r}")  # a bug in the spec below, not user input


def param(name, default, kind, doc, **kw) -> Param:
    return Param(name=name, default=default, kind=kind, doc=doc, **kw)


SAMPLE_RATE = param("sample_rate_hz", DEFAULT_SAMPLE_RATE_HZ, "float", "Motor clock, samples per second.", lo=0, lo_open=True)
OFFSET = param("offset_deg", 0.0, "float", "Level the signal oscillates about, deg; reached from 0 by a ramp of ramp_s.")
RAMP = param("ramp_s", 2.0, "float", "Raised-cosine ramp from 0 to the offset and back, s.", lo=0)
REST = param("rest_s", 2.0, "float", "Hold between consecutive blocks and axes, s.", lo=0)


def axes_param(default: list[str], length: int | None = None, doc: str | None = None) -> Param:
    text = doc or "Axes driven, one after the other (the others hold at 0): names or axis1/axis2."
    return param("axes", default, "axes", text, length=length)


def amplitude_param(default: float, doc: str = "Peak of the signal about the offset, deg.") -> Param:
    return param("amplitude_deg", default, "float", doc, lo=0, lo_open=True)


def positive_param(name: str, default: float, doc: str) -> Param:
    return param(name, default, "float", doc, lo=0, lo_open=True)


def count_param(name: str, default: int, doc: str) -> Param:
    return param(name, default, "int", doc, lo=1)


