"""A user's own effects and bases: loaded from the files the user names, checked, registered as the user's.

An effect file is a Python file that defines one or more subclasses of
:class:`~endocal.models.effects.base.InputEffect`, :class:`~endocal.models.effects.base.OutputFilter`
or :class:`~endocal.models.effects.base.OutputEffect` (the effect contract,
:mod:`endocal.models.effects.base`), and may define bases: subclasses of
:class:`~endocal.models.base.HysteresisModel` with a ``base_name``. The command line loads it
with ``--effects-file FILE.py`` (repeatable); a lab ships its effects as a package through the
entry-point group ``endocal.effects`` (:data:`ENTRY_POINT_GROUP`), whose entries name a module or
a class. The Python API takes ``effects_file=`` or the class itself (:func:`register_user_class`).

Loading a file runs it: an effect file is Python the user chooses to run, as pytest runs a
``conftest.py``. Nothing here ever loads a file the user did not name: not from a data folder,
not from a run folder, not from a model file (a model file records where its user effects came
from, :func:`source_of`, and loading it without them is refused with the file named,
:func:`check_model_sources`).

Every class is checked before it is registered; each failure is one
:class:`EffectFileError` naming the file and the effect:

- the file is missing, unreadable, has a syntax error or raises when run;
- a class lacks a declaration of the contract (:func:`~endocal.models.effects.contract.missing_declarations`);
- its name clashes with the catalogue's or with another file's;
- its parameters have no bounds (each bound finite or explicitly open);
- its equation returns NaN or the wrong length on a small sample record
  (:func:`~endocal.models.effects.contract.sample_data`);
- its inverse (when it declares one) does not invert, checked on a sweep.

The first four are the effect contract's own check; a base is fitted on the sample record and its
inverse run on a sweep (:func:`sweep_deg`).

A registered class is the user's: :func:`source_of` gives its :class:`Source` (the module's file
and that file's SHA-256), and ``endocal effects`` marks it so.
"""

from __future__ import annotations

import hashlib
import importlib.util
import inspect
import math
import sys
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from endocal.errors import ModelError

#: The entry-point group a package lists its effects (or bases) under, e.g. in its pyproject.toml:
#: ``[project.entry-points."endocal.effects"] stickslip = "labfx.stickslip"`` (a module or a class).
ENTRY_POINT_GROUP = "endocal.effects"
#: The attribute a registered user class carries its :class:`Source` in.
_SOURCE_ATTR = "__endocal_source__"
#: A base's inverse inverts when ``forward(inverse(v))`` is within this of ``v`` (deg): a hundredth of a
#: degree, thirty times below a tracker's noise, far above the rounding of a good inverse; plus
#: this fraction of the sweep's span for an inverse that interpolates (a delay's sub-sample shift).
INVERSE_TOL_DEG, INVERSE_TOL_FRAC = 0.01, 1e-3


class EffectFileError(ModelError):
    """A user's effect file, or a class in it, cannot be used (one line naming the file and the effect)."""


class EffectFileWarning(UserWarning):
    """A user's effect file changed since a model was fitted with it, and was given anyway."""


@dataclass(frozen=True)
class Source:
    """Where a user's effect or base came from.

    Attributes
    ----------
    path : str
        The module's file (absolute).
    module : str
        The module's name (a file's stem, or the package module an entry point names).
    sha256 : str
        The SHA-256 of the file's bytes when it was loaded.
    given : bool
        Named by the user (``--effects-file``, ``effects_file=``, the class passed in), rather than
        found through an installed package's entry point.
    """

    path: str
    module: str
    sha256: str
    given: bool = True

    def to_dict(self) -> dict:
        """What a model file records (``given`` is this session's, not the model's)."""
        return {"path": self.path, "module": self.module, "sha256": self.sha256}


#: path -> (sha256, the classes its load registered), for every file loaded in this process
_LOADED: dict[str, tuple[str, list[type]]] = {}
_ENTRY_POINTS_LOADED = False


def source_of(cls: type) -> Source | None:
    """The :class:`Source` of a user's class; None for the catalogue's own."""
    return cls.__dict__.get(_SOURCE_ATTR)


def is_users(cls: type) -> bool:
    """True when ``cls`` was registered from a user's file, package or notebook."""
    return source_of(cls) is not None


