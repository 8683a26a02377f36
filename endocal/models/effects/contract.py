"""The effect contract, checked: what a class must declare to join the catalogue.

:func:`missing_declarations` names every declaration an effect class lacks (see
:class:`~endocal.models.effects.base.Effect` for each one's meaning); the contract test
walks every registered effect with it, and the loader of a user's effect file refuses a
class it finds incomplete, naming the first item.
"""

from __future__ import annotations

import inspect
import math

import numpy as np

from endocal.models.data import OTHER_CMD, HysteresisData
from endocal.models.effects.base import COLUMN, Effect, InputEffect, OutputEffect, OutputFilter
from endocal.models.effects.requirements import Requirement
from endocal.models.params import Parameter

#: Residual signals an effect may name in ``residual`` (the residual tests' cross-correlations,
#: :mod:`endocal.validation.residuals`), and the regimes (``regime:NAME``, :mod:`endocal.validation.regimes`).
SIGNALS = ("other command", "time", "speed", "abs speed", "load")
REGIMES = ("regime:other axis", "regime:hold")

#: Declarations every effect class makes itself (a default inherited from Effect does not count).
REQUIRED = ("name", "cause", "signature", "protocol", "units", "requires", "residual", "lookalikes")

#: The column the sample record carries for effects that read one (``load:COLUMN``).
SAMPLE_COLUMN = "condition"


def _declared(cls: type, attr: str) -> bool:
    """True when a class below :class:`Effect` (or its three kinds) sets ``attr``."""
    bases = {Effect, InputEffect, OutputFilter, OutputEffect, object}
    return any(attr in k.__dict__ for k in cls.__mro__ if k not in bases)


