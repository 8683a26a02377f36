"""What the words of a log's column names say: the vocabulary a map's draft guesses roles by
(:mod:`endocal.runs.mapdraft`) and its import checks units against (:mod:`endocal.runs.csvchecks`).

A name is split into lower-case words at underscores, spaces, dots, brackets and case changes
(``apPresentTicks``, ``ap_present_ticks`` and ``Tendon Disp.`` give ap, present, ticks and
tendon, disp); a unit written in mixed case stays one word (``current_mA``, ``torque_Nm``: ma, nm).
"""

from __future__ import annotations

import re

#: words naming an angle's unit, and the unit they name
ANGLE_UNIT_WORDS = {"deg": "deg", "degree": "deg", "degrees": "deg", "rad": "rad", "radian": "rad", "radians": "rad",
                    "tick": "ticks", "ticks": "ticks", "raw": "ticks", "counts": "ticks", "count": "ticks"}
#: words naming a length's unit, and the unit they name (``m`` only as a name's last word: ``stage_pos_m``)
LENGTH_UNIT_WORDS = {"mm": "mm", "millimetre": "mm", "millimetres": "mm", "millimeter": "mm", "millimeters": "mm",
                     "m": "m", "metre": "m", "metres": "m", "meter": "m", "meters": "m",
                     "um": "um", "micron": "um", "microns": "um", "micrometre": "um", "micrometres": "um",
                     "micrometer": "um", "micrometers": "um"}
#: words of a linear drive's travel: a tendon pulled (or a stage moved) by so many mm
DISPLACEMENT_WORDS = {"disp", "displ", "displacement", "stroke", "extension", "elongation", "travel"}
#: words of what a drive exerts rather than where it is: a motor's current, a torque, a force or a load
#: (a column so named is never a position)
EFFORT_WORDS = {"current", "cur", "curr", "ma", "amp", "amps", "ampere", "amperes", "effort", "torque", "trq",
                "force", "load", "tension", "nm", "newton", "newtons"}

#: words of what else a drive logs about itself: its speed, temperature, voltage or power (a column
#: so named is never a position either)
STATE_WORDS = {"vel", "velocity", "speed", "rpm", "rate", "temp", "temperature", "celsius", "degc", "volt", "volts",
               "voltage", "pwm", "duty", "power", "watt", "watts"}


def words(name: str) -> list[str]:
    """A column name's words, lower case: ``apPresentTicks`` and ``ap_present_ticks`` give ap, present, ticks."""
    # a case change starts a word (apPresent, posX, motorRPM), but not within a unit such as mA or Nm:
    # one lower-case letter alone before the capital is a unit's prefix, not a word
    name = str(name).replace("\u00b5", "u").replace("\u03bc", "u")  # µm (micro sign or Greek mu): um
    spaced = re.sub(r"(?<=[a-z0-9])(?=[A-Z][a-z])|(?<=[a-z0-9]{2})(?=[A-Z])", " ", name)
    return [w for w in re.split(r"[^A-Za-z0-9]+", spaced.lower()) if w]


#: words that hint at servo ticks without naming a unit (a raw reading, encoder counts)
_TICK_HINTS = {"raw", "count", "counts"}


def unit_named(name: str) -> str | None:
    """The unit a column's name says (its last unit word: ``deg``, ``rad``, ``ticks``, ``mm``, ``m``, ``um``), or None.

    ``raw`` and ``counts`` hint at ticks (a draft reads them so) but name no unit here."""
    ws = words(name)
    for i in range(len(ws) - 1, -1, -1):
        w = ws[i]
        if w in ANGLE_UNIT_WORDS and w not in _TICK_HINTS:
            return ANGLE_UNIT_WORDS[w]
        if w in LENGTH_UNIT_WORDS and (w != "m" or i == len(ws) - 1):
            return LENGTH_UNIT_WORDS[w]
    return None


def named_length(name: str) -> str:
    """Why a column's name says it holds a length (its length unit, else a displacement word), or ``""``."""
    unit = unit_named(name)
    if unit is not None:
        return f"its name says {unit}" if unit in LENGTH_UNIT_WORDS.values() else ""
    disp = next((w for w in words(name) if w in DISPLACEMENT_WORDS), None)
    return f"it is named like a displacement ({disp})" if disp else ""


__all__ = ["ANGLE_UNIT_WORDS", "DISPLACEMENT_WORDS", "EFFORT_WORDS", "LENGTH_UNIT_WORDS", "STATE_WORDS", "named_length",
           "unit_named", "words"]