def file_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# ---------------------------------------------------------------------------------------------- loading
def load_effects_files(paths: Iterable[str | Path] = (), *, entry_points: bool = True) -> list[type]:
    """Load the user's effect files (and the ``endocal.effects`` entry points), check and register every class.

    Loading a file again that has not changed registers nothing new; a file that changed
    since it was loaded in this process replaces its classes.

    Parameters
    ----------
    paths : iterable of path
        ``.py`` files, in the order given.
    entry_points : bool
        Also load the installed packages' entry points of :data:`ENTRY_POINT_GROUP`.

    Returns
    -------
    list of type
        The classes the named files define (effects, then bases), in file order.

    Raises
    ------
    EffectFileError
        One line naming the file and the effect (module docstring).
    """
    if entry_points:
        load_entry_points()
    out: list[type] = []
    for p in paths:
        out += _load_file(Path(p))
    return out


def _load_file(path: Path) -> list[type]:
    where = f"effects file {path}"
    if path.suffix != ".py":
        raise EffectFileError(f"{where}: an effects file is a Python file (.py); give the file that defines the effect")
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise EffectFileError(f"{where} does not exist; give the path of the .py file that defines the effect") from None
    except OSError as exc:
        raise EffectFileError(f"{where} cannot be read: {exc.strerror or exc}") from None
    key = str(path.resolve())
    sha = hashlib.sha256(data).hexdigest()
    if key in _LOADED:
        old_sha, classes = _LOADED[key]
        if old_sha == sha:
            for cls in classes:  # named now: a class an entry point loaded from this file becomes given
                src = source_of(cls)
                if src is not None and not src.given:
                    setattr(cls, _SOURCE_ATTR, Source(src.path, src.module, src.sha256, True))
            return list(classes)
        _unregister(classes)
        del _LOADED[key]
    try:
        code = compile(data, str(path), "exec")
    except SyntaxError as exc:
        raise EffectFileError(f"{where}: syntax error at line {exc.lineno}: {exc.msg}; fix the file") from None
    except ValueError as exc:  # null bytes
        raise EffectFileError(f"{where}: not a Python source file ({exc})") from None
    module_name = f"endocal_user_effects.{_identifier(path.stem)}_{sha[:12]}"
    module = importlib.util.module_from_spec(importlib.util.spec_from_loader(module_name, loader=None,
                                                                               origin=str(path)))
    module.__file__ = str(path)
    sys.modules[module_name] = module  # dataclasses and forked workers look classes up by module
    try:
        exec(code, module.__dict__)  # noqa: S102 - running it is what --effects-file asks for (module docstring)
    except Exception as exc:  # the user's code: any error of theirs is one line, not a traceback
        del sys.modules[module_name]
        raise EffectFileError(f"{where}: running it raised {type(exc).__name__}: {_first_line(exc)}"
                              f"{_line_of(exc, str(path))}; fix the file") from None
    try:
        classes = _register_module(module, Source(key, path.stem, sha, True), where)
    except EffectFileError:
        del sys.modules[module_name]  # nothing of a refused file stays
        raise
    _LOADED[key] = (sha, classes)
    return classes


def load_entry_points() -> list[type]:
    """Load and register every entry point of :data:`ENTRY_POINT_GROUP` (once per process).

    Each entry names a module (every effect and base it defines) or one class.

    Raises
    ------
    EffectFileError
    """
    global _ENTRY_POINTS_LOADED
    if _ENTRY_POINTS_LOADED:
        return []
    _ENTRY_POINTS_LOADED = True
    from importlib.metadata import entry_points

    out: list[type] = []
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        where = f"entry point '{ep.name} = {ep.value}' ({ENTRY_POINT_GROUP})"
        try:
            obj = ep.load()
        except Exception as exc:  # an installed package's import error is one line too
            raise EffectFileError(f"{where}: loading it raised {type(exc).__name__}: {_first_line(exc)}") from None
        module = inspect.getmodule(obj) if inspect.isclass(obj) else obj
        file = getattr(module, "__file__", None)
        if not file:
            raise EffectFileError(f"{where}: its module has no file to record in model files")
        key = str(Path(file).resolve())
        source = Source(key, module.__name__, file_sha256(key), False)
        where = f"{where} in {key}"
        classes = (_register_classes([obj], source, where) if inspect.isclass(obj) else
                   _register_module(module, source, where))
        _LOADED.setdefault(key, (source.sha256, []))[1].extend(classes)
        out += classes
    return out


