"""Probe configurations: which degrees of freedom a probe has, their names, units and limits.

Frames and axis convention (used everywhere in endocal)
-------------------------------------------------------
The *base frame* sits at the base of the bending section (where the base EM sensor
is), with ``z`` along the straight probe, pointing distally. The first bending axis
(``ap`` on the TEE probe, ``ud`` on the duodenoscope) bends the tip towards ``+y``
or ``-y`` (its plane is the standard ``y-z`` plane); the second (``ml`` / ``lr``)
bends it towards ``+x`` or ``-x`` (standard ``x-z`` plane). A positive knob angle
bends towards the positive half-plane when the planes are not twisted.

Translation (mm) moves the whole probe along the base ``z`` axis; rotation (deg)
turns it about that axis. Knob angles are in degrees.
"""

from __future__ import annotations

import tomllib
from dataclasses import asdict, dataclass
from pathlib import Path

from endocal.errors import ConfigError

TRANSLATION = "translation"
ROTATION = "rotation"


@dataclass(frozen=True)
class ProbeConfig:
    """Geometry, degrees of freedom and limits of one probe.

    Parameters
    ----------
    name : str
        Short name (``tee``, ``duodenoscope`` or a user's own).
    bending_axes : tuple of str
        Names of the two bending knobs; the first bends in the ``y-z`` plane, the
        second in the ``x-z`` plane of the base frame.
    knob_limits_deg : dict
        Per bending axis, ``(min, max)`` knob angle in degrees. Commands beyond
        these are refused before anything moves.
    bending_length_mm : float
        Length of the bending section between base and tip sensors, in mm.
    translation_limits_mm, rotation_limits_deg : tuple of float
        Range of the insertion translation (mm) and of the probe rotation (deg).
    max_knob_speed_dps : float
        Fastest knob speed a protocol may ask for, in deg/s.
    max_knob_accel_dps2 : float
        Largest change of knob speed per second, deg/s^2. The default, 10 000 deg/s^2, lets a
        knob reach 100 deg/s in 10 ms (one tick at 100 Hz), within what an XM430 on a knob
        delivers, and refuses what no servo follows: a step to full speed in one tick
        (36 000 deg/s^2), e.g. an inverse backlash model's jump across its dead band.
    """

    name: str
    bending_axes: tuple[str, str]
    knob_limits_deg: dict[str, tuple[float, float]]
    bending_length_mm: float
    translation_limits_mm: tuple[float, float] = (-150.0, 150.0)
    rotation_limits_deg: tuple[float, float] = (-180.0, 180.0)
    max_knob_speed_dps: float = 360.0
    max_knob_accel_dps2: float = 10000.0

    def __post_init__(self) -> None:
        if len(self.bending_axes) != 2 or len(set(self.bending_axes)) != 2:
            raise ConfigError(f"probe '{self.name}': bending_axes must name two different knobs, got {self.bending_axes}")
        reserved = {TRANSLATION, ROTATION}
        for axis in self.bending_axes:
            if axis in reserved or not axis.isidentifier():
                raise ConfigError(f"probe '{self.name}': '{axis}' cannot name a bending axis (use a short identifier)")
            if axis not in self.knob_limits_deg:
                raise ConfigError(f"probe '{self.name}': no knob_limits_deg for axis '{axis}'")
            lo, hi = self.knob_limits_deg[axis]
            if not lo < 0 < hi:
                raise ConfigError(f"probe '{self.name}': knob limits for '{axis}' must bracket 0, got ({lo}, {hi})")
        if not self.bending_length_mm > 0:
            raise ConfigError(f"probe '{self.name}': bending_length_mm must be positive")
        if not (self.max_knob_speed_dps > 0 and self.max_knob_accel_dps2 > 0):
            raise ConfigError(f"probe '{self.name}': max_knob_speed_dps and max_knob_accel_dps2 must be positive")

    @property
    def dofs(self) -> tuple[str, ...]:
        """All degrees of freedom: the two bending knobs, then translation and rotation."""
        return (*self.bending_axes, TRANSLATION, ROTATION)

    def unit(self, dof: str) -> str:
        """Unit suffix of a degree of freedom: ``mm`` for translation, ``deg`` otherwise."""
        return "mm" if dof == TRANSLATION else "deg"

    def limits(self, dof: str) -> tuple[float, float]:
        """``(min, max)`` of a degree of freedom in its unit."""
        if dof == TRANSLATION:
            return self.translation_limits_mm
        if dof == ROTATION:
            return self.rotation_limits_deg
        try:
            return self.knob_limits_deg[dof]
        except KeyError:
            raise ConfigError(
                f"unknown axis '{dof}' for probe '{self.name}' (it has {', '.join(self.dofs)})"
            ) from None

    def resolve_axis(self, name: str) -> str:
        """Turn an axis reference (a name, or the aliases ``axis1``/``axis2``) into a DoF name."""
        aliases = {"axis1": self.bending_axes[0], "axis2": self.bending_axes[1]}
        dof = aliases.get(name, name)
        if dof not in self.dofs:
            raise ConfigError(
                f"unknown axis '{name}' for probe '{self.name}' (it has {', '.join(self.dofs)}, or axis1/axis2)"
            )
        return dof

    def to_dict(self) -> dict:
        d = asdict(self)
        d["bending_axes"] = list(self.bending_axes)
        d["knob_limits_deg"] = {k: list(v) for k, v in self.knob_limits_deg.items()}
        d["translation_limits_mm"] = list(self.translation_limits_mm)
        d["rotation_limits_deg"] = list(self.rotation_limits_deg)
        return d

    @classmethod
    def from_dict(cls, d: dict, where: str = "probe") -> ProbeConfig:
        known = {"name", "bending_axes", "knob_limits_deg", "bending_length_mm",
                 "translation_limits_mm", "rotation_limits_deg", "max_knob_speed_dps", "max_knob_accel_dps2"}
        if not isinstance(d, dict):
            raise ConfigError(f"{where}: the probe must be a table of its keys ({', '.join(sorted(known))}), "
                              f"got {type(d).__name__}; restore it (or record the run again)")
        unknown = set(d) - known
        if unknown:
            raise ConfigError(f"{where}: unknown key(s) {sorted(unknown)}; known keys are {sorted(known)}")
        try:
            return cls(
                name=str(d["name"]),
                bending_axes=tuple(d["bending_axes"]),
                knob_limits_deg={k: (float(v[0]), float(v[1])) for k, v in d["knob_limits_deg"].items()},
                bending_length_mm=float(d["bending_length_mm"]),
                translation_limits_mm=tuple(float(x) for x in d.get("translation_limits_mm", (-150.0, 150.0))),
                rotation_limits_deg=tuple(float(x) for x in d.get("rotation_limits_deg", (-180.0, 180.0))),
                max_knob_speed_dps=float(d.get("max_knob_speed_dps", 360.0)),
                max_knob_accel_dps2=float(d.get("max_knob_accel_dps2", 10000.0)),
            )
        except KeyError as exc:
            raise ConfigError(f"{where}: missing key {exc.args[0]!r}") from None
        except (TypeError, ValueError, AttributeError, IndexError) as exc:
            raise ConfigError(f"{where}: a key of the probe has the wrong type or shape ({exc}); restore it") from None
        except (TypeError, ValueError, IndexError) as exc:
            raise ConfigError(f"{where}: {exc}") from None