def sample_data(n: int = 800) -> HysteresisData:
    """A record every effect can be fitted on: a chirp of two runs with holds, time stamps, the other
    knob moving and a condition column that varies within each run."""
    t = np.arange(n) / 100.0
    f = 0.2 + 0.6 * t / t[-1]
    cmd = 30.0 * np.sin(2 * np.pi * np.cumsum(f) / 100.0)
    cmd[n // 2 - 60:n // 2] = cmd[n // 2 - 61]  # a hold after a move
    meas = 0.9 * cmd + 2.0 * np.sign(np.gradient(cmd))
    other = 20.0 * np.cos(2 * np.pi * 0.13 * t)
    cond = 90.0 + 30.0 * np.sin(2 * np.pi * 0.05 * t)
    half = n // 2
    return HysteresisData(cmd_deg=cmd, meas_deg=meas, t_s=np.concatenate([t[:half], t[half:] - t[half]]),
                          extras={OTHER_CMD: other, SAMPLE_COLUMN: cond}, run_starts=np.array([0, half]))


def sample_instance(cls: type) -> Effect:
    """An instance of ``cls`` for the checks: ``cls()``, else ``cls.from_argument(SAMPLE_COLUMN)``."""
    try:
        return cls()
    except Exception:
        if hasattr(cls, "from_argument"):
            return cls.from_argument(SAMPLE_COLUMN)
        raise


def missing_declarations(cls: type, *, run: bool = True) -> list[str]:
    """What ``cls`` does not declare, or declares wrong, of the effect contract.

    Parameters
    ----------
    cls : type
        An effect class.
    run : bool
        Also instantiate it and run its equation on :func:`sample_data` (parameters with bounds
        and a start inside them, finite output of the record's length, an inverse that inverts).

    Returns
    -------
    list of str
        Empty when the class is complete; each item names what is missing
        (``"no 'residual' (what in the residual points at it)"``, ``"parameters without bounds: x"``).
    """
    if not (isinstance(cls, type) and issubclass(cls, Effect)):
        return [f"{cls!r} is not a subclass of InputEffect, OutputFilter or OutputEffect"]
    if not issubclass(cls, (InputEffect, OutputFilter, OutputEffect)):
        return ["it subclasses Effect directly: subclass InputEffect, OutputFilter or OutputEffect"]
    out: list[str] = []
    words = {"name": "its catalogue name", "cause": "the physical cause, in words",
             "signature": "what it leaves in the residual, in words", "protocol": "the experiment that shows it",
             "units": "its parameters' short names and units", "requires": "what the records must hold to fit or test it",
             "residual": "what in the residual points at it (an empty tuple: nothing)",
             "lookalikes": "the effects it looks like and the records that separate them (an empty dict: none)"}
    for attr in REQUIRED:
        if not _declared(cls, attr):
            out.append(f"no '{attr}' ({words[attr]})")
    name = cls.__dict__.get("name", getattr(cls, "name", ""))
    if _declared(cls, "name") and (not isinstance(name, str) or not name.isidentifier()):
        out.append(f"name {name!r} is not an identifier (letters, digits, _)")
    for attr in ("cause", "signature", "protocol"):
        if _declared(cls, attr) and not (isinstance(getattr(cls, attr), str) and getattr(cls, attr).strip()):
            out.append(f"'{attr}' is empty")
    if not isinstance(cls.units, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in cls.units.items()):
        out.append("'units' must map short parameter names to unit strings")
    if not isinstance(cls.usage, str) or not cls.usage.startswith(str(name)):
        out.append(f"'usage' ({cls.usage!r}) must start with the name")
    if not isinstance(cls.needs, tuple) or not all(isinstance(x, str) for x in cls.needs):
        out.append("'needs' must be a tuple of strings")
    if not isinstance(cls.requires, tuple) or not all(isinstance(r, Requirement) for r in cls.requires):
        out.append("'requires' must be a tuple of Requirement (endocal.models.effects.requirements)")
    if not isinstance(cls.residual, tuple) or not all(
            callable(r) or r in SIGNALS or r in REGIMES or (isinstance(r, str) and r.startswith("load"))
            for r in cls.residual):
        out.append(f"'residual' must be a tuple of signals {SIGNALS}, regimes {REGIMES} or callables")
    if not isinstance(cls.lookalikes, dict) or not all(
            isinstance(k, str) and isinstance(v, str) and v.strip() for k, v in cls.lookalikes.items()):
        out.append("'lookalikes' must map effect names to the records that separate them, in words")
    null = cls.null
    if null and not (issubclass(cls, OutputEffect) and isinstance(null, dict) and isinstance(cls.units, dict)
                     and all(k in cls.units and isinstance(v, (int, float)) and math.isfinite(v)
                             for k, v in null.items())):
        out.append(f"'null' ({null!r}) must map short parameter names of 'units' to finite numbers, on an additive "
                   "term (OutputEffect) only: the values at which the term adds nothing")
    variants = cls.variants
    if not (isinstance(variants, tuple) and all(isinstance(v, str) and v.startswith(f"{name}:") for v in variants)
            and (not variants or hasattr(cls, "from_argument"))):
        out.append(f"'variants' ({variants!r}) must be a tuple of forms written '{name}:ARG', which from_argument(ARG) makes")
    if inspect.isabstract(cls):
        out.append("equation methods not defined: " + ", ".join(sorted(cls.__abstractmethods__)))
    if cls.streamable and issubclass(cls, InputEffect) and cls.invert_step is InputEffect.invert_step:
        out.append("streamable but no invert_step")
    seg = getattr(cls, "segment", None)
    if not callable(seg) or len(inspect.signature(seg).parameters) != 3:
        out.append("'segment' must be a method segment(self, design, n_half_cycles)")
    if out or not run:
        return out
    return out + _run_checks(cls)


def _run_checks(cls: type) -> list[str]:
    """Instantiate ``cls`` and each of its variants, and run their equations on :func:`sample_data`."""
    data = sample_data()
    try:
        eff = sample_instance(cls)
    except Exception as exc:
        return [f"cannot be made with no argument or from_argument('{SAMPLE_COLUMN}'): {exc}"]
    out = _check_instance(eff, data)
    for spec in cls.variants:
        try:
            var = cls.from_argument(spec.partition(":")[2].replace(COLUMN, SAMPLE_COLUMN))
        except Exception as exc:
            out.append(f"variant '{spec}' cannot be made: {type(exc).__name__}: {exc}")
            continue
        if not isinstance(var, Effect) or var.name != cls.name:
            out.append(f"variant '{spec}' makes {var!r}, not an effect named '{cls.name}'")
            continue
        out += [f"variant '{spec}': {msg}" for msg in _check_instance(var, data)]
    return out


def _check_instance(eff: Effect, data) -> list[str]:
    """Run one effect's start, equation and inverse on ``data``."""
    cls = type(eff)
    u = data.cmd_deg
    try:
        params = eff.initial(data, u)
    except Exception as exc:
        return [f"initial(data, u) failed on a sample record: {type(exc).__name__}: {exc}"]
    if not isinstance(params, list) or not all(isinstance(p, Parameter) for p in params):
        return ["initial(data, u) must return a list of Parameter"]
    out: list[str] = []
    names = [p.name for p in params]
    if names != eff.full_names():
        out.append(f"initial returns parameters {names}, not its units' {eff.full_names()}")
    short = {p.name: p.name[len(eff.prefix) + 1:] for p in params}
    unbounded = [short[p.name] for p in params if not (math.isfinite(p.lower) or math.isfinite(p.upper))
                 and short[p.name] not in cls.open_bounds]
    if unbounded:
        out.append("parameters without bounds: " + ", ".join(unbounded)
                   + " (give finite bounds, or list them in open_bounds)")
    bad = [short[p.name] for p in params if not (math.isfinite(p.value) and p.lower <= p.value <= p.upper)]
    if bad:
        out.append("start values not finite or outside their bounds: " + ", ".join(bad))
    if out:
        return out
    p = {short[q.name]: q.clipped_start() for q in params}
    try:
        y = (eff.term(p, u, data) if isinstance(eff, OutputEffect) else eff.apply(p, u if isinstance(eff, InputEffect)
                                                                                 else data.meas_deg, data))
    except Exception as exc:
        return [f"its predict failed on a sample record: {type(exc).__name__}: {exc}"]
    y = np.asarray(y, dtype=float)
    if y.shape != (data.n_samples,):
        return [f"its predict returns shape {y.shape}, not ({data.n_samples},)"]
    if not np.all(np.isfinite(y)):
        return ["its predict returns NaN or inf on a sample record"]
    if hasattr(eff, "friction_factor"):  # the base's friction bound, times its own: positive at every sample
        try:
            f = np.asarray(eff.friction_factor(p, u, data), dtype=float)
        except Exception as exc:
            return [f"friction_factor(p, v, data) failed on a sample record: {type(exc).__name__}: {exc}"]
        if f.shape != (data.n_samples,) or not np.all(np.isfinite(f) & (f > 0.0)):
            return [f"friction_factor(p, v, data) must return ({data.n_samples},) finite positive factors"]
    try:  # validate words a candidate's caution with it (validation.scan): a crash there would end the scan
        why = eff.implausible(p, data)
    except Exception as exc:
        return [f"implausible(p, data) failed on a sample record: {type(exc).__name__}: {exc}"]
    if not isinstance(why, str):
        return [f"implausible(p, data) returns {type(why).__name__}, not a string ('' where the values can be its "
                "physics)"]
    if cls.has_inverse and isinstance(eff, (InputEffect, OutputFilter)):
        try:
            back = np.asarray(eff.invert(p, y, data), dtype=float)
        except Exception as exc:
            return [f"its inverse failed on a sample record: {type(exc).__name__}: {exc}"]
        x = u if isinstance(eff, InputEffect) else data.meas_deg
        again = np.asarray(eff.apply(p, back, data), dtype=float)
        if back.shape != x.shape or not np.all(np.isfinite(back)):
            out.append("its inverse returns NaN or the wrong length")
        elif float(np.max(np.abs(again - y))) > 1e-3 * max(float(np.ptp(y)), 1.0):
            out.append(f"its inverse does not invert: apply(invert(y)) misses y by up to "
                       f"{float(np.max(np.abs(again - y))):.3g} deg on a sweep")
    return out