def register_user_class(cls: type) -> type:
    """Check and register one class a notebook defines or imports (the API's ``effects=[MyEffect]``).

    Its source is the file of the module that defines it (a notebook's classes have none: they
    are registered, but a model fitted with them records no file, and loading that model in
    another session needs the class registered again).

    Raises
    ------
    EffectFileError
    """
    src = source_of(cls)
    if src is not None:
        return cls
    module = inspect.getmodule(cls)
    file = getattr(module, "__file__", None)
    if file and Path(file).is_file():
        key = str(Path(file).resolve())
        source = Source(key, getattr(module, "__name__", Path(file).stem), file_sha256(key), True)
    else:
        source = Source("", getattr(module, "__name__", "__main__"), "", True)
    where = f"class {cls.__qualname__} ({source.path or source.module})"
    _register_classes([cls], source, where)
    return cls


def forget_user_classes() -> None:
    """Unregister every user class (tests; a notebook that wants the catalogue as shipped)."""
    global _ENTRY_POINTS_LOADED
    for _, classes in list(_LOADED.values()):
        _unregister(classes)
    _LOADED.clear()
    from endocal.models.effects import EFFECTS
    from endocal.models.registry import BASES

    for table in (EFFECTS, BASES):
        for name, cls in list(table.items()):
            if is_users(cls):
                del table[name]
    _ENTRY_POINTS_LOADED = False


def _unregister(classes: Sequence[type]) -> None:
    from endocal.models.effects import EFFECTS
    from endocal.models.registry import BASES

    for cls in classes:
        for table, name in ((EFFECTS, getattr(cls, "name", None)), (BASES, getattr(cls, "base_name", None))):
            if name and table.get(name) is cls:
                del table[name]


def _register_module(module, source: Source, where: str) -> list[type]:
    from endocal.models.base import HysteresisModel
    from endocal.models.effects.base import Effect

    own = [obj for obj in vars(module).values()
           if inspect.isclass(obj) and obj.__module__ == module.__name__
           and issubclass(obj, (Effect, HysteresisModel)) and not _is_abstract_helper(obj)]
    if not own:
        raise EffectFileError(f"{where}: defines no effect (a subclass of InputEffect, OutputFilter or OutputEffect "
                              "from endocal.models.effects.base) and no base (a subclass of HysteresisModel); "
                              "see docs/how-to/add-effect.md")
    return _register_classes(own, source, where)


def _is_abstract_helper(cls: type) -> bool:
    """A user's own intermediate class: abstract, and without a name of its own to be registered under."""
    name = cls.__dict__.get("name") or cls.__dict__.get("base_name")
    return inspect.isabstract(cls) and not name


def _register_classes(classes: Sequence[type], source: Source, where: str) -> list[type]:
    """Check every class, then register them all (nothing is registered when one fails)."""
    from endocal.models.base import HysteresisModel
    from endocal.models.effects import EFFECTS, register
    from endocal.models.effects.base import Effect
    from endocal.models.registry import BASES, register_base

    effects = [c for c in classes if issubclass(c, Effect)]
    bases = [c for c in classes if issubclass(c, HysteresisModel)]
    seen: dict[str, type] = {}
    for cls in effects:
        _check_effect_class(cls, where, EFFECTS, seen)
        seen[cls.name] = cls
    seen_bases: dict[str, type] = {}
    for cls in bases:
        _check_base_class(cls, where, BASES, seen_bases)
        seen_bases[cls.base_name] = cls
    for cls in effects:
        setattr(cls, _SOURCE_ATTR, source)
        register(cls)
    for cls in bases:
        setattr(cls, _SOURCE_ATTR, source)
        register_base(cls)
    return [*effects, *bases]


# ---------------------------------------------------------------------------------------------- checks
def _clash(name: str, cls: type, table: dict, seen: dict, what: str) -> str | None:
    """Why ``name`` cannot be registered for ``cls``, or None."""
    if name in seen and seen[name] is not cls:
        return f"{what} '{name}' is defined twice in this file; rename one"
    other = table.get(name)
    if other is None or other is cls:
        return None
    src = source_of(other)
    if src is None:
        return f"{what} '{name}' clashes with the catalogue's '{name}'; rename yours"
    return f"{what} '{name}' clashes with the {what} '{name}' of {src.path or src.module}; rename one of them"


