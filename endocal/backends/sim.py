"""The simulator as a backend: :class:`SimBackend` wraps :class:`endocal.sim.Simulator`.

It runs as fast as it can (``realtime = False``); pacing to the wall clock is the caller's job.
"""

from __future__ import annotations

import numpy as np

from endocal.backends.base import StreamChunk
from endocal.backends.limits import GoalChecker
from endocal.probe import ProbeConfig
from endocal.sim import SimConfig, Simulator


class SimBackend:
    """Backend contract over the physics simulator.

    Parameters
    ----------
    config : SimConfig
        Simulator configuration (``SimConfig.default()`` when None).
    probe : ProbeConfig
    seed : int
        Seed of every random draw; the same seed and goals give the same streams.
    """

    name = "sim"
    realtime = False

    def __init__(self, config: SimConfig | None, probe: ProbeConfig, seed: int = 0) -> None:
        self.config = config if config is not None else SimConfig.default()
        self.probe = probe
        self.seed = seed
        self._sim: Simulator | None = None
        #: Per-tick hook (:class:`endocal.force.guard.ForceGuard`) or None; see :meth:`attach_guard`.
        self.force_guard = None
        Simulator(self.config, probe, seed)  # validate now (contact axis, seed) rather than at open()

    def attach_guard(self, guard) -> None:
        """Step ``guard`` at every simulated tick (it may hold back its knob's goal); None detaches."""
        self.force_guard = guard

    def with_settings(self, sections: dict) -> SimBackend:
        """A fresh backend with some sim-config sections changed (a protocol's ``[sim]`` table).

        Raises
        ------
        ConfigError
            An unknown section or key, or a bad value (validated like a sim config file).
        """
        backend = SimBackend(self.config.replace(**sections) if sections else self.config, self.probe, self.seed)
        backend.force_guard = self.force_guard
        return backend

    def open(self) -> None:
        """Start a fresh simulation (neutral probe, clock and random streams at their start)."""
        self._sim = Simulator(self.config, self.probe, self.seed)
        self._checker = GoalChecker(self.probe)

    def execute(self, t_s: np.ndarray, goal: dict[str, np.ndarray]) -> StreamChunk:
        """Simulate one chunk; see :meth:`endocal.sim.Simulator.execute`. Opens on first use."""
        if self._sim is None:
            self.open()
        self._checker.check(t_s, goal)  # the probe's limits, as the hardware backend checks them
        return self._sim.execute(t_s, goal, guard=self.force_guard)

    def close(self) -> None:
        """Release the simulation; safe to call more than once."""
        self._sim = None

    def describe(self) -> dict:
        """What ``run.json`` records: config (every parameter), seed, config hash, effects on."""
        return {
            "config": self.config.to_dict(),
            "config_hash": self.config.config_hash(),
            "seed": self.seed,
            "effects_enabled": self.config.effects_enabled(),
        }
