"""Excitation protocols: load and validate a TOML file, apply overrides, build the trajectory.

A protocol file names a *signal* (the generator in :mod:`endocal.protocols.signals`) and
sets its parameters; every parameter has a default, so a file sets only what it changes.
The user overrides any parameter at load time; an override or file key naming a
parameter the signal does not have is an error, never silently ignored::

    description = "Damped sine of the duodenoscope paper"
    signal = "damped-sine"

    [params]
    axes = ["axis1"]
    amplitude_deg = 60.0

:meth:`Protocol.trajectory` turns the parameters into goals for every degree of freedom
of a probe on the motor clock (a :class:`Trajectory`); :meth:`Trajectory.check_limits`
refuses goals beyond the probe's limits or faster than its knobs, before anything moves.
The schema is documented in ``protocols/README.md``.
"""

from __future__ import annotations

import hashlib
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import endocal
from endocal.errors import ConfigError, ProtocolError
from endocal.probe import ROTATION, TRANSLATION, ProbeConfig
from endocal.protocols.catalogue import SIGNALS, SignalSpec, Timeline
from endocal.protocols.trajectory import Trajectory

# Top-level keys of a protocol file.
_FILE_KEYS = ("description", "signal", "params", "sim", "conditions", "design")

#: A condition is logged as a column of that name: a column name, its unit in the name.
_COLUMN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


# --------------------------------------------------------------------------- protocol


def _resolve_params(spec: SignalSpec, given: dict, where: str, base: dict | None = None) -> dict:
    """Defaults (or ``base``), then ``given`` on top; every value checked."""
    return spec.resolve(given, where, base)


def _conditions(raw: Any, spec: SignalSpec, where: str) -> dict:
    """The ``[conditions]`` table checked: name -> ``{"instruction": str, "recorded": [float, ...]}``."""
    if not isinstance(raw, dict):
        raise ProtocolError(f"{where}: 'conditions' must be a table of conditions (a section headed "
                            "conditions.NAME with an 'instruction')")
    params = {q.name for q in spec.params}
    out = {}
    for name, cond in raw.items():
        at = f"{where}, condition '{name}'"
        if not _COLUMN.match(str(name)) or name in params:
            raise ProtocolError(f"{at}: a condition is logged as a column of its name: use a column name with its "
                                "unit (e.g. sheath_wrap_deg) that is not a parameter of the signal")
        if not isinstance(cond, dict) or not isinstance(cond.get("instruction"), str) or not cond["instruction"].strip():
            raise ProtocolError(f"{at}: needs an 'instruction' saying what to change and how to measure it")
        unknown = [k for k in cond if k not in ("instruction", "recorded")]
        if unknown:
            raise ProtocolError(f"{at}: unknown field(s) {', '.join(map(repr, unknown))}; a condition has "
                                "instruction, recorded")
        recorded = cond.get("recorded", [])
        if not isinstance(recorded, list) or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in recorded):
            raise ProtocolError(f"{at}: 'recorded' must be a list of numbers (the values earlier records hold)")
        out[str(name)] = {"instruction": " ".join(cond["instruction"].split()), "recorded": [float(x) for x in recorded]}
    return out


