"""A user's own effects, hidden in the simulated plant: ``[user_effects.NAME]`` of a sim config.

The same file that adds an effect to the models hides it in the simulator, so the whole loop
(record, validate, refit) can be tried on a plant that has it. The sim config names the effect
and its true parameters; the effect's class comes from the file the user gives with
``--effects-file`` (``endocal excite ... --sim-config plant.toml --effects-file wear.py``), never
from the config itself::

    [user_effects.wear]
    per_kdeg = 0.01        # the effect's parameters, by their short names (its ``units``)
    axes = ["axis1"]       # optional: the bending axes it acts on (default: both)

How the plant produces it, per bending axis, on each record from its start:

- an effect that defines ``simulate(data, rng)`` (the contract's hook) returns the axis's angle
  with the effect added; ``data`` holds the knob's goal (``cmd_deg``), the time and the noise-free
  angle the plant bent to (``meas_deg``: half the axis's bend, the eq.-1 angle of an in-plane bend);
- else an input effect (:class:`~endocal.models.effects.base.InputEffect`) changes the knob goal the
  tendons are pulled by: the run logs the goal as written, and the knob's position as it moved, so
  the tendon follows the effect's output;
- else an output filter or an additive term acts on that angle with its own equation.

Chunks (:meth:`HiddenEffects.goal`, :meth:`HiddenEffects.bend`) give the same streams as one
call: each effect is evaluated on the record so far and the new samples are kept.
"""

from __future__ import annotations

import math

import numpy as np

from endocal.errors import ConfigError


def check_user_effects(table, where: str) -> dict:
    """``[user_effects]`` of a sim config, checked: each name a registered effect of the user's, each
    key one of its parameters (or ``axes``), each value a finite number.

    Raises
    ------
    ConfigError
    """
    from endocal.models.effects import EFFECTS
    from endocal.models.userfile import is_users

    if not isinstance(table, dict):
        raise ConfigError(f"{where}: [user_effects] must be a table of [user_effects.NAME] tables")
    out = {}
    for name, values in table.items():
        cls = EFFECTS.get(name)
        if cls is None:
            raise ConfigError(f"{where}: [user_effects.{name}] names an effect no --effects-file provides: give the "
                              f"file that defines '{name}' with --effects-file")
        if not is_users(cls):
            raise ConfigError(f"{where}: [user_effects.{name}]: '{name}' is the catalogue's"
                              + (f"; switch it on in its own section [{cls.sim_section}]" if cls.sim_section else
                                 ": the simulator hides only a user's effects"))
        if not isinstance(values, dict):
            raise ConfigError(f"{where}: [user_effects.{name}] must be a table of its parameters")
        short = list(cls.units)
        unknown = sorted(set(values) - set(short) - {"axes"})
        if unknown:
            raise ConfigError(f"{where}: unknown key 'user_effects.{name}.{unknown[0]}' (effect '{name}' has parameters "
                              f"{', '.join(short) or 'none'}, and axes)")
        missing = [k for k in short if k not in values]
        if missing:
            raise ConfigError(f"{where}: [user_effects.{name}] lacks {', '.join(missing)}: give every parameter of "
                              "the hidden effect its true value")
        checked = {}
        for k, v in values.items():
            if k == "axes":
                if not (isinstance(v, list) and v and all(isinstance(a, str) for a in v)):
                    raise ConfigError(f"{where}: 'user_effects.{name}.axes' must be a list of axis names, got {v!r}")
                checked[k] = list(v)
            elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ConfigError(f"{where}: 'user_effects.{name}.{k}' must be a finite number, got {v!r}")
            else:
                checked[k] = float(v)
        out[name] = checked
    return out


