"""Contact-force prediction from the knob torque and the safety guard (duodenoscope paper, sec. 2.4).

- :mod:`endocal.force.model`: :func:`fit_force`, :class:`ForceModel` (eqs. 12-15);
- :mod:`endocal.force.io`: versioned JSON files;
- :mod:`endocal.force.guard`: :class:`ForceGuard`, the per-tick stop at a force threshold.
"""

from endocal.force.guard import ForceGuard, check_guard_fits
from endocal.force.io import load_force_model, save_force_model
from endocal.force.model import ForceModel, fit_force

__all__ = ["ForceGuard", "ForceModel", "check_guard_fits", "fit_force", "load_force_model", "save_force_model"]