def _condition_value(name: str, value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ProtocolError(f"{where}: condition '{name}' takes a number (its value in this run, in the unit its name "
                            f"says), got {value!r}")
    return float(value)


@dataclass(frozen=True)
class Protocol:
    """A validated excitation protocol.

    Attributes
    ----------
    name : str
        File stem (``damped-sine``) or the name given to :meth:`from_dict`.
    description : str
        One line.
    signal : str
        Kind of signal, a key of :data:`SIGNALS`.
    params : dict
        Every parameter of the signal, resolved: defaults, then the file, then overrides.
    source_path : Path or None
        The TOML file it was read from.
    sha256 : str or None
        SHA-256 of the file's bytes (overrides are recorded in ``params``/``overrides``).
    overrides : dict
        The parameters the user changed at load time.
    sim : dict
        The file's optional ``[sim]`` table: simulator settings this protocol needs (e.g.
        ``[sim.contact]``, an obstacle), in the layout of a sim config TOML. The simulator
        backend applies them over ``--sim-config``; other backends only record them.
    conditions : dict
        The file's optional ``[conditions]`` table: conditions of the rig that only the user
        can set (the insertion tube's curvature, a tendon's pretension), name ->
        ``{"instruction": ..., "recorded": [values of earlier records]}``. Each is given a
        value per run (``--set NAME=VALUE``, :attr:`condition_values`) and logged as a
        constant column ``NAME``; :meth:`check_conditions` refuses a run without it.
    condition_values : dict
        The value given to each condition (``NAME -> float``).
    design : dict
        The file's optional ``[design]`` table: what the protocol was designed to test (the
        suspects ``endocal validate --next`` wrote it for), recorded with the run.
    """

    name: str
    description: str
    signal: str
    params: dict
    source_path: Path | None = None
    sha256: str | None = None
    overrides: dict = field(default_factory=dict)
    sim: dict = field(default_factory=dict)
    conditions: dict = field(default_factory=dict)
    condition_values: dict = field(default_factory=dict)
    design: dict = field(default_factory=dict)

    @property
    def spec(self) -> SignalSpec:
        return SIGNALS[self.signal]

    def with_overrides(self, overrides: dict | None) -> Protocol:
        """A copy with some parameters (or conditions' values) changed, validated like the file's."""
        if not overrides:
            return self
        where = f"override for protocol '{self.name}'"
        given = {k: v for k, v in overrides.items() if k not in self.conditions}
        values = {k: _condition_value(k, v, where) for k, v in overrides.items() if k in self.conditions}
        params = _resolve_params(self.spec, given, where, base=self.params) if given else self.params
        return Protocol(self.name, self.description, self.signal, params, self.source_path, self.sha256,
                        {**self.overrides, **dict(overrides)}, self.sim, self.conditions,
                        {**self.condition_values, **values}, self.design)

    def check_conditions(self) -> None:
        """Refuse a run of this protocol before every condition has a value.

        Raises
        ------
        ProtocolError
            Naming the first condition without a value, its instruction, and the ``--set`` to give.
        """
        for name, cond in self.conditions.items():
            if name not in self.condition_values:
                before = (f" (earlier records hold {', '.join(f'{x:g}' for x in cond['recorded'])})"
                          if cond["recorded"] else "")
                raise ProtocolError(f"protocol '{self.name}' asks for the condition '{name}': {cond['instruction']}"
                                    f"{before}; give its value in this run as --set {name}=VALUE")

    def resolved_axes(self, probe: ProbeConfig) -> list[str]:
        """The protocol's ``axes`` as the probe's DoF names.

        Raises
        ------
        ProtocolError
            An axis the probe does not have, one named twice, or ``translation`` (protocol
            amplitudes are in degrees).
        """
        out: list[str] = []
        for ref in self.params["axes"]:
            try:
                dof = probe.resolve_axis(ref)
            except ConfigError as exc:
                raise ProtocolError(f"protocol '{self.name}': {exc}") from None
            if dof == TRANSLATION:
                raise ProtocolError(
                    f"protocol '{self.name}': axis 'translation' moves in mm but protocol amplitudes are in deg; "
                    f"drive a bending knob ({', '.join(probe.bending_axes)}) or '{ROTATION}'"
                )
            if dof in out:
                raise ProtocolError(f"protocol '{self.name}': axis '{ref}' is {dof}, which is already listed in axes")
            out.append(dof)
        return out

    def _timeline(self, axes: list[str], seed: int) -> Timeline:
        tl = Timeline()
        try:
            self.spec.build(tl, self.params, axes, seed)
        except ValueError as exc:  # a generator refusing its arguments; the spec checks should have caught it
            raise ProtocolError(f"protocol '{self.name}': {exc}") from None
        return tl

    def trajectory(self, probe: ProbeConfig, seed: int | None = None) -> Trajectory:
        """Goals for every DoF of ``probe`` on the motor clock.

        Parameters
        ----------
        probe : ProbeConfig
            Resolves ``axis1``/``axis2`` and names the DoFs; DoFs not driven hold at 0.
        seed : int, optional
            The run's seed. Used by random signals whose ``seed`` parameter is unset (a
            seed set in the file or as an override wins); otherwise 0.

        Returns
        -------
        Trajectory
            Not yet checked against the probe's limits: call :meth:`Trajectory.check_limits`
            before playing it.
        """
        axes = self.resolved_axes(probe)
        tl = self._timeline(axes, 0 if seed is None else int(seed))
        traj = tl.render(probe.dofs, self.params["sample_rate_hz"], self.name)
        traj.conditions = dict(self.condition_values)
        return traj

    @property
    def duration_s(self) -> float:
        """Length of the trajectory (the same on every probe), s."""
        tl = self._timeline(list(self.params["axes"]), 0)
        fs = self.params["sample_rate_hz"]
        return (int(math.ceil(tl.now_s * fs - 1e-9))) / fs

    def to_dict(self) -> dict:
        """Plain, JSON-ready description (what ``run.json`` records)."""
        return {
            "name": self.name,
            "description": self.description,
            "signal": self.signal,
            "params": {k: (list(v) if isinstance(v, list) else v) for k, v in self.params.items()},
            "overrides": dict(self.overrides),
            "source": str(self.source_path) if self.source_path else None,
            "sha256": self.sha256,
            **({"sim": self.sim} if self.sim else {}),
            **({"conditions": {k: {**c, "value": self.condition_values.get(k)} for k, c in self.conditions.items()}}
               if self.conditions else {}),
            **({"design": self.design} if self.design else {}),
        }

    def to_toml(self, header: str = "") -> str:
        """The protocol as a protocol file (:func:`read_protocol_file` reads it back to an equal protocol).

        Every parameter is written, resolved (defaults included), so the file says exactly what
        runs; a ``sequence``'s segments as ``[[params.segments]]`` tables; conditions without
        their values (a value is given per run). ``header`` becomes ``#`` comment lines on top.
        """
        lines = [f"# {line}".rstrip() for line in header.splitlines()]
        lines += [f"description = {_toml_value(self.description)}", f"signal = {_toml_value(self.signal)}", "",
                  "[params]"]
        lines += _toml_keys({k: v for k, v in self.params.items() if k != "segments"})
        for seg in self.params.get("segments", []) if self.signal == "sequence" else []:
            lines += ["", "[[params.segments]]", *_toml_keys(seg)]
        for section, table in self.sim.items():
            lines += ["", f"[sim.{section}]", *_toml_keys(table)]
        for name, cond in self.conditions.items():
            lines += ["", f"[conditions.{name}]", *_toml_keys(cond)]
        if self.design:
            plain = {k: v for k, v in self.design.items() if not _is_tables(v)}
            lines += ["", "[design]", *_toml_keys(plain)]
            for key, rows in self.design.items():
                if _is_tables(rows):
                    for row in rows:
                        lines += ["", f"[[design.{key}]]", *_toml_keys(row)]
        return "\n".join(lines) + "\n"

    @classmethod
    def from_dict(cls, d: dict, where: str = "protocol") -> Protocol:
        """Rebuild a protocol from :meth:`to_dict` output (e.g. read back from ``run.json``).

        Raises
        ------
        ProtocolError
            Missing keys, unknown signal, or invalid parameters.
        """
        try:
            name, signal, params = str(d["name"]), d["signal"], d["params"]
        except (KeyError, TypeError):
            raise ProtocolError(f"{where}: needs 'name', 'signal' and 'params'") from None
        spec = _spec(signal, where)
        if not isinstance(params, dict):
            raise ProtocolError(f"{where}: 'params' must be a table")
        src = d.get("source")
        raw = d.get("conditions") or {}
        conditions = _conditions({k: {f: v for f, v in c.items() if f != "value"} if isinstance(c, dict) else c
                                  for k, c in raw.items()} if isinstance(raw, dict) else raw, spec, where)
        values = {k: _condition_value(k, c["value"], where) for k, c in raw.items()
                  if isinstance(c, dict) and c.get("value") is not None}
        return cls(name, str(d.get("description", "")), signal, _resolve_params(spec, params, where),
                   Path(src) if src else None, d.get("sha256"), dict(d.get("overrides") or {}), dict(d.get("sim") or {}),
                   conditions, values, dict(d.get("design") or {}))


def _is_tables(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


def _toml_value(value: Any) -> str:
    """One TOML value: strings (escaped), booleans, numbers, lists of these."""
    if isinstance(value, str):
        escaped = value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n").replace("\t", "\\t")
        return f'"{escaped}"'
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ProtocolError(f"a protocol file cannot hold the number {value!r}")
        return repr(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise ProtocolError(f"a protocol file cannot hold {value!r}")


def _toml_keys(table: dict) -> list[str]:
    """``key = value`` lines; a key whose value is None (an unset seed) is left out, as unset."""
    return [f"{k} = {_toml_value(v)}" if _COLUMN.match(str(k)) else f"{_toml_value(str(k))} = {_toml_value(v)}"
            for k, v in table.items() if v is not None]


def _spec(signal: Any, where: str) -> SignalSpec:
    if not isinstance(signal, str) or signal not in SIGNALS:
        raise ProtocolError(f"{where}: field 'signal' must be one of {', '.join(SIGNALS)}, got {signal!r}")
    return SIGNALS[signal]


# --------------------------------------------------------------------------- files


def shipped_protocols_dir() -> Path:
    """The protocols shipped with endocal.

    The repository's top-level ``protocols/`` in a source or editable install, else
    ``endocal/_protocols`` inside an installed wheel.
    """
    pkg = Path(endocal.__file__).resolve().parent
    source = pkg.parent / "protocols"
    return source if source.is_dir() else pkg / "_protocols"


def protocol_dirs() -> list[Path]:
    """Where protocol names are looked up, first match wins: ``./protocols``, then the shipped ones."""
    dirs = []
    local = Path.cwd() / "protocols"
    if local.is_dir():
        dirs.append(local)
    shipped = shipped_protocols_dir()
    if shipped.is_dir() and all(shipped.resolve() != d.resolve() for d in dirs):
        dirs.append(shipped)
    return dirs


def _known_files() -> dict[str, Path]:
    found: dict[str, Path] = {}
    for d in protocol_dirs():
        for path in sorted(d.glob("*.toml")):
            found.setdefault(path.stem, path)
    return found


def _looks_like_path(name: str) -> bool:
    return name.endswith(".toml") or "/" in name or "\\" in name


def read_protocol_file(path: str | Path) -> Protocol:
    """Read and validate one protocol TOML file.

    Raises
    ------
    ProtocolError
        Missing file, malformed TOML (with the line), missing or invalid fields (named).
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ProtocolError(f"protocol file {path} does not exist") from None
    except IsADirectoryError:
        raise ProtocolError(f"protocol file {path} is a folder, not a .toml file") from None
    except OSError as exc:
        raise ProtocolError(f"cannot read protocol file {path}: {exc.strerror}") from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ProtocolError(f"protocol file {path} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ProtocolError(f"protocol file {path} is malformed TOML: {exc}") from None
    where = f"protocol file {path}"
    unknown = [k for k in data if k not in _FILE_KEYS]
    if unknown:
        raise ProtocolError(f"{where}: unknown field(s) {', '.join(map(repr, unknown))}; a protocol has {', '.join(_FILE_KEYS)}")
    for key in ("description", "signal"):
        if key not in data:
            raise ProtocolError(f"{where}: missing field '{key}'")
    if not isinstance(data["description"], str) or not data["description"].strip():
        raise ProtocolError(f"{where}: field 'description' must be a non-empty string")
    spec = _spec(data["signal"], where)
    params = data.get("params", {})
    if not isinstance(params, dict):
        raise ProtocolError(f"{where}: 'params' must be a table (a section headed params)")
    sim = data.get("sim", {})
    if not isinstance(sim, dict):
        raise ProtocolError(f"{where}: 'sim' must be a table of sim config sections (e.g. a section headed sim.contact)")
    design = data.get("design", {})
    if not isinstance(design, dict):
        raise ProtocolError(f"{where}: 'design' must be a table (what the protocol was designed to test)")
    return Protocol(
        name=path.stem,
        description=" ".join(data["description"].split()),
        signal=spec.name,
        params=_resolve_params(spec, params, where),
        source_path=path.resolve(),
        sha256=hashlib.sha256(raw).hexdigest(),
        sim=sim,
        conditions=_conditions(data.get("conditions", {}), spec, where),
        design=design,
    )


def load_protocol(name_or_path: str | Path, overrides: dict | None = None) -> Protocol:
    """A protocol by name (``./protocols`` first, then the shipped ones) or from a ``.toml`` path.

    Parameters
    ----------
    name_or_path : str or Path
        ``damped-sine``, or ``my/protocol.toml``.
    overrides : dict, optional
        Parameter values replacing the file's, e.g. ``{"amplitude_deg": 40, "axes": ["ml"]}``.

    Returns
    -------
    Protocol

    Raises
    ------
    ProtocolError
        Unknown name (listing the known ones), bad file, or an override the protocol
        does not have or cannot take.
    """
    key = str(name_or_path)
    if isinstance(name_or_path, Path) or _looks_like_path(key):
        proto = read_protocol_file(Path(key))
    else:
        files = _known_files()
        if key not in files:
            where = " and ".join(str(d) for d in protocol_dirs()) or "no protocols folder"
            raise ProtocolError(
                f"unknown protocol '{key}': known protocols are {', '.join(sorted(files)) or 'none'} "
                f"(from {where}); or give the path of a .toml file"
            )
        proto = read_protocol_file(files[key])
    return proto.with_overrides(overrides)


def list_protocols() -> list[tuple[str, str, Path]]:
    """Every protocol found by name, sorted: ``(name, description, path)``.

    Raises
    ------
    ProtocolError
        A protocol file in the search folders is invalid (named), rather than hiding it.
    """
    return [(name, read_protocol_file(path).description, path) for name, path in sorted(_known_files().items())]


def parse_overrides(pairs: list[str], option: str = "--set") -> dict:
    """``["amplitude_deg=40", "axes=['ml']", "method=log"]`` -> ``{"amplitude_deg": 40.0, ...}``.

    Values are read as TOML values (numbers, lists, booleans, quoted strings); anything
    that is not a TOML value is taken as a plain string.

    Raises
    ------
    ProtocolError
        A pair without ``=`` or with an empty key (the message names ``option``).
    """
    overrides: dict = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key:
            raise ProtocolError(f"{option} expects key=value, got '{pair}'")
        try:
            overrides[key] = tomllib.loads(f"v = {value}")["v"]
        except tomllib.TOMLDecodeError:
            overrides[key] = value
    return overrides
