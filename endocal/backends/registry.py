"""Choose and build a backend by name; hardware modules are imported only when asked for."""

from __future__ import annotations

from pathlib import Path

from endocal.backends.base import Backend
from endocal.errors import ConfigError
from endocal.probe import ProbeConfig

BACKENDS = ("sim", "hardware")


def make_backend(
    name: str,
    probe: ProbeConfig,
    *,
    seed: int = 0,
    sim_config: Path | None = None,
    hardware_config: Path | None = None,
) -> Backend:
    """Build the backend ``name`` for ``probe``.

    Parameters
    ----------
    name : {"sim", "hardware"}
    sim_config : Path, optional
        Simulator TOML (defaults: ``SimConfig.default()``).
    hardware_config : Path
        Rig TOML, required for ``hardware``.

    Raises
    ------
    ConfigError
        Unknown backend, a config given to the wrong backend, or a malformed config.
    """
    if name == "sim":
        if hardware_config is not None:
            raise ConfigError("--hardware-config applies to --backend hardware, not sim")
        from endocal.backends.sim import SimBackend
        from endocal.sim import SimConfig

        cfg = SimConfig.from_toml(sim_config) if sim_config is not None else SimConfig.default()
        return SimBackend(cfg, probe, seed=seed)
    if name == "hardware":
        if sim_config is not None:
            raise ConfigError("--sim-config applies to --backend sim, not hardware")
        if hardware_config is None:
            raise ConfigError("--backend hardware needs --hardware-config RIG.toml (see configs/hardware-example.toml)")
        from endocal.backends.hardware import HardwareBackend, HardwareConfig

        return HardwareBackend(HardwareConfig.from_toml(hardware_config), probe)
    raise ConfigError(f"unknown backend '{name}': use one of {', '.join(BACKENDS)}")