PRESETS: dict[str, ProbeConfig] = {
    # Philips X7-2t TEE probe as robotised in the thesis: AP on the lower knob, ML on the upper.
    "tee": ProbeConfig(
        name="tee",
        bending_axes=("ap", "ml"),
        knob_limits_deg={"ap": (-90.0, 90.0), "ml": (-90.0, 90.0)},
        bending_length_mm=60.0,
    ),
    # Side-viewing duodenoscope of the Machines 2024 paper: U/D and L/R knobs.
    "duodenoscope": ProbeConfig(
        name="duodenoscope",
        bending_axes=("ud", "lr"),
        knob_limits_deg={"ud": (-100.0, 100.0), "lr": (-90.0, 90.0)},
        bending_length_mm=45.0,
    ),
}


def load_probe(name_or_path: str | Path | None) -> ProbeConfig:
    """A preset by name (``tee`` when None), or a probe TOML file.

    Raises
    ------
    ConfigError
        Unknown preset, unreadable or malformed file.
    """
    if name_or_path is None:
        return PRESETS["tee"]
    key = str(name_or_path)
    if key in PRESETS:
        return PRESETS[key]
    path = Path(key)
    if not path.suffix == ".toml":
        raise ConfigError(f"unknown probe '{key}': use one of {', '.join(PRESETS)} or a .toml file")
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"probe file {path} does not exist") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"probe file {path} is not valid TOML: {exc}") from None
    return ProbeConfig.from_dict(data.get("probe", data), where=str(path))