class HiddenEffects:
    """The user's effects of a sim config, as the simulator applies them (module docstring).

    Parameters
    ----------
    table : dict
        ``SimConfig.user_effects``.
    axes : sequence of str
        The probe's two bending axes.
    resolve_axis : callable
        The probe's ``resolve_axis`` (``axis1`` -> its name).
    seed : int
        Seed of a ``simulate`` hook's generator.
    """

    def __init__(self, table: dict, axes, resolve_axis, seed: int) -> None:
        from endocal.models.effects import EFFECTS
        from endocal.models.effects.base import InputEffect

        self.seed = seed
        self._inputs, self._outputs = [], []
        for i, (name, values) in enumerate(table.items()):
            cls = EFFECTS.get(name)
            if cls is None:
                raise ConfigError(f"sim config: [user_effects.{name}] names an effect no --effects-file provides: "
                                  f"give the file that defines '{name}' with --effects-file")
            on = []
            for a in values.get("axes", list(axes)):
                try:
                    resolved = resolve_axis(a)
                except ConfigError as exc:
                    raise ConfigError(f"user_effects.{name}.axes: {exc}") from None
                if resolved not in axes:
                    raise ConfigError(f"user_effects.{name}.axes: '{a}' is not a bending axis ({', '.join(axes)})")
                on.append(list(axes).index(resolved))
            try:
                effect = cls()
            except Exception as exc:  # one that takes a column (NAME:COLUMN), or the user's constructor failing
                raise ConfigError(f"sim config: [user_effects.{name}]: the simulator hides effects made without an "
                                  f"argument; {name}() raised {type(exc).__name__}: {exc}") from None
            p = {k: v for k, v in values.items() if k != "axes"}
            hook = callable(getattr(effect, "simulate", None))
            item = (effect, p, sorted(set(on)), i)
            (self._inputs if isinstance(effect, InputEffect) and not hook else self._outputs).append(item)
        self._inputs.sort(key=lambda x: x[0].order)
        self._t = np.empty(0)
        self._goal = np.empty((0, 2))
        self._angle = np.empty((0, 2))

    def __bool__(self) -> bool:
        return bool(self._inputs or self._outputs)

    def goal(self, t_s: np.ndarray, goal_deg: np.ndarray) -> np.ndarray:
        """The knob goals (deg, (n, 2)) the tendons are pulled by, for this chunk's goals as written
        (each input effect in its ``order``, on the record so far)."""
        from endocal.models.data import HysteresisData

        self._t = np.concatenate([self._t, t_s])
        self._goal = np.concatenate([self._goal, goal_deg])
        out = np.array(goal_deg, dtype=float)
        n = t_s.size
        for ax in range(2):
            u, changed = self._goal[:, ax].copy(), False
            data = HysteresisData(cmd_deg=u, t_s=self._t)
            for effect, p, on, _ in self._inputs:
                if ax in on:
                    u, changed = np.asarray(effect.apply(p, u, data), dtype=float), True
            if changed:
                out[:, ax] = u[-n:]
        return out

    def bend(self, t_s: np.ndarray, beta_rad: np.ndarray) -> np.ndarray:
        """The per-axis bends (rad, (n, 2)) with the output-side effects added (the chunk's ``t_s``, as
        passed to :meth:`goal` before)."""
        if not self._outputs:
            return beta_rad
        from endocal.models.data import HysteresisData
        from endocal.models.effects.base import OutputEffect

        self._angle = np.concatenate([self._angle, np.degrees(beta_rad) / 2.0])  # eq. 1: half an in-plane bend
        n = t_s.size
        out = np.array(beta_rad, dtype=float)
        for ax in range(2):
            y = self._angle[:, ax].copy()
            changed = False
            for effect, p, on, i in self._outputs:
                if ax not in on:
                    continue
                data = HysteresisData(cmd_deg=self._goal[:, ax], meas_deg=y, t_s=self._t)
                if callable(getattr(effect, "simulate", None)):
                    rng = np.random.default_rng(np.random.SeedSequence([self.seed, i, ax]))  # same draws every chunk
                    y = np.asarray(effect.simulate(data, rng), dtype=float)
                elif isinstance(effect, OutputEffect):
                    y = y + np.asarray(effect.term(p, data.cmd_deg, data), dtype=float)
                else:
                    y = np.asarray(effect.apply(p, y, data), dtype=float)
                changed = True
            if changed:
                out[:, ax] = np.radians(2.0 * y[-n:])
        return out