def _checked_name(cls: type, attr: str, what: str, where: str, label: str, table: dict, seen: dict, kind: str) -> str:
    """``cls``'s name (its ``attr``), once it is concrete, one word and unlike the catalogue's and the other
    files' (:func:`_clash`); else one line naming the file and the class."""
    if inspect.isabstract(cls):
        raise EffectFileError(f"{where}: {label} does not define {', '.join(sorted(cls.__abstractmethods__))}")
    name = getattr(cls, attr)
    if not isinstance(name, str) or not name.isidentifier():
        raise EffectFileError(f"{where}: {label}: {what} must be one word (letters, digits, _), got {name!r}")
    why = _clash(name, cls, table, seen, kind)
    if why:
        raise EffectFileError(f"{where}: {why}")
    return name


def _check_effect_class(cls: type, where: str, table: dict, seen: dict) -> None:
    from endocal.models.effects.base import InputEffect, OutputEffect, OutputFilter

    label = f"effect '{cls.__dict__.get('name') or cls.__name__}'"
    if not issubclass(cls, (InputEffect, OutputFilter, OutputEffect)):
        raise EffectFileError(f"{where}: {label}: subclass InputEffect, OutputFilter or OutputEffect, not Effect itself")
    name = _checked_name(cls, "name", "its name", where, label, table, seen, "effect")
    from endocal.models.effects.contract import missing_declarations

    try:
        missing = missing_declarations(cls)  # declarations, bounds, the equation and its inverse on a sample record
    except Exception as exc:  # the user's code raised outside the contract's own guards
        raise EffectFileError(f"{where}: effect '{name}' raised {type(exc).__name__} on a sample record: "
                              f"{_first_line(exc)}{_line_of(exc, _file_of(cls))}") from None
    if missing:
        raise EffectFileError(f"{where}: effect '{name}': {'; '.join(missing)} (see docs/how-to/add-effect.md)")


def sweep_deg(n: int = 800, amplitude_deg: float = 30.0) -> np.ndarray:
    """A sweep a base's inverse is checked on: up and down over +-amplitude, with smaller reversals inside."""
    s = np.linspace(0.0, 1.0, n)
    return amplitude_deg * np.sin(2 * np.pi * 2.0 * s) * (1.0 - 0.5 * s) + 3.0 * np.sin(2 * np.pi * 11.0 * s)


def _check_base_class(cls: type, where: str, table: dict, seen: dict) -> None:
    from endocal.models.data import HysteresisData
    from endocal.models.effects.contract import sample_data

    label = f"base '{cls.__dict__.get('base_name') or cls.__name__}'"
    name = _checked_name(cls, "base_name", "base_name", where, label, table, seen, "base")
    data = sample_data()
    try:
        model = cls(axis="x").fit(data)
        y = np.asarray(model.predict(data), dtype=float)
    except Exception as exc:  # the user's code, or the fit it drives
        raise EffectFileError(f"{where}: base '{name}' cannot be fitted and run on a sample record "
                              f"({type(exc).__name__}: {_first_line(exc)}{_line_of(exc, _file_of(cls))})") from None
    if y.shape != (data.n_samples,) or not np.isfinite(y).all():
        raise EffectFileError(f"{where}: base '{name}' predicts {'NaN or inf' if y.shape == (data.n_samples,) else y.shape}"
                              " on a sample record; it must return one finite angle per sample")
    if not getattr(cls, "has_inverse", True):
        return
    n = 800
    t = np.arange(n) / 100.0
    sweep = HysteresisData(cmd_deg=np.clip(sweep_deg(n), data.cmd_deg.min(), data.cmd_deg.max()), t_s=t)
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            want = np.asarray(model.predict(sweep), dtype=float)
            back = np.asarray(model.inverse(HysteresisData(cmd_deg=want, t_s=t)), dtype=float)
            again = np.asarray(model.predict(HysteresisData(cmd_deg=back, t_s=t)), dtype=float)
    except Exception as exc:
        raise EffectFileError(f"{where}: base '{name}': its inverse does not converge on a sweep ({type(exc).__name__}: "
                              f"{_first_line(exc)}); fix it, or declare has_inverse = False (compensation is then "
                              "refused)") from None
    err = float(np.max(np.abs(again - want))) if again.shape == want.shape else math.inf
    tol = INVERSE_TOL_DEG + INVERSE_TOL_FRAC * float(np.ptp(want))
    if not err <= tol:
        raise EffectFileError(f"{where}: base '{name}': its inverse does not converge on a sweep (predict(inverse(y)) "
                              f"misses y by {err:.3g} deg, tolerance {tol:.3g}); fix it, or declare has_inverse = False "
                              "(compensation is then refused)")


