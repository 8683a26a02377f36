"""Simulator configuration: the physical parameters and the effect catalog, read from TOML.

A sim config is a TOML file (see ``configs/sim-default.toml`` for every key with its
default and its meaning). Every key is optional; a missing key keeps its default. A key
the schema does not know, a value of the wrong type and a value out of its physical range
are :class:`~endocal.errors.ConfigError` naming the key and the file.

Layout
------
``deviation_deg``
    top-level table, the signed deviation of each half-plane of bending from its nominal
    direction (duodenoscope paper, sec. 3.2: 12.7, 20.2, 2.3, 15.6 deg).
``[tendon]``, ``[bending]``, ``[motor]``, ``[tracker]``
    the always-on physics.
``[rate]``, ``[deadzone]``, ``[envelope]``, ``[coupling]``, ``[delay]``, ``[drift]``, ``[creep]``, ``[load]``
    the effects of the catalogue the simulator produces (:data:`EFFECTS`: the effects whose class
    names its section, ``Effect.sim_section``); each has ``enabled``.
``[contact]``
    an optional obstacle at the tip (ground truth for the contact-force issue).
``[user_effects.NAME]``
    a user's own effect hidden in the plant (:mod:`endocal.sim.user_effects`): its parameters
    by their short names (``per_kdeg = 0.01``) and optionally ``axes = ["axis1"]`` (default: both
    bending axes). The effect comes from the file given with ``--effects-file``, never from
    the config: a config that names an effect no file provides is refused.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from endocal.errors import ConfigError

#: Conditions of the rig the simulator models and logs (a protocol's ``[conditions]``, set per run with
#: ``--set NAME=VALUE``): condition column -> (section, key) of the sim config it sets. The wrap of the
#: sheath along the insertion tube (its curvature) is logged as ``sheath_wrap_deg``; the capstan
#: friction of every tendon grows with it.
CONDITIONS = {"sheath_wrap_deg": ("tendon", "wrap_deg")}

#: Half-plane names of the deviation table: first bending axis towards +y / -y, second towards +x / -x.
HALF_PLANES = ("y+", "y-", "x+", "x-")

#: Duodenoscope paper, sec. 3.2: measured deviation of the U+, U-, L+, L- motion planes (deg).
PAPER_DEVIATION_DEG = {"y+": 12.7, "y-": 20.2, "x+": 2.3, "x-": 15.6}


def _p(default: Any, doc: str, lo: float | None = None, hi: float | None = None, *,
       lo_open: bool = False, hi_open: bool = False, choices: tuple | None = None, length: int | None = None):
    """A schema entry: default, one-line meaning (with unit) and the admissible range."""
    meta = {"doc": doc, "lo": lo, "hi": hi, "lo_open": lo_open, "hi_open": hi_open, "choices": choices, "length": length}
    if isinstance(default, (list, tuple)):
        return field(default_factory=lambda d=tuple(default): d, metadata=meta)
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class TendonConfig:
    """Antagonistic tendon pair of one bending axis, running through the insertion-tube sheath."""

    pulley_radius_mm: float = _p(10.0, "knob pulley radius r_p (mm): tendon pulled per knob radian", 0.0, lo_open=True)
    offset_mm: float = _p(5.0, "tendon offset r_t from the neutral axis of the bending section (mm)", 0.0, lo_open=True)
    sheath_length_mm: float = _p(1000.0, "length of the tendon inside the sheath (mm)", 0.0, lo_open=True)
    axial_stiffness_n: float = _p(8000.0, "effective axial stiffness EA of tendon and sheath in series (N)", 0.0, lo_open=True)
    n_segments: int = _p(12, "number of friction segments along the sheath", 2, 64)
    mu: float = _p(0.2, "Coulomb friction coefficient tendon/sheath (capstan)", 0.0, 2.0)
    wrap_deg: float = _p(180.0, "total wrap angle of the sheath along the insertion tube (deg)", 0.0, 1080.0)
    pretension_n: float = _p(4.0, "tendon pretension at the neutral knob without slack (N)", 0.0, 200.0)
    friction: str = _p("capstan", "friction law of the tendons in the sheath: 'capstan' (Coulomb friction distributed "
                       "along the sheath: a small reversal returns to the branch it left) or 'bouc-wen' (one smooth "
                       "Bouc-Wen element at the knob, frictionless sheath: no return-point memory)",
                       choices=("capstan", "bouc-wen"))
    bouc_wen_lag_deg: float = _p(20.0, "friction = 'bouc-wen': knob lag (deg) at which the element saturates, per unit "
                                 "of the capstan exponent mu * wrap (mu * (1 + rate) * wrap_rad with [rate])", 0.0)
    bouc_wen_sigma: float = _p(1.0, "friction = 'bouc-wen': sigma of the normalised Bouc-Wen law (>= 0.5; the tip "
                               "holds at a reversal from saturation, then picks up along an exponential)", 0.5, 50.0)


@dataclass(frozen=True)
class BendingConfig:
    """Elastic bending section."""

    stiffness_nmm_per_rad: float = _p(30.0, "bending stiffness K: moment per radian of bend (N*mm/rad)", 0.0, lo_open=True)
    friction_nmm: float = _p(8.0, "Coulomb friction moment of the snake-bone joints and cover (N*mm)", 0.0)


@dataclass(frozen=True)
class MotorConfig:
    """Servo position loops (knobs: Dynamixel XM430) and their current readings."""

    knob_time_constant_s: float = _p(0.03, "time constant of the knob position loop (critically damped, s; 0 = ideal)", 0.0, 2.0)
    knob_max_speed_dps: float = _p(400.0, "knob speed limit (deg/s)", 0.0, lo_open=True)
    torque_constant_nm_per_a: float = _p(1.5, "knob torque per motor current (N*m/A)", 0.0, lo_open=True)
    knob_friction_nmm: float = _p(15.0, "Coulomb friction of the knob drive (N*mm)", 0.0)
    current_noise_ma: float = _p(3.0, "Gaussian noise of the current readings, std (mA)", 0.0)
    translation_time_constant_s: float = _p(0.05, "time constant of the translation loop (s)", 0.0, 2.0)
    translation_max_speed_mmps: float = _p(50.0, "translation speed limit (mm/s)", 0.0, lo_open=True)
    translation_friction_ma: float = _p(40.0, "current to overcome translation friction (mA)", 0.0)
    rotation_time_constant_s: float = _p(0.05, "time constant of the rotation loop (s)", 0.0, 2.0)
    rotation_max_speed_dps: float = _p(90.0, "rotation speed limit (deg/s)", 0.0, lo_open=True)
    rotation_friction_ma: float = _p(40.0, "current to overcome rotation friction (mA)", 0.0)


@dataclass(frozen=True)
class TrackerConfig:
    """EM tracker (NDI Aurora-like) with a tip and a base sensor."""

    rate_hz: float = _p(40.0, "frame rate of both sensors (Hz)", 0.0, 1000.0, lo_open=True)
    noise_mm: float = _p(0.5, "position noise, RMS over the three coordinates (mm)", 0.0, 50.0)
    orientation_noise_deg: float = _p(0.1, "orientation noise, RMS rotation angle (deg)", 0.0, 45.0)
    latency_s: float = _p(0.015, "base latency of every frame (s); [delay] adds to it", 0.0, 5.0)
    invalid_rate: float = _p(0.0, "probability that a sensor frame is invalid (missing)", 0.0, 1.0, hi_open=True)
    mount_xyz_mm: tuple = _p((30.0, -40.0, -180.0), "probe mount (base frame at zero translation) in the tracker frame (mm)", length=3)
    mount_rpy_deg: tuple = _p((10.0, -5.0, 25.0), "probe mount orientation, extrinsic x-y-z Euler angles (deg)", length=3)


@dataclass(frozen=True)
class RateConfig:
    """Friction growing with sliding speed: mu_eff = mu * (1 + gain * |knob speed|) (law 'capstan'), or
    the slip thresholds times (1 + gain * |knob speed|) (law 'linear', a plant unlike the catalogue's law)."""

    enabled: bool = _p(False, "switch the effect on")
    gain_s_per_deg: float = _p(0.006, "relative friction increase per deg/s of knob speed (s/deg)", 0.0, 1.0)
    law: str = _p("capstan", "'capstan' (the friction coefficient grows with speed) or 'linear' (the slip "
                  "thresholds grow linearly with speed)", choices=("capstan", "linear"))


@dataclass(frozen=True)
class DeadzoneConfig:
    """Tendon slack that must be taken up before a tendon pulls."""

    enabled: bool = _p(True, "switch the effect on")
    slack_mm: float = _p(1.5, "extra free length of each tendon at the neutral knob (mm)", 0.0, 50.0)
    center_deg: float = _p(0.0, "knob angle at which both tendons are equally slack (deg): a band not centred "
                           "at 0 (the agonist has pulley_radius * center less slack)", -90.0, 90.0)


@dataclass(frozen=True)
class EnvelopeConfig:
    """Bending-section stiffening at large bends: M = K*beta*(1 + (beta/beta_s)^2)."""

    enabled: bool = _p(True, "switch the effect on")
    stiffening_bend_deg: float = _p(110.0, "bend angle beta_s at which the stiffness has doubled (deg)", 0.0, 1000.0, lo_open=True)


@dataclass(frozen=True)
class CouplingConfig:
    """Tendon-hole offsets: the other axis' bend moves this axis' distal tendon ends."""

    enabled: bool = _p(False, "switch the effect on")
    first_from_second: float = _p(0.3, "distal displacement of the first axis' tendons per unit bend of the second", -1.0, 1.0)
    second_from_first: float = _p(0.2, "distal displacement of the second axis' tendons per unit bend of the first", -1.0, 1.0)


@dataclass(frozen=True)
class DelayConfig:
    """Extra tracker/transport latency."""

    enabled: bool = _p(False, "switch the effect on")
    latency_s: float = _p(0.15, "latency added to the tracker's base latency (s)", 0.0, 5.0)


@dataclass(frozen=True)
class DriftConfig:
    """Slow zero drift: the base sensor slips in its mount at a constant rate."""

    enabled: bool = _p(False, "switch the effect on")
    rate_deg_per_min: tuple = _p((1.0, -0.5), "drift of the measured (eq. 1) angle of the first and second axis (deg/min)", -60.0, 60.0, length=2)


@dataclass(frozen=True)
class CreepConfig:
    """Viscoelastic relaxation of the bending section (standard linear solid)."""

    enabled: bool = _p(False, "switch the effect on")
    fraction: float = _p(0.25, "share a of the bend that relaxes slowly (0..1)", 0.0, 1.0)
    time_constant_s: float = _p(2.0, "relaxation time constant tau (s)", 0.0, 3600.0, lo_open=True)
    fraction2: float = _p(0.0, "share of the bend that relaxes with the second time constant (0 = one relaxation)",
                          0.0, 1.0)
    time_constant2_s: float = _p(20.0, "second relaxation time constant (s)", 0.0, 3600.0, lo_open=True)


@dataclass(frozen=True)
class LoadConfig:
    """Insertion-tube curvature changing during the run: the sheath wrap angle varies slowly."""

    enabled: bool = _p(False, "switch the effect on")
    mode: str = _p("random", "'random' (seeded, band-limited) or 'sine' (slow sine)", choices=("random", "sine"))
    amplitude_deg: float = _p(60.0, "largest change of the wrap angle (deg); must not exceed tendon.wrap_deg", 0.0, 1080.0)
    period_s: float = _p(120.0, "period of the 'sine' mode (s)", 0.0, lo_open=True)
    bandwidth_hz: float = _p(0.02, "highest frequency of the 'random' mode (Hz)", 0.0, 10.0, lo_open=True)


@dataclass(frozen=True)
class ContactConfig:
    """A load at the tip of one bending axis: a wall past a given bend, or a hung weight.

    Either way the tip force ``F`` acts perpendicular to the tip in the axis' plane, so its
    moment about the base of the bending section is ``F * L(beta)`` with the constant-curvature
    lever arm ``L(beta) = l sin(beta) / beta`` (the tip's axial distance from the base).
    """

    enabled: bool = _p(False, "switch the obstacle on")
    mode: str = _p("wall", "'wall' (an elastic wall past wall_deg) or 'weight' (a constant force weight_n at the tip)",
                   choices=("wall", "weight"))
    axis: str = _p("axis1", "bending axis the wall blocks: 'axis1', 'axis2' or the probe's axis name")
    wall_deg: float = _p(25.0, "eq.-1 angle where the tip meets the wall (deg, sign = half-plane)", -89.0, 89.0)
    stiffness_n_per_mm: float = _p(0.05, "wall stiffness at the tip (N/mm)", 0.0, lo_open=True)
    weight_n: float = _p(0.5, "mode 'weight': force hung at the tip (N), opposing bending towards the positive half-plane", 0.0, 20.0)


_SECTIONS: dict[str, type] = {
    "tendon": TendonConfig,
    "bending": BendingConfig,
    "motor": MotorConfig,
    "tracker": TrackerConfig,
    "rate": RateConfig,
    "deadzone": DeadzoneConfig,
    "envelope": EnvelopeConfig,
    "coupling": CouplingConfig,
    "delay": DelayConfig,
    "drift": DriftConfig,
    "creep": CreepConfig,
    "load": LoadConfig,
    "contact": ContactConfig,
}


def simulated_effects() -> tuple[str, ...]:
    """The catalogue's effects this simulator produces: those whose class names one of its sections
    (``Effect.sim_section``), in the order of the sections."""
    from endocal.models.effects import EFFECTS as CATALOGUE

    simulated = {cls.sim_section for cls in CATALOGUE.values() if cls.sim_section}
    return tuple(name for name in _SECTIONS if name in simulated)


#: The effects the simulator switches (each section has ``enabled``), asked of the catalogue.
EFFECTS = simulated_effects()


def _coerce(value: Any, f: dataclasses.Field, key: str, where: str) -> Any:
    """Check one value against its schema entry; return it in its canonical Python type."""
    meta, default = f.metadata, (f.default if f.default is not dataclasses.MISSING else f.default_factory())
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: '{key}' must be true or false, got {value!r}")
        return value
    if isinstance(default, str):
        if not isinstance(value, str) or not value:
            raise ConfigError(f"{where}: '{key}' must be a non-empty string, got {value!r}")
        if meta["choices"] and value not in meta["choices"]:
            raise ConfigError(f"{where}: '{key}' must be one of {', '.join(meta['choices'])}, got {value!r}")
        return value
    if isinstance(default, tuple):
        if not isinstance(value, (list, tuple)) or len(value) != meta["length"]:
            raise ConfigError(f"{where}: '{key}' must be a list of {meta['length']} numbers, got {value!r}")
        return tuple(_number(v, meta, key, where, float) for v in value)
    return _number(value, meta, key, where, int if isinstance(default, int) else float)


def _number(value: Any, meta: dict, key: str, where: str, kind: type) -> float | int:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (kind is int and not isinstance(value, int)):
        raise ConfigError(f"{where}: '{key}' must be {'an integer' if kind is int else 'a number'}, got {value!r}")
    value = kind(value)
    if not math.isfinite(value):
        raise ConfigError(f"{where}: '{key}' must be finite, got {value!r}")
    lo, hi = meta["lo"], meta["hi"]
    if lo is not None and (value < lo or (meta["lo_open"] and value == lo)):
        raise ConfigError(f"{where}: '{key}' = {value} is out of range: it must be {'>' if meta['lo_open'] else '>='} {lo} ({meta['doc']})")
    if hi is not None and (value > hi or (meta["hi_open"] and value == hi)):
        raise ConfigError(f"{where}: '{key}' = {value} is out of range: it must be {'<' if meta['hi_open'] else '<='} {hi} ({meta['doc']})")
    return value


def _build_section(name: str, cls: type, data: Any, where: str):
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: [{name}] must be a table of keys, got {data!r}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(
            f"{where}: unknown key '{name}.{unknown[0]}' (known keys in [{name}]: {', '.join(fields)})"
        )
    return cls(**{k: _coerce(v, fields[k], f"{name}.{k}", where) for k, v in data.items()})


def _deviation(data: Any, where: str) -> dict[str, float]:
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: 'deviation_deg' must be a table like {{ \"y+\" = 12.7, ... }}, got {data!r}")
    unknown = sorted(set(data) - set(HALF_PLANES))
    if unknown:
        raise ConfigError(f"{where}: unknown key 'deviation_deg.{unknown[0]}' (half-planes are {', '.join(HALF_PLANES)})")
    out = dict(PAPER_DEVIATION_DEG)
    meta = {"lo": -60.0, "hi": 60.0, "lo_open": False, "hi_open": False, "doc": "signed deviation of a half-plane, deg"}
    for k, v in data.items():
        out[k] = float(_number(v, meta, f"deviation_deg.{k}", where, float))
    return out


@dataclass(frozen=True)
class SimConfig:
    """Everything the simulator needs besides the probe: physics, tracker and the effect catalog.

    Build it with :meth:`default`, :meth:`from_toml` or :meth:`from_dict`; derive variants with
    :meth:`replace`. Frozen: a config never changes once a simulator uses it.

    Attributes
    ----------
    deviation_deg : dict
        ``{"y+", "y-", "x+", "x-"} -> deg``: signed deviation (counter-clockwise about base
        ``+z``) of each half-plane of bending from its nominal direction (+y = 90 deg,
        -y = 270 deg, +x = 0 deg, -x = 180 deg). Duodenoscope paper, sec. 3.2.
    tendon, bending, motor, tracker :
        Always-on physics, see the section classes.
    rate, deadzone, envelope, coupling, delay, drift, creep, load :
        Effects, each with ``enabled``.
    contact :
        Optional obstacle at the tip.
    user_effects : dict
        ``name -> {short parameter name: value, "axes": [...]}``: a user's effects hidden in the
        plant (:mod:`endocal.sim.user_effects`).
    """

    deviation_deg: dict = field(default_factory=lambda: dict(PAPER_DEVIATION_DEG))
    tendon: TendonConfig = field(default_factory=TendonConfig)
    bending: BendingConfig = field(default_factory=BendingConfig)
    motor: MotorConfig = field(default_factory=MotorConfig)
    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    rate: RateConfig = field(default_factory=RateConfig)
    deadzone: DeadzoneConfig = field(default_factory=DeadzoneConfig)
    envelope: EnvelopeConfig = field(default_factory=EnvelopeConfig)
    coupling: CouplingConfig = field(default_factory=CouplingConfig)
    delay: DelayConfig = field(default_factory=DelayConfig)
    drift: DriftConfig = field(default_factory=DriftConfig)
    creep: CreepConfig = field(default_factory=CreepConfig)
    load: LoadConfig = field(default_factory=LoadConfig)
    contact: ContactConfig = field(default_factory=ContactConfig)
    user_effects: dict = field(default_factory=dict)

    # -- construction -------------------------------------------------------------------
    @classmethod
    def default(cls) -> SimConfig:
        """The default digital twin: TEE-like magnitudes, ``envelope`` and ``deadzone`` on."""
        return cls()

    @classmethod
    def from_dict(cls, data: dict, where: str = "sim config") -> SimConfig:
        """Build from nested dicts as in the TOML file; missing keys keep their defaults.

        Raises
        ------
        ConfigError
            Unknown key (named with its section and ``where``), wrong type or out-of-range value.
        """
        if not isinstance(data, dict):
            raise ConfigError(f"{where}: a sim config must be a table of sections")
        known = {"deviation_deg", "user_effects", *_SECTIONS}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(f"{where}: unknown key '{unknown[0]}' (known sections: deviation_deg, {', '.join(_SECTIONS)})")
        kwargs: dict[str, Any] = {}
        if "deviation_deg" in data:
            kwargs["deviation_deg"] = _deviation(data["deviation_deg"], where)
        for name, section_cls in _SECTIONS.items():
            if name in data:
                kwargs[name] = _build_section(name, section_cls, data[name], where)
        if "user_effects" in data:
            from endocal.sim.user_effects import check_user_effects

            kwargs["user_effects"] = check_user_effects(data["user_effects"], where)
        cfg = cls(**kwargs)
        cfg._check_consistency(where)
        return cfg

    @classmethod
    def from_toml(cls, path: str | Path) -> SimConfig:
        """Read a sim config TOML file.

        Raises
        ------
        ConfigError
            Missing or unreadable file, malformed TOML, unknown key, bad value.
        """
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise ConfigError(f"sim config {path} does not exist") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise ConfigError(f"sim config {path} cannot be read: {exc}") from None
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"sim config {path} is not valid TOML: {exc}") from None
        return cls.from_dict(data, where=str(path))

    def replace(self, **sections: dict) -> SimConfig:
        """A copy with some keys changed, e.g. ``cfg.replace(rate={"enabled": True}, tendon={"mu": 0.2})``.

        Validated exactly like a file.
        """
        data = self.to_dict()
        for name, values in sections.items():
            if name == "user_effects" and name not in data:  # the first hidden user effect
                data[name] = {}
            if name not in data:
                raise ConfigError(f"sim config: unknown section '{name}'")
            if not isinstance(values, dict):
                raise ConfigError(f"sim config: replace({name}=...) takes a dict of keys")
            data[name] = {**data[name], **values}
        return SimConfig.from_dict(data, where="sim config (replace)")

    def _check_consistency(self, where: str) -> None:
        if self.creep.fraction + self.creep.fraction2 > 1.0:
            raise ConfigError(f"{where}: creep.fraction + creep.fraction2 ({self.creep.fraction} + "
                              f"{self.creep.fraction2}) exceeds 1: more of the bend cannot relax than there is")
        if self.load.enabled and self.load.amplitude_deg > self.tendon.wrap_deg:
            raise ConfigError(
                f"{where}: load.amplitude_deg ({self.load.amplitude_deg}) exceeds tendon.wrap_deg "
                f"({self.tendon.wrap_deg}); the sheath wrap angle cannot become negative"
            )

    # -- export -------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Nested plain dict (JSON/TOML-ready) of every parameter, for ``run.json``."""
        out: dict[str, Any] = {"deviation_deg": dict(self.deviation_deg)}
        for name in _SECTIONS:
            section = getattr(self, name)
            out[name] = {f.name: (list(v) if isinstance(v := getattr(section, f.name), tuple) else v)
                         for f in dataclasses.fields(section)}
        if self.user_effects:  # absent otherwise: the hash of every config without one is unchanged
            out["user_effects"] = {k: dict(v) for k, v in self.user_effects.items()}
        return out

    def effects_enabled(self) -> list[str]:
        """Names of the switched-on effects, in catalog order (``contact`` is listed after them if on, then the
        user's hidden effects)."""
        names = [name for name in EFFECTS if getattr(self, name).enabled]
        if self.contact.enabled:
            names.append("contact")
        return names + list(self.user_effects)

    def config_hash(self) -> str:
        """First 16 hex digits of the SHA-256 of the canonical JSON of :meth:`to_dict`."""
        text = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def schema() -> dict[str, dict[str, tuple[Any, str]]]:
    """``section -> key -> (default, doc)`` for every parameter (used to keep the default TOML true)."""
    out: dict[str, dict[str, tuple[Any, str]]] = {
        "deviation_deg": {k: (v, "signed half-plane deviation (deg)") for k, v in PAPER_DEVIATION_DEG.items()}
    }
    for name, cls in _SECTIONS.items():
        out[name] = {}
        for f in dataclasses.fields(cls):
            default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
            out[name][f.name] = (list(default) if isinstance(default, tuple) else default, f.metadata["doc"])
    return out
