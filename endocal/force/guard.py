"""The contact-force safety guard: stop bending when the predicted tip force reaches a threshold.

Duodenoscope paper, sec. 2.4 (eq. 15, fig. 6a): every control tick the contact force is
predicted from the knob torque (:class:`~endocal.force.model.ForceModel`), and the bending
drive stops further bending once the prediction reaches the safety threshold. Here the stop
is one-sided: the goal of the guarded knob is held where the knob was when the threshold was
reached, but only against motion that would bend further into the load (the model's
``side``); a goal that backs off (relieves the force) passes and releases the hold.

Both backends call :meth:`ForceGuard.step` once per tick where ticks are stepped (the
simulator between its compiled ticks, the hardware backend in its tick loop), so it is
plain Python on floats: a table lookup, a low-pass filter and a comparison.
"""

from __future__ import annotations

import math

from endocal.errors import ModelError
from endocal.force.model import ForceModel

#: Time constant of the low-pass filter on the torque increment (s): the motor current's noise
#: (3 mA rms on the simulated XM430, about 0.02 N of predicted force) averaged over ~10 ticks at
#: 100 Hz, while a force rising at 0.5 N/s lags by under 0.01 N.
FILTER_TIME_CONSTANT_S = 0.02
#: Knob speed below which the direction of motion is kept from the last moving tick (deg/s).
STILL_DPS = 0.5


class ForceGuard:
    """Per-tick contact-force check of one knob (duodenoscope paper, eq. 15).

    Parameters
    ----------
    model : ForceModel
        Fitted contact-force model of the guarded axis.
    max_force_n : float
        Safety threshold on the predicted tip force (N), > 0.
    filter_time_constant_s : float
        Low-pass filter on the knob-torque increment before the comparison (s; 0 = none).

    Attributes
    ----------
    axis : str
        The guarded knob (the model's axis).
    force_n : float
        The force predicted at the last :meth:`step` (N); NaN while the knob backs off the
        load (the model is calibrated moving into it).
    events : list of dict
        One entry per stop and per release: ``t_s``, ``kind`` (``stop`` / ``release``),
        ``axis``, ``force_pred_n`` (None for a release while backing off), ``threshold_n``, ``knob_deg`` (``{axis: angle}``).
    """

    def __init__(self, model: ForceModel, max_force_n: float, filter_time_constant_s: float = FILTER_TIME_CONSTANT_S) -> None:
        if not isinstance(model, ForceModel):
            raise ModelError(f"a force guard needs a fitted ForceModel, got {type(model).__name__}")
        if isinstance(max_force_n, bool) or not isinstance(max_force_n, (int, float)) or not math.isfinite(max_force_n) \
                or max_force_n <= 0:
            raise ModelError(f"--max-force-n must be a force above 0 N, got {max_force_n!r}")
        self.model = model
        self.axis = model.axis
        self.max_force_n = float(max_force_n)
        self.filter_time_constant_s = float(filter_time_constant_s)
        self._side = model.side
        self._ev = model.evaluator()
        self.force_n = 0.0
        self.events: list[dict] = []
        self._dm_filt: float | None = None
        self._t_last: float | None = None
        self._loading = True
        self._hold: float | None = None

    def step(self, t_s: float, knob_deg: float, knob_dps: float, current_ma: float, goal_deg: float) -> float:
        """Check one tick; return the goal to write for the guarded knob.

        Parameters
        ----------
        t_s : float
            Time of the reading (s, run clock).
        knob_deg, knob_dps : float
            Measured knob angle (deg) and speed (deg/s).
        current_ma : float
            Measured motor current (mA).
        goal_deg : float
            The goal the protocol asks for at this tick (deg).

        Returns
        -------
        float
            ``goal_deg``, or the hold angle when the goal would bend further into the load
            while the predicted force is at or above the threshold.
        """
        if knob_dps * self._side > STILL_DPS:
            self._loading = True
        elif knob_dps * self._side < -STILL_DPS:
            self._loading = False
        if not self._loading:
            # Backing off relieves the force, and the model is calibrated moving into the load
            # only (the capstan friction reverses on the way back): nothing to predict or stop.
            self.force_n = math.nan
            self._dm_filt = None
            if self._hold is not None and (goal_deg - self._hold) * self._side <= 0.0:
                self._hold = None
                self.events.append(self._event(t_s, "release", math.nan, knob_deg))
            return goal_deg if self._hold is None else self._hold
        dm = self._ev.torque_increment_nmm(knob_deg, current_ma, self._loading)
        if self._dm_filt is None or self.filter_time_constant_s <= 0.0:
            self._dm_filt = dm
        else:
            a = min(1.0, (t_s - self._t_last) / self.filter_time_constant_s)
            self._dm_filt += a * (dm - self._dm_filt)
        self._t_last = t_s
        self.force_n = force = self._ev.force_n(knob_deg, self._dm_filt)
        hold = self._hold
        if hold is not None:
            if (goal_deg - hold) * self._side > 0.0:
                return hold
            self._hold = None
            self.events.append(self._event(t_s, "release", force, knob_deg))
            return goal_deg
        if force >= self.max_force_n and (goal_deg - knob_deg) * self._side > 0.0:
            self._hold = knob_deg
            self.events.append(self._event(t_s, "stop", force, knob_deg))
            return knob_deg
        return goal_deg

    def _event(self, t_s: float, kind: str, force: float, knob_deg: float) -> dict:
        return {"t_s": round(t_s, 4), "kind": kind, "axis": self.axis,
                "force_pred_n": None if math.isnan(force) else round(force, 4),
                "threshold_n": self.max_force_n, "knob_deg": {self.axis: round(knob_deg, 3)}}

    def describe(self) -> dict:
        """What ``run.json`` records about the guard."""
        return {"axis": self.axis, "max_force_n": self.max_force_n, "side": self._side,
                "filter_time_constant_s": self.filter_time_constant_s, "model_probe": self.model.probe,
                "model_source": self.model.source}


def check_guard_fits(model: ForceModel, probe, max_force_n: float | None) -> None:
    """Refuse a force model calibrated for another probe or an axis the probe lacks, and a bad threshold.

    Raises
    ------
    ModelError
        What is wrong and what to give instead.
    """
    if max_force_n is None:
        raise ModelError("--force-model needs --max-force-n F (the safety threshold on the predicted tip force, N)")
    if model.probe != probe.name:
        raise ModelError(f"force model {model.source or ''} was calibrated on probe '{model.probe}', not '{probe.name}': "
                         f"calibrate this probe (endocal fit force) or pass --probe {model.probe}".replace("  ", " "))
    if model.axis not in probe.bending_axes:
        raise ModelError(f"force model is for axis '{model.axis}', but probe '{probe.name}' has "
                         f"{', '.join(probe.bending_axes)}")