# ---------------------------------------------------------------------------------------------- model files
def check_model_sources(d: dict, where: str) -> None:
    """Before a model file is built: every user effect and base it records is registered, from its file.

    An effect or base the catalogue does not hold and the file records a source for is looked
    for among the entry points; then:

    - not registered: refused, naming the file that defines it (and whether that file is
      missing or changed since the fit);
    - registered from a file whose SHA-256 differs from the recorded one: refused when it came
      from an entry point, a :class:`EffectFileWarning` naming the change when the user gave the
      file (``--effects-file``).

    Raises
    ------
    EffectFileError
    """
    from endocal.models.effects import EFFECTS
    from endocal.models.registry import BASES

    wanted = [("effect", e.get("name"), e.get("source"), EFFECTS) for e in d.get("effects") or []
              if isinstance(e, dict)]
    wanted.append(("base", d.get("base"), d.get("base_source"), BASES))
    recorded = [w for w in wanted if isinstance(w[2], dict)]
    if any(w[1] not in w[3] for w in recorded):
        load_entry_points()
    for what, name, src, table in recorded:
        path, sha = str(src.get("path", "")), str(src.get("sha256", ""))
        cls = table.get(name)
        if cls is None:
            if not path:
                raise EffectFileError(f"{where}: {what} '{name}' was defined in a notebook (module {src.get('module')}), "
                                      "not in a file: register the class again before loading the model")
            state = ("which does not exist" if not Path(path).is_file() else
                     "which changed since the model was fitted" if file_sha256(path) != sha else "")
            raise EffectFileError(f"{where}: {what} '{name}' comes from {path}{', ' + state if state else ''}: "
                                  f"give the file that defines it with --effects-file {path}")
        now = source_of(cls)
        if now is None:
            raise EffectFileError(f"{where}: {what} '{name}' was the user's ({path}) but the catalogue now has its "
                                  f"own '{name}': rename the user's {what} and refit")
        if sha and now.sha256 and now.sha256 != sha:
            change = (f"{what} '{name}': {now.path} changed since {where} was fitted" if now.path == path else
                      f"{what} '{name}': {where} was fitted with {path}, and it now comes from {now.path}")
            change += f" (SHA-256 {sha[:12]} -> {now.sha256[:12]})"
            if not now.given:
                raise EffectFileError(f"{where}: {change}, and was not given: give it with --effects-file {now.path} "
                                      "to use it as it is now, or refit")
            warnings.warn(f"{change}: the model's parameters are read by the file as it is now", EffectFileWarning,
                          stacklevel=2)


def sources_of_model(model) -> tuple[list[Source | None], Source | None]:
    """The :class:`Source` of each of a model's effects (None: the catalogue's) and of its base."""
    return [source_of(type(e)) for e in model.effects_], source_of(type(model))


def given_files() -> list[str]:
    """The files the user named in this process (``--effects-file``, ``effects_file=``), in load order."""
    return [path for path, (_, classes) in _LOADED.items()
            if any((src := source_of(c)) is not None and src.given for c in classes)]


def files_for(base: str, labels: Iterable[str]) -> list[str]:
    """The user's files a base and the effects named by ``labels`` (``wear``, ``load:col``) come from, each
    once (what a command that refits them gives with ``--effects-file``)."""
    from endocal.models.effects import EFFECTS
    from endocal.models.registry import BASES

    classes = [BASES.get(base), *(EFFECTS.get(str(lab).partition(":")[0]) for lab in labels)]
    sources = [source_of(c) for c in classes if c is not None]
    return list(dict.fromkeys(s.path for s in sources if s is not None and s.path))


# ---------------------------------------------------------------------------------------------- helpers
def _identifier(stem: str) -> str:
    s = "".join(c if c.isalnum() or c == "_" else "_" for c in stem)
    return s if s and not s[0].isdigit() else f"m_{s}"


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _file_of(cls: type) -> str:
    mod = sys.modules.get(cls.__module__)
    return str(getattr(mod, "__file__", "") or "")


def _line_of(exc: BaseException, file: str) -> str:
    """`` (line N)`` of the deepest frame of ``exc``'s traceback in ``file``, or ``""``."""
    if not file:
        return ""
    line = None
    tb = exc.__traceback__
    while tb is not None:
        if tb.tb_frame.f_code.co_filename == file:
            line = tb.tb_lineno
        tb = tb.tb_next
    return f" (line {line})" if line else ""

