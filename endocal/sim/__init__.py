"""Physics simulator of a robot-driven, tendon-driven probe: the default backend of ``endocal excite``.

A digital twin built from tendon-sheath mechanics (capstan friction, tendon elasticity and
slack), an elastic bending section in constant curvature with deviated bending planes,
servo position loops and an EM tracker, with a catalog of switchable effects
(:data:`EFFECTS`). It is *not* one of the hysteresis models endocal fits.

    >>> from endocal.probe import PRESETS
    >>> from endocal.sim import SimConfig, Simulator
    >>> sim = Simulator(SimConfig.default(), PRESETS["tee"], seed=0)
    >>> chunk = sim.execute(t_s, goal)          # doctest: +SKIP
"""

from endocal.sim.config import EFFECTS, SimConfig
from endocal.sim.simulator import Simulator

__all__ = ["EFFECTS", "SimConfig", "Simulator"]
