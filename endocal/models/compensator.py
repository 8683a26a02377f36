"""Streaming feedforward compensation for a control loop (1 kHz): one desired angle in, one command out.

:class:`StreamingCompensator` holds the inverse model's state (the inverse play
operators of the PI, eqs. 9-11 of the duodenoscope paper, or the last command and
output of a direction-dependent model) so each loop tick costs one call of
:meth:`StreamingCompensator.step`. It gives the same commands as the batch
:meth:`~endocal.models.base.HysteresisModel.inverse` on the same sequence.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from endocal.errors import ModelError, OutOfRangeWarning
from endocal.models.data import HysteresisData
from endocal.models.effects.base import InputEffect
from endocal.models.effects.base import OutputFilter


class StreamingCompensator:
    """Sample-by-sample inverse of a fitted model.

    Parameters
    ----------
    model : HysteresisModel
        A fitted model whose effects can all be compensated causally (``envelope``,
        ``deadzone``, ``rate``, ``creep`` can; ``delay`` needs future samples, ``load``,
        ``coupling`` and ``drift`` logged columns or time, so they cannot).
    dt_s : float, optional
        Fixed sample period of the loop (s), needed by ``rate`` and ``creep``.

    Raises
    ------
    ModelError
        Unfitted model, an effect that cannot run sample by sample, or a time-based
        effect without ``dt_s``.
    """

    def __init__(self, model, dt_s: float | None = None):
        model._require_fitted()
        model.check_effects_invert()
        for e in model.effects_:
            if not e.streamable:
                raise ModelError(f"effect '{e.label}' cannot be compensated one sample at a time "
                                 "(it needs future samples or logged columns); use model.inverse(...) on the whole trajectory")
        if dt_s is not None and not (isinstance(dt_s, (int, float)) and math.isfinite(dt_s) and dt_s > 0):
            raise ModelError(f"dt_s must be a positive sample period in seconds, got {dt_s!r}")
        self.model = model
        self.dt_s = dt_s
        base_p, eff_p = model._grouped(model.params_)
        self._filters = [(e, eff_p[id(e)]) for e in reversed(model.effects_) if isinstance(e, OutputFilter)]
        self._inputs = [(e, eff_p[id(e)]) for e in reversed(model.effects_) if isinstance(e, InputEffect)]
        self._base = model._base_stepper(model.structure_, base_p, model._v_range())
        self._lo, self._hi = model.cmd_range_deg_
        self._clamp = model.out_of_range == "clamp"
        self.reset()

    def reset(self, history_cmd_deg=None) -> None:
        """Start over: from rest (fresh operators), or continuing after the commands already played.

        Parameters
        ----------
        history_cmd_deg : ndarray (m,), optional
            Commands (deg) the knob received since the operators were last at rest; the
            compensator then continues from the forward model's state after them
            (for the PI, the inverse plays are loaded by eq. 11's initial loading).
        """
        self._base.reset()
        self._states = [self._state(e, p) for e, p in self._inputs]
        self._filter_states = [self._state(e, p) for e, p in self._filters]
        if history_cmd_deg is None:
            return
        stateful = [e.label for e in self.model.effects_ if getattr(e, "stateful", False)]
        if stateful:
            raise ModelError(f"reset(history_cmd_deg=...) supports only static input effects such as the envelope; "
                             f"{', '.join(stateful)} keep(s) a state of its own: start from rest")
        u = np.asarray(history_cmd_deg, dtype=float)
        if u.ndim != 1 or u.size == 0 or not np.all(np.isfinite(u)):
            raise ModelError("history_cmd_deg must be a non-empty 1-D array of finite commands (deg)")
        d = HysteresisData(cmd_deg=u, t_s=np.arange(u.size, dtype=float))
        v = u
        for e, p in reversed(self._inputs):
            v = e.apply(p, v, d)
        if hasattr(self._base, "forward"):
            r, w = self._base.forward
            self._base.prime(v, r, w)
        else:
            base_p, _ = self.model._grouped(self.model.params_)
            y = self.model._base_forward(self.model.structure_, base_p, v, d.run_starts)
            self._base.prime(v, y)

    def _state(self, e, p) -> np.ndarray:
        if getattr(e, "needs_period", False):
            return e.stream_state(p, dt_s=self.dt_s)
        return e.stream_state(p)

    def step(self, desired_deg: float) -> float:
        """The knob command (deg) for the next desired bending angle (deg).

        Raises
        ------
        ModelError
            Non-finite input, or (``out_of_range="error"``) a command beyond the fitted range.
        """
        if not math.isfinite(desired_deg):
            raise ModelError(f"desired angle must be finite, got {desired_deg!r}")
        y = float(desired_deg)
        for (e, p), state in zip(self._filters, self._filter_states):
            y = e.invert_step(p, y, state)
        v = self._base.step(y)
        for (e, p), state in zip(self._inputs, self._states):
            v = e.invert_step(p, v, state)
        if v < self._lo or v > self._hi:
            msg = (f"command {v:.3f} deg for desired angle {desired_deg:.3f} deg lies outside the fitted range "
                   f"[{self._lo:.3f}, {self._hi:.3f}] deg")
            if not self._clamp:
                raise ModelError(msg + "; clamp to the fitted range with --out-of-range clamp (out_of_range='clamp' in Python)")
            warnings.warn(msg + "; clamped", OutOfRangeWarning, stacklevel=2)
            v = min(max(v, self._lo), self._hi)
        return v
