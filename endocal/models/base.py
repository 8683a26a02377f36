"""The estimator every hysteresis model shares: fit, predict, inverse, print (files: :mod:`~endocal.models.io`).

A model is a *base* (the direction-dependent hysteresis: :mod:`~endocal.models.linear`,
:mod:`~endocal.models.bspline`, :mod:`~endocal.models.pi`) plus *effect terms*
(:mod:`endocal.models.effects`)::

    u = E_in(cmd)               input effects, in order (delay, rate, load, deadzone, envelope)
    y = F(base(u)) + sum E_out  output filters (creep, coupling), then additive terms (drift)

Contract (scikit-learn / lmfit style): ``__init__`` only stores its arguments;
``fit`` returns ``self`` and sets the trailing-underscore attributes (``params_``,
``stderr_``, ``correlation_``, ``fit_report_``, ``structure_`` ...); ``predict`` and
``inverse`` refuse an unfitted model.

The command is a knob's angle (deg) or a linear drive's tendon displacement (mm): the
hysteresis maths is the same in either unit, so every base and effect works on the numbers as
given. ``fit`` records the data's unit as ``drive_unit_``; the model prints its input-side
parameters in it (``slack_mm``, a play threshold ``r`` in mm) and refuses data commanded in
another unit (:meth:`HysteresisModel.check_drive_unit`). Fitting is :func:`scipy.optimize.least_squares`
(trust-region reflective with bounds) on all free parameters of the base and the
effects jointly; standard errors come from the Jacobian at the optimum.
"""

from __future__ import annotations

import contextvars
import copy
import inspect
import math
import re
import warnings
from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass, field
from typing import ClassVar

import numpy as np
from threadpoolctl import threadpool_limits

from endocal.errors import CompensationRefusedError, ModelError, OutOfRangeWarning
from endocal.messages import KEYS, Message, key_of
from endocal.models.compensator import StreamingCompensator
from endocal.models.data import HysteresisData, as_data
from endocal.models.effects import plain_form, resolve_effects
from endocal.models.effects.base import Effect, InputEffect, OutputEffect
from endocal.models.effects.base import OutputFilter
from endocal.models.lsq import Residuals, solve
from endocal.models.params import Parameter
from endocal.models.start import (FIT_HISTORY_FRACTION, HISTORIES, START_GAIN_MIN, assumed_starts, estimate_starts,
                                  first_stretch_fraction, rescored, with_lead_ins)

OUT_OF_RANGE_CHOICES = ("error", "clamp")
#: ``out_of_range`` values a model accepts: the users' choices, and ``"extrapolate"``, with which
#: :meth:`HysteresisModel.predict` continues the model's own branches beyond the fitted range (B-spline end
#: tangents, straight lines, saturated plays) as validation scores it; the inverse clamps then.
_OUT_OF_RANGE_MODES = OUT_OF_RANGE_CHOICES + ("extrapolate",)
#: :meth:`HysteresisModel.fit_from`: a warm fit whose RMSE exceeds its start model's by more than this
#: fraction stopped in a local minimum (far above FTOL's per-step change; a nested optimum is never worse)
NESTED_TOL = 1e-3
#: The same for a fit stopped early (an ``ftol`` looser than FTOL: validate's quick candidate fits). Those end
#: within 0.42 % of the RMSE a fit to FTOL reaches (validation.structure.SCAN_FTOL), so a smaller gap is their
#: stopping, not a local minimum: on three record sets (the demo's, the README's two) their warm fits ended
#: 0.16 to 0.24 % above the start model, and each from-scratch fit this then ran ended worse still (by 0.1 to
#: 0.2 %), at 15 % of the scan's time. The refit validate prints, to FTOL, starts where the candidate did.
NESTED_TOL_QUICK = 1e-2
#: :meth:`HysteresisModel._starts_by_history`: evaluations per free parameter of a history's screening fit
HISTORY_NFEV_PER_PARAMETER = 10
#: :meth:`HysteresisModel._start_cost`: evaluations per free parameter (and one more) of a start's refinement
START_NFEV_PER_PARAMETER = 8
#: :meth:`HysteresisModel._best_start`: the share of that refinement every candidate gets, and how many go on
START_SCREEN_SHARE = 0.25
START_KEEP = 2
#: samples a start candidate's or a start history's screening fit sees of a long record (:func:`_subsample`)
SUBSAMPLE_SAMPLES = 4000
#: relative cost decrease per step under which a fit stops (:func:`_solve`), unless ``fit(ftol=...)`` says otherwise
FTOL = 1e-7
#: the stopping rule of the fit running in this context (:meth:`HysteresisModel.fit`'s ``ftol``)
_FTOL_NOW: contextvars.ContextVar[float] = contextvars.ContextVar("endocal_fit_ftol", default=FTOL)


#: What drives each command unit names, for messages.
DRIVES = {"deg": "a knob or pulley turned", "mm": "a linear stage pulling the tendon"}


def in_drive_unit(text: str, unit: str) -> str:
    """Text written for a drive commanded in degrees (an input effect's parameters and their units,
    the plays' thresholds) in ``unit``: ``slack_deg=4.7 deg`` reads ``slack_mm=4.7 mm`` in mm, and
    ``amp_s_per_deg`` ``amp_s_per_mm``. Only input-side text goes through here: the bending angle
    stays in deg."""
    return text if unit == "deg" else re.sub(r"(?<![A-Za-z])deg\b", unit, text)


def parameter_label(name: str, owner, unit: str) -> str:
    """A parameter's full name as printed for a drive in ``unit``: an input effect's in the drive's unit
    (:func:`in_drive_unit`), the base's and the others' as they are (they act on the bending angle)."""
    return in_drive_unit(name, unit) if isinstance(owner, InputEffect) else name


def min_fit_samples(n_free: int) -> int:
    """The fewest samples a fit of ``n_free`` parameters accepts: two per parameter and 20 spare.

    Only what cannot be fitted with any confidence is refused; below ten per parameter the fit
    runs and its report warns.
    """
    return 2 * n_free + 20


@dataclass
class FitReport:
    """How the least-squares fit went.

    Attributes
    ----------
    success : bool
        scipy's convergence flag.
    status : int
        scipy's status code (``least_squares``: 1-4 converged, 0 max evaluations).
    message : str
        Why it stopped.
    nfev, njev : int
        Residual and Jacobian evaluations (iterations of the trust-region method).
    cost : float
        Half the sum of squared residuals (deg²).
    rmse_deg : float
        Root-mean-square residual at the optimum.
    n_samples, n_runs, n_free : int
        Samples, runs and free parameters in the fit.
    rank_deficient : bool
        The Jacobian was (numerically) singular: some parameters are not identified by
        the data, their standard errors are infinite.
    estimated_starts : list of dict
        The runs that were fitted from an estimated start (:mod:`endocal.models.start`, the
        ``RecordStart.to_dict`` of each): they began away from the state every model assumes.
    method : str
        Optimiser used.
    warnings : list of str
        Effect parameters the data does not pin down: at a bound, or with a standard error
        larger than the value (the term ran off or is not identified; the fit report prints them).
    """

    success: bool
    status: int
    message: str
    nfev: int
    njev: int
    cost: float
    rmse_deg: float
    n_samples: int
    n_runs: int
    n_free: int
    rank_deficient: bool
    method: str = "trf"
    warnings: list = field(default_factory=list)
    estimated_starts: list = field(default_factory=list)

    def to_dict(self) -> dict:
        """As a model file keeps it: ``warnings`` as text, and ``warning_keys`` the key of each
        (:class:`endocal.messages.Message`), so a warning read back keeps the key it was made with."""
        return {**asdict(self), "warning_keys": [key_of(w) for w in self.warnings]}

    @classmethod
    def from_dict(cls, d: dict) -> FitReport:
        """The inverse of :meth:`to_dict` (a file without ``warning_keys``, written before warnings carried
        keys, gives plain text: its warnings print under the key ``other``)."""
        d = dict(d)
        keys = d.pop("warning_keys", None)
        keys = keys if isinstance(keys, list) else []
        warnings = list(d.get("warnings") or [])
        d["warnings"] = [Message(w, k) if isinstance(w, str) and isinstance(k, str) and k in KEYS else w
                         for w, k in zip(warnings, keys + [None] * (len(warnings) - len(keys)))]
        return cls(**d)


class HysteresisModel(ABC):
    """Common machinery of the hysteresis models (not used directly).

    Parameters (shared by every model, after the model's own settings)
    ----------
    effects : sequence of str or Effect, optional
        Effect terms composed onto the base (``"envelope"``, ``"load:sheath_wrap_deg"``,
        or :class:`~endocal.models.effects.base.Effect` instances).
    fixed : dict of str to float, optional
        Parameters held at the given values during the fit (lmfit's ``vary=False``).
        When None, the model fixes only what is needed to make the parameters
        identifiable (e.g. the envelope's scale, see ``fixed_``).
    axis : str, optional
        Name of the bending axis (``ap``, ``ml``, ``ud``, ``lr``); printed and saved.
    out_of_range : {"error", "clamp"}
        What ``predict``/``inverse`` do with commands beyond the fitted range:
        raise ModelError, or clamp them with an :class:`OutOfRangeWarning`.
    """

    #: name in the registry and in model files
    base_name: ClassVar[str] = ""
    #: settings that are not base-specific (handled here)
    _common = ("effects", "fixed", "axis", "out_of_range")

    # ------------------------------------------------------------------ settings
    def get_settings(self) -> dict:
        """The base model's own constructor arguments (JSON-able), without the common ones."""
        sig = inspect.signature(type(self).__init__)
        return {k: getattr(self, k) for k in sig.parameters if k != "self" and k not in self._common}

    def _check_common(self) -> None:
        if self.out_of_range not in _OUT_OF_RANGE_MODES:
            raise ModelError(f"out_of_range must be one of {OUT_OF_RANGE_CHOICES}, got {self.out_of_range!r}")

    def _effects(self) -> list[Effect]:
        resolved = resolve_effects(self.effects)
        effects = [e.for_model(self, resolved) for e in resolved]
        for e in effects:
            if why := self.refuses(e):
                raise ModelError(why)
        return effects

    def refuses(self, effect: Effect) -> str:
        """Why this base cannot carry ``effect`` (``""``: it can): a form that acts on one friction state
        (``Effect.needs_friction_state``: ``rate:friction``, ``load:friction:COLUMN``, ``envelope:tip``) needs a base
        that has one (``dahl``, ``bouc-wen``)."""
        if effect.needs_friction_state and not self.friction_state:
            plain = plain_form(effect.label) or effect.name
            return (f"effect '{effect.label}' needs a base with one friction state ({effect.needs_friction_state}); the "
                    f"{self.base_name} base has none: fit --model dahl or bouc-wen, or use '{plain}'")
        return ""

    @staticmethod
    def _friction_factor(eff_p: dict[int, dict], v: np.ndarray, data: HysteresisData,
                         effects: list[Effect]) -> dict:
        """``{"factor": f}`` for the base when effects scale its friction's bound (``f`` (n,) > 0, the product of
        each one's ``friction_factor``: ``rate:friction``'s speed, ``load:friction:COLUMN``'s condition), else ``{}``.
        ``v`` is the command reaching the base, None in the inverse (where only a factor known ahead is asked for)."""
        f = None
        for e in effects:
            if hasattr(e, "friction_factor"):
                fe = np.asarray(e.friction_factor(eff_p[id(e)], v, data), dtype=float)
                f = fe if f is None else f * fe
        return {} if f is None else {"factor": f}

    def _filter_inputs(self, e: OutputFilter, eff_p: dict[int, dict], data: HysteresisData,
                       effects: list[Effect]) -> dict:
        """``{"friction": f}`` for an output filter that models another knob's friction (``other_friction``: the
        column of that knob) when effects scale the base's friction: their factor (:meth:`_friction_factor`) with
        that knob's position as the command (its speed for ``rate:friction``, the shared condition for
        ``load:friction:COLUMN``); else ``{}``. The column is logged or planned, so the inverse has it too."""
        if e.other_friction is None:
            return {}
        f = self._friction_factor(eff_p, np.ascontiguousarray(data.column(e.other_friction), dtype=float), data,
                                  effects)
        return {"friction": f["factor"]} if f else {}

    # ------------------------------------------------------------------ base hooks
    @abstractmethod
    def _resolve_structure(self, effects: list[Effect], v: np.ndarray | None, data: HysteresisData | None) -> dict:
        """Resolve "auto" settings and data-dependent structure (thresholds, knots) into a JSON-able dict.

        ``v`` is the effective input reaching the base at the start values (None when
        the structure is set without data, :meth:`set_parameters`).
        """

    @abstractmethod
    def _base_names(self, structure: dict) -> list[str]:
        """Short names of the base parameters for this structure."""

    @abstractmethod
    def _base_initial(self, structure: dict, v: np.ndarray, data: HysteresisData) -> list[Parameter]:
        """Base parameters (short names) with bounds and a start from the data (effective input ``v``)."""

    @abstractmethod
    def _base_forward(self, structure: dict, p: dict, v: np.ndarray, run_starts: np.ndarray) -> np.ndarray:
        """Base output (deg) for effective input ``v`` (n,)."""

    @abstractmethod
    def _base_inverse(self, structure: dict, p: dict, y: np.ndarray, run_starts: np.ndarray,
                      v_range: tuple[float, float]) -> np.ndarray:
        """Effective input (n,) whose base output is ``y`` (analytic or numerical)."""

    @abstractmethod
    def _base_describe(self, structure: dict, p: dict, se: dict, inner: str) -> str:
        """Equation of the base acting on the expression ``inner``, with its parameters."""

    @abstractmethod
    def _base_stepper(self, structure: dict, p: dict, v_range: tuple[float, float]):
        """An object with ``reset()`` and ``step(y) -> v`` (one-sample base inverse)."""

    def _base_forward_jac(self, structure: dict, p: dict, v: np.ndarray, run_starts: np.ndarray, M: np.ndarray):
        """Optional analytic Jacobian: ``(y, dy/dbase (n, n_base), dy/dupstream (n, q))`` or None.

        ``M`` (n, q) is the Jacobian of ``v`` w.r.t. the input effects' parameters.
        Returning None makes the fit differentiate numerically.
        """
        return None

    def _gauge(self, effects: list[Effect]) -> dict[str, float]:
        """Parameters to fix so the composition is identifiable (when the user fixes none)."""
        return {}

    inverse_kind: ClassVar[str] = "numerical"
    #: A small reversal inside the loop returns to the branch it left (a bank of plays, a backlash between
    #: two branches); the smooth friction bases (``bouc-wen``, ``dahl``) have no such memory.
    return_point_memory: ClassVar[bool] = True
    #: whether the base holds one friction state whose bound an effect may scale (``rate:friction``)
    friction_state: ClassVar[bool] = False

    # ------------------------------------------------------------------ helpers
    def _require_fitted(self) -> None:
        if not hasattr(self, "params_"):
            raise ModelError(f"this {type(self).__name__} is not fitted yet: call fit(...) or set_parameters(...) first")

    def _owners(self, effects: list[Effect], structure: dict) -> dict[str, tuple[object, str]]:
        owners: dict[str, tuple[object, str]] = {}
        for short in self._base_names(structure):
            owners[f"{self.base_name}_{short}"] = ("base", short)
        for e in effects:
            for short, full in zip(e.param_names(), e.full_names()):
                if full in owners:
                    other = owners[full][0]
                    who = "the base model" if other == "base" else f"effect '{other.label}'"
                    raise ModelError(f"parameter '{full}' is claimed by effect '{e.label}' and by {who}; "
                                     "give one of them another prefix or drop one")
                owners[full] = (e, short)
        return owners

    def _grouped(self, values: dict[str, float]) -> tuple[dict, dict[int, dict]]:
        base: dict = {}
        per_effect: dict[int, dict] = {}
        for full, v in values.items():
            owner, short = self._owner_map_[full]
            if owner == "base":
                base[short] = v
            else:
                per_effect.setdefault(id(owner), {})[short] = v
        return base, per_effect

    def _forward(self, data: HysteresisData, base_p: dict, eff_p: dict[int, dict], structure: dict,
                 effects: list[Effect]) -> np.ndarray:
        u = data.cmd_deg
        for e in effects:
            if isinstance(e, InputEffect):
                u = e.apply(eff_p[id(e)], u, data)
        y = self._base_forward(structure, base_p, u, data.run_starts, **self._friction_factor(eff_p, u, data, effects))
        for e in effects:
            if isinstance(e, OutputFilter):
                y = e.apply(eff_p[id(e)], y, data, **self._filter_inputs(e, eff_p, data, effects))
        for e in effects:
            if isinstance(e, OutputEffect):
                y = y + e.term(eff_p[id(e)], data.cmd_deg, data)
        return y

    def _forward_jac(self, data: HysteresisData, base_p: dict, eff_p: dict[int, dict], structure: dict,
                     effects: list[Effect]):
        """Output and full Jacobian ``(y, J, names)`` when every part is differentiable analytically, else None."""
        res = self._forward_jac_blocks(data, base_p, eff_p, structure, effects)
        if res is None:
            return None
        y, blocks, names = res
        return y, np.column_stack(blocks), names

    def _forward_jac_blocks(self, data: HysteresisData, base_p: dict, eff_p: dict[int, dict], structure: dict,
                            effects: list[Effect]):
        """:meth:`_forward_jac` with the Jacobian as its column blocks (base, upstream, filters, terms), unjoined."""
        inputs = [e for e in effects if isinstance(e, InputEffect)]
        filters = [e for e in effects if isinstance(e, OutputFilter)]
        outputs = [e for e in effects if isinstance(e, OutputEffect)]
        if (any(not hasattr(e, "apply_jac") for e in inputs + filters) or any(not hasattr(e, "term_jac") for e in outputs)
                or any(hasattr(e, "friction_factor") for e in effects)):
            return None
        u = data.cmd_deg
        M = np.zeros((u.size, 0))
        up_names: list[str] = []
        for e in inputs:
            u, own, prev = e.apply_jac(eff_p[id(e)], u, data, M)
            # the first input effect has no upstream columns: its own are the whole Jacobian so far
            M = np.column_stack([prev, own]) if prev.shape[1] else np.ascontiguousarray(own, dtype=float)
            up_names += e.full_names()
        res = self._base_forward_jac(structure, base_p, u, data.run_starts, M)
        if res is None:
            return None
        y, Jb, Ju = res
        names = [f"{self.base_name}_{s}" for s in self._base_names(structure)] + up_names
        blocks = [Jb, Ju]
        for e in filters:
            y, Jf, own = e.apply_jac(eff_p[id(e)], y, data, np.column_stack(blocks))
            blocks = [Jf, own]
            names += e.full_names()
        for e in outputs:
            t, Jo = e.term_jac(eff_p[id(e)], data.cmd_deg, data)
            y = y + t
            blocks.append(Jo)
            names += e.full_names()
        return y, blocks, names

    @staticmethod
    def _ordered(effects: list[Effect]) -> list[Effect]:
        inputs = sorted((e for e in effects if isinstance(e, InputEffect)), key=lambda e: e.order)
        filters = sorted((e for e in effects if isinstance(e, OutputFilter)), key=lambda e: e.order)
        outputs = [e for e in effects if isinstance(e, OutputEffect)]
        return inputs + filters + outputs

    # ------------------------------------------------------------------ fit
    def fit(self, data, meas_deg=None, *, t_s=None, extras=None, max_nfev: int | None = None,
            warm_start: dict | None = None, ftol: float | None = None):
        """Fit the base and all effect terms jointly by least squares.

        Parameters
        ----------
        data : HysteresisData, list of HysteresisData, ndarray (n,) or list of ndarray
            Knob commands (deg), or data objects carrying them. A list is several runs
            fitted together (operator states restart at each run).
        meas_deg : ndarray (n,) or list of ndarray, optional
            Measured bending angles (deg) when ``data`` is arrays.
        t_s : ndarray (n,) or list, optional
            Time stamps (s), needed by time-based effects.
        extras : dict or list of dict, optional
            Extra named columns (n,) needed by effects (``other_cmd_deg``, covariates).
        max_nfev : int, optional
            Cap on residual evaluations (default: scipy's, 100 × free parameters).
        warm_start : dict, optional
            Parameter values known to be good starts (full names, e.g. the ``params_`` of a
            model with some of these effects fitted on similar data). An effect whose
            parameters all appear starts from them and skips its start-candidate search;
            the fit itself is unchanged. ``validate`` uses it to refit many candidate
            structures that share the model's effects.
        ftol : float, optional
            Relative cost decrease per step under which the fit stops (default :data:`FTOL`).
            ``validate`` fits its candidates on a subsample with a looser one
            (``validation.structure.SCAN_FTOL``): they are compared at 10 % of the RMSE, not at 1e-7.

        Returns
        -------
        self

        Raises
        ------
        ModelError
            Invalid settings or data: NaN/inf, non-monotonic time, no measurement, too few
            samples for the free parameters, a command that never reverses (backlash
            cannot be identified), missing columns for an effect, duplicate parameters.
        """
        # The fit's linear algebra is on thin matrices (n × a few parameters): BLAS threads
        # only contend with each other there (10-20x slower on a loaded machine), so one.
        if ftol is not None and not (isinstance(ftol, (float, int)) and 0.0 < ftol < 1.0):
            raise ModelError(f"ftol must be a number between 0 and 1 (a relative cost change per step), got {ftol!r}")
        token = _FTOL_NOW.set(float(ftol)) if ftol is not None else None
        try:
            with threadpool_limits(limits=1, user_api="blas"):
                return self._fit(data, meas_deg, t_s=t_s, extras=extras, max_nfev=max_nfev, warm_start=warm_start)
        finally:
            if token is not None:
                _FTOL_NOW.reset(token)

    def fit_from(self, start: HysteresisModel, data, *, max_nfev: int | None = None, ftol: float | None = None):
        """Fit starting from ``start``, a fitted model with some of these effects (``--start-from``).

        The effects ``start`` has begin at its values (:meth:`fit`'s ``warm_start``). A ``start`` of
        another base lends its effects' values only; this base starts afresh (validate's base changes
        are fitted so, and the refit it prints for one). When this model
        holds ``start``'s effects and more, each of which can vanish, its least-squares optimum
        on ``data`` is never worse than ``start`` there: a warm fit that ends worse than ``start``
        predicts stopped in another local minimum (`pi` + `delay` + `envelope` on one sweep of a
        foreign tendon-sheath bench: 0.231 deg from the `pi` + `delay` values, which score 0.204
        themselves; 0.155 from scratch). Then the fit is run from scratch too and the better kept,
        said in the fit report.

        Parameters
        ----------
        start : HysteresisModel
            A fitted model (validate's model, when it scans candidates or other bases).
        data : HysteresisData or list of them
            What to fit, as :meth:`fit` takes it.
        max_nfev, ftol : optional
            As :meth:`fit` takes them.
        """
        start.check_drive_unit(as_data(data)[0], "the data to fit")
        self.fit(data, max_nfev=max_nfev, warm_start=self.lent_values(start), ftol=ftol)
        if start.base_name != self.base_name:  # another base: only the effects' values carried over
            return self
        if not {e.label for e in start.effects_} <= {e.label for e in self.effects_}:
            return self  # an effect dropped: this model does not nest start, and may well fit worse
        d, _ = as_data(data)
        scored = copy.copy(start)
        scored.out_of_range = "extrapolate"
        try:
            start_rmse = float(np.sqrt(np.mean((scored.predict(d) - d.meas_deg) ** 2)))
        except ModelError:  # start reads columns this data lacks: nothing to hold the fit to
            return self
        warm_rmse = self.fit_report_.rmse_deg
        if not warm_rmse > start_rmse * (1.0 + (NESTED_TOL if ftol is None or ftol <= FTOL else NESTED_TOL_QUICK)):
            return self
        warm = dict(self.__dict__)
        self.fit(data, max_nfev=max_nfev, ftol=ftol)
        if not self.fit_report_.rmse_deg < warm_rmse:
            self.__dict__.update(warm)
            return self
        self.fit_report_.warnings.insert(0, Message(
            f"from the start model's values the fit ended at {warm_rmse:.3g} deg RMSE, worse than the start model "
            f"itself ({start_rmse:.3g} deg; a local minimum): fitted from scratch "
            f"({self.fit_report_.rmse_deg:.3g} deg)", "local-minimum"))
        return self

    def lent_values(self, start: HysteresisModel) -> dict[str, float]:
        """What ``start``, a fitted model, lends this one's fit as its warm start (:meth:`fit_from`): every
        fitted value when its base is this one's, else its effects' values only (the base starts afresh)."""
        if start.base_name == self.base_name:
            return dict(start.params_)
        own = f"{start.base_name}_"
        return {k: v for k, v in start.params_.items() if not k.startswith(own)}

    def try_start(self, data, warm_start: dict[str, float], *, max_nfev: int | None = None,
                  ftol: float | None = None, margin: float = 0.0):
        """Fit this fitted model once more from ``warm_start`` (:meth:`fit`'s), and keep that fit only where it
        ends lower on ``data`` than the fit it has (by more than the share ``margin`` of its training RMSE): a
        second start, never a worse model.

        ``fit hysteresis --start-value`` (validate's refits of an effect whose start is searched) gives the values
        the scan's candidate reached: a search of the effect's start on every sample can end in a worse minimum
        than the scan's on a subsample (a tip-side slack: 0.171 deg training RMSE against 0.158,
        scripts/stress_promises.py seed 30), and those values, beside the model's, can too (the demo's slack:
        1.42 against 1.05 deg); so neither start is taken blindly.
        """
        self._require_fitted()
        first = dict(self.__dict__)
        self.fit(data, max_nfev=max_nfev, warm_start=warm_start, ftol=ftol)
        if not self.fit_report_.rmse_deg < (1.0 - margin) * first["fit_report_"].rmse_deg:
            self.__dict__.update(first)
        return self

    def _fit(self, data, meas_deg, *, t_s, extras, max_nfev, warm_start=None):
        self._check_common()
        d, _ = as_data(data, meas_deg, t_s=t_s, extras=extras)
        if d.meas_deg is None:
            raise ModelError("fitting needs the measured bending angle meas_deg (deg)")
        effects = self._ordered(self._effects())
        for e in effects:
            e.check(d)
            e.check_fit(d)
        if np.ptp(d.meas_deg) <= 1e-9 * max(1.0, float(np.max(np.abs(d.meas_deg)))):
            raise ModelError(f"the measured angle never changes ({float(d.meas_deg[0]):.6g} deg throughout): nothing to "
                             "fit; check that the tracker saw the tip sensor and that this is the axis the knob bends")
        if d.n_reversals() == 0:
            raise ModelError("backlash cannot be identified: the command never reverses; "
                             "fit on data that moves the knob back and forth (e.g. a damped sine)")

        fixed = dict(self.fixed) if self.fixed is not None else self._gauge(effects)
        for e in effects:
            # constants an effect takes from the data (a covariate's range) are held fixed
            for short, val in (e.constants(d).items() if hasattr(e, "constants") else ()):
                fixed.setdefault(f"{e.prefix}_{short}", float(val))
        # Long records: start values and the first convergence use a decimated copy
        # (every s-th sample; the knob moves little between samples, so loops keep
        # their shape); the final iterations and the covariance use every sample.
        stride = d.n_samples // 20000
        dd = d.decimate(stride) if stride >= 2 else d
        initials: dict = {}  # the output effects' start values on dd, the same for every start tried below
        # Effects whose nonlinear parameters (a delay, a time constant, a play width) need a
        # good start offer a few candidates: each is tried with the base re-started on the
        # command it produces, and the one with the lowest start cost is kept (greedy, in
        # chain order). An effect whose every free parameter the warm start gives starts there.
        overrides: dict[str, float] = {}
        warm = warm_start or {}
        for e in effects:
            known = [n for n in e.full_names() if n not in fixed]
            if known and all(n in warm for n in known):
                overrides.update({n: float(warm[n]) for n in known})
        start, structure, owners = self._start(dd, effects, fixed, overrides, initials)
        ds = _subsample(dd)
        for e in effects:
            if not hasattr(e, "start_candidates") or all(n in overrides for n in e.full_names() if n not in fixed):
                continue
            tried = []
            for cand in e.start_candidates(dd, dd.cmd_deg):
                trial = {**overrides, **{f"{e.prefix}_{k}": float(v) for k, v in cand.items()
                                         if f"{e.prefix}_{k}" not in fixed}}
                if isinstance(e, InputEffect):
                    st, stru, own = self._start(dd, effects, fixed, trial, initials)
                else:  # the base's start does not depend on a filter or an additive term
                    st, stru, own = dict(start), structure, owners
                    for k, v in trial.items():
                        if k in st and k.startswith(e.prefix + "_"):
                            st[k] = Parameter(k, v, st[k].lower, st[k].upper)
                tried.append((trial, st, stru, own))
            best = self._best_start(ds, tried, effects, fixed)
            if best is not None:
                _, overrides, start, structure, owners = best
                # the next effect's candidates start from this effect's refined values, not its raw
                # candidate: a coarse candidate (a 0.4 s delay) that refines to the right value
                # would otherwise be restarted raw and mislead every later effect's search
                overrides.update({n: float(start[n].value) for n in e.full_names() if n in overrides})

        names = list(owners)
        free = [n for n in names if n not in fixed]
        n_free = len(free)
        need = min_fit_samples(n_free)
        if d.n_samples < need:
            raise ModelError(f"too few samples to fit {n_free} parameters: got {d.n_samples}, need at least {need} "
                             "(record longer, or a model with fewer parameters: --model bspline --set n_knots=3, "
                             "--model pi --set n_operators=8, or --model linear)")

        self._owner_map_ = owners
        x0 = np.array([start[n].clipped_start() for n in free])
        lo = np.array([start[n].lower for n in free])
        hi = np.array([start[n].upper for n in free])
        values = {n: float(start[n].value) for n in names}
        fns = self._residual_fns(d, values, free, structure, effects)
        nfev = njev = 0
        if stride >= 2:
            pre = _solve(self._residual_fns(dd, values, free, structure, effects), x0, (lo, hi), max_nfev)
            x0 = np.clip(pre.x, lo, hi)
            nfev, njev = pre.nfev, int(pre.njev or 0)
        res = _solve(fns, x0, (lo, hi), max_nfev)
        # A run that starts where a longer motion left the knob is fitted from its estimated start
        # (models.start): else its stretch before the first reversal pulls the parameters.
        starts = self._estimated_starts(d, values, free, res.x, structure, effects)
        x_from = res.x
        if not starts and first_stretch_fraction(d) >= FIT_HISTORY_FRACTION:
            # a short record's first stretch may have pulled the rest fit until it predicts the
            # wrong start as well as the right one: fit from each history and estimate again
            x_from, starts, more = self._starts_by_history(d, values, free, res, structure, effects, (lo, hi),
                                                           max_nfev)
            nfev, njev = nfev + more[0], njev + more[1]
        if starts:
            nfev, njev = nfev + res.nfev, njev + int(res.njev or 0)
            led, keep = with_lead_ins(d, starts)
            res = _solve(self._residual_fns(led, values, free, structure, effects, keep), np.clip(x_from, lo, hi),
                         (lo, hi), max_nfev)
            final = {**values, **{n: float(v) for n, v in zip(free, res.x)}}
            starts = rescored(starts, d, self._forward(d, *self._grouped(final), structure, effects), res.fun)
        res.nfev += nfev
        res.njev = int(res.njev or 0) + njev
        r = res.fun
        m = r.size
        for n, v in zip(free, res.x):
            values[n] = float(v)
        dof = max(m - n_free, 1)
        s2 = float(r @ r) / dof
        J = np.atleast_2d(res.jac)
        cov, rank_def = _covariance(J, s2)
        stderr = {n: 0.0 for n in names if n in fixed}
        diag = np.diag(cov)
        for i, n in enumerate(free):
            stderr[n] = float(math.sqrt(diag[i])) if np.isfinite(diag[i]) and diag[i] >= 0 else math.inf
        with np.errstate(invalid="ignore", divide="ignore"):
            sd = np.sqrt(np.where(np.isfinite(diag) & (diag > 0), diag, np.nan))
            corr = cov / np.outer(sd, sd)

        self.effects_ = effects
        self.structure_ = structure
        self.fixed_ = {k: float(v) for k, v in fixed.items()}
        self.params_ = {n: values[n] for n in names}
        self.stderr_ = {n: stderr[n] for n in names}
        self.param_names_ = free
        self.covariance_ = cov
        self.correlation_ = corr
        self.cmd_range_deg_ = (float(d.cmd_deg.min()), float(d.cmd_deg.max()))
        self.drive_unit_ = d.cmd_unit
        self.training_data_ = d.fingerprint()
        self.fit_report_ = FitReport(
            success=bool(res.success), status=int(res.status), message=str(res.message),
            nfev=int(res.nfev), njev=int(res.njev or 0), cost=float(res.cost),
            rmse_deg=float(math.sqrt(float(r @ r) / m)), n_samples=d.n_samples, n_runs=d.n_runs,
            n_free=n_free, rank_deficient=rank_def, estimated_starts=[st.to_dict() for st in starts],
            warnings=([Message(f"{d.n_samples} samples for {n_free} free parameters (fewer than 10 per parameter): "
                               "the fit may follow the noise; check it on a record it was not fitted on (endocal "
                               "validate)", "few-samples")]
                      if d.n_samples < 10 * n_free else []) + _loose_parameters(free, owners, values, stderr, lo, hi,
                                                                                  d.cmd_unit)
                     + _no_better_than_a_line(d, float(math.sqrt(float(r @ r) / m)), self.base_name),
        )
        return self

    def _estimated_starts(self, d: HysteresisData, values: dict, free: list[str], x: np.ndarray, structure: dict,
                          effects: list[Effect]) -> list:
        """The runs of ``d`` that the model at ``x`` predicts better from a lead-in (models.start)."""
        trial = {**values, **{n: float(v) for n, v in zip(free, x)}}
        return estimate_starts(lambda dd: self._forward(dd, *self._grouped(trial), structure, effects), d)[1]

    def _starts_by_history(self, d: HysteresisData, values: dict, free: list[str], rest, structure: dict,
                           effects: list[Effect], bounds: tuple, max_nfev) -> tuple[np.ndarray, list, tuple]:
        """The rest fit ``rest`` refitted with every run started along each history
        (models.start.assumed_starts); the best that lowers the RMSE by START_GAIN_MIN, and the
        starts estimated from it (an empty list: keep the rest fit). Also (nfev, njev) spent.

        Each history fit screens (the fit from the starts it finds polishes the winner), so it is
        capped at HISTORY_NFEV_PER_PARAMETER evaluations per free parameter: a history that fits
        reaches its minimum in 4-63 evaluations (tests/test_models_start.py), while one that does
        not fit can crawl (B-spline + delay + deadzone on one 20 000-sample sweep: 2 500
        evaluations, 90 s, to end twice the rest fit's cost).
        """
        cap = HISTORY_NFEV_PER_PARAMETER * (len(free) + 1)
        max_nfev = min(max_nfev, cap) if max_nfev else cap
        # a long record is screened on a subsample (as start candidates are), against the rest
        # fit's cost there; the starts are then estimated on every sample
        ds, rest_cost = _subsample(d), rest.cost
        if ds is not d:
            at_rest = {**values, **{n: float(v) for n, v in zip(free, rest.x)}}
            r = self._forward(ds, *self._grouped(at_rest), structure, effects) - ds.meas_deg
            rest_cost = 0.5 * float(r @ r)
        best, spent = None, [0, 0]
        for history in HISTORIES:
            trial = assumed_starts(ds, history)
            if not trial:
                continue
            led, keep = with_lead_ins(ds, trial)
            fit = _solve(self._residual_fns(led, values, free, structure, effects, keep), np.clip(rest.x, *bounds),
                         bounds, max_nfev)
            spent = [spent[0] + fit.nfev, spent[1] + int(fit.njev or 0)]
            if fit.cost < (1.0 - START_GAIN_MIN) ** 2 * rest_cost and (best is None or fit.cost < best.cost):
                best = fit
        if best is None:
            return rest.x, [], tuple(spent)
        return best.x, self._estimated_starts(d, values, free, best.x, structure, effects), tuple(spent)

    def _residual_fns(self, data: HysteresisData, values: dict, free: list[str], structure: dict,
                      effects: list[Effect], keep: np.ndarray | None = None):
        """The fit's residual (deg) over the ``free`` parameters and its Jacobian (analytic, else "2-point"), as
        :class:`Residuals`.

        Each writes the trial values into ``values`` (shared with the caller, which reads the
        solution back from it). With ``keep``, ``data`` carries lead-ins (models.start) and only
        the samples at ``keep`` are residuals.
        """
        rows = slice(None) if keep is None else keep
        meas = data.meas_deg[rows]

        def residual(x):
            for n, v in zip(free, x):
                values[n] = float(v)
            base_p, eff_p = self._grouped(values)
            return self._forward(data, base_p, eff_p, structure, effects)[rows] - meas

        analytic = self._forward_jac_blocks(data, *self._grouped(values), structure, effects)
        if analytic is None:
            return Residuals(residual, "2-point")
        # where each free parameter's column sits: (block, column in it, column of the fit's Jacobian); the
        # Jacobian is assembled from the blocks directly (joining them first, then picking the free columns,
        # copied every column twice: several per cent of a scan candidate's time)
        where = [(b, c) for b, block in enumerate(analytic[1]) for c in range(_columns(block).shape[1])]
        col = {n: where[i] for i, n in enumerate(analytic[2])}
        picks: dict[int, tuple[list[int], list[int]]] = {}
        for k, n in enumerate(free):
            b, c = col[n]
            picks.setdefault(b, ([], []))[0].append(c)
            picks[b][1].append(k)
        n_rows = meas.size

        def both(x):
            for n, v in zip(free, x):
                values[n] = float(v)
            base_p, eff_p = self._grouped(values)
            y, blocks, _ = self._forward_jac_blocks(data, base_p, eff_p, structure, effects)
            # Fortran order, LAPACK's: the compression's triangular solve (models.lsq) works on it without a copy
            J = np.empty((n_rows, len(free)), order="F")
            for b, (src, dst) in picks.items():
                block = _columns(blocks[b])
                J[:, dst] = (block if keep is None else block[keep])[:, src]
            return y[rows] - meas, J

        return Residuals(residual, lambda x: both(x)[1], both)

    def _start(self, dd: HysteresisData, effects: list[Effect], fixed: dict, overrides: dict,
               initials: dict | None = None):
        """Start values (input effects in chain order, each seeing the command the chain gives it), structure, owners.

        ``initials`` keeps the output effects' start values between calls on the same ``dd``
        (they see the raw command, not the chain's): an envelope's hinge search is done once per fit.
        """
        initials = {} if initials is None else initials
        start: dict[str, Parameter] = {}
        u = dd.cmd_deg
        unmeasured = None
        for e in effects:
            if isinstance(e, InputEffect):
                # an effect whose every free parameter is given needs only its bounds: it sees the data
                # without the measured angle, so it skips its start search (an envelope's hinge grid,
                # a fifth of a warm-started scan candidate's time); an effect's bounds never depend on it
                given = all(n in overrides for n in e.full_names() if n not in fixed)
                if given and unmeasured is None:
                    unmeasured = dd.with_cmd(dd.cmd_deg)
                for prm in e.initial(unmeasured if given else dd, u):
                    start[prm.name] = prm
                e.adapt_start(start, fixed)
                self._apply_fixed(start, fixed, e)
                for full in e.full_names():
                    if full in overrides:
                        start[full].value = overrides[full]
                u = e.apply({s: start[f].value for s, f in zip(e.param_names(), e.full_names())}, u, dd)
        structure = self._resolve_structure(effects, u, dd)
        owners = self._owners(effects, structure)
        for prm in self._base_initial(structure, u, dd):
            start[f"{self.base_name}_{prm.name}"] = Parameter(f"{self.base_name}_{prm.name}", prm.value, prm.lower, prm.upper)
        for e in effects:
            if not isinstance(e, InputEffect):
                if id(e) not in initials:
                    initials[id(e)] = e.initial(dd, dd.cmd_deg)
                for prm in initials[id(e)]:
                    start[prm.name] = copy.copy(prm)
                e.adapt_start(start, fixed)
                for full in e.full_names():
                    if full in overrides:
                        start[full].value = overrides[full]
        unknown = set(fixed) - set(owners)
        if unknown:
            raise ModelError(f"fixed names unknown parameter(s) {sorted(unknown)}; this model has {sorted(owners)}")
        for name, val in fixed.items():
            start[name].value = float(val)
        return start, structure, owners

    def _best_start(self, ds: HysteresisData, tried: list[tuple], effects: list[Effect], fixed: dict):
        """The start candidate that leads lowest, as ``(cost, trial, refined start, structure, owners)``; None if none.

        Successive halving (Jamieson & Talwalkar, AISTATS 2016): every candidate is refined with
        START_SCREEN_SHARE of :meth:`_start_cost`'s evaluations, the START_KEEP lowest go on with the
        rest, and the lowest after that wins. A start that leads nowhere shows it early: in the five
        searches of ``validate`` on the demo's records (3 to 7 candidates each) the start kept ended within
        0.25 % of the cost of the best of all candidates refined in full, with 10 to 60 % fewer evaluations
        (where several candidates lead into one basin, it may be another of them than the full search's).
        """
        if len(tried) <= START_KEEP:
            kept = [(*self._start_cost(ds, st, stru, own, effects, fixed), trial, stru, own)
                    for trial, st, stru, own in tried]
        else:
            screened = [(*self._start_cost(ds, st, stru, own, effects, fixed, START_SCREEN_SHARE), trial, stru, own)
                        for trial, st, stru, own in tried]
            order = sorted(range(len(screened)), key=lambda i: (screened[i][0], i))[:START_KEEP]
            kept = [(*self._start_cost(ds, screened[i][1], screened[i][3], screened[i][4], effects, fixed,
                                       1.0 - START_SCREEN_SHARE), screened[i][2], screened[i][3], screened[i][4])
                    for i in sorted(order)]
        best = None
        for cost, st, trial, stru, own in kept:
            if best is None or cost < best[0]:
                best = (cost, trial, st, stru, own)
        return best

    def _start_cost(self, ds: HysteresisData, start: dict, structure: dict, owners: dict, effects: list[Effect],
                    fixed: dict, share: float = 1.0) -> tuple[float, dict]:
        """Cost (deg²) of a start after a few iterations on a small subsample, and the refined start.

        The raw start cost ranks candidates poorly (the base's start is only a linear
        approximation); a short refinement of all parameters together tells which
        candidate leads somewhere. ``share``: the part of the refinement's evaluations to spend
        (:meth:`_best_start` screens with a quarter, then goes on with the rest).
        """
        self._owner_map_ = owners
        free = [n for n in owners if n not in fixed]
        values = {n: float(start[n].value) for n in owners}
        x0 = np.array([start[n].clipped_start() for n in free])
        lo = np.array([start[n].lower for n in free])
        hi = np.array([start[n].upper for n in free])

        fns = self._residual_fns(ds, values, free, structure, effects)
        try:
            res = _solve(fns, x0, (lo, hi), max(1, round(share * START_NFEV_PER_PARAMETER * (1 + len(free)))))
        except (ValueError, FloatingPointError):
            return math.inf, start
        refined = dict(start)
        for n, v in zip(free, res.x):
            refined[n] = Parameter(n, float(v), start[n].lower, start[n].upper)
        cost = 2.0 * float(res.cost)
        return (cost if math.isfinite(cost) else math.inf), refined

    @staticmethod
    def _apply_fixed(start: dict, fixed: dict, e: Effect) -> None:
        for full in e.full_names():
            if full in fixed:
                start[full].value = float(fixed[full])

    # ------------------------------------------------------------------ known parameters
    def set_parameters(self, values: dict[str, float], *, cmd_range_deg: tuple[float, float] | None = None,
                       structure: dict | None = None, drive_unit: str = "deg"):
        """Use known parameter values instead of fitting (e.g. a paper's table).

        Parameters
        ----------
        values : dict of str to float
            Every parameter of the model by full name (see :meth:`parameter_names`).
        cmd_range_deg : (float, float), optional
            Valid command range (in ``drive_unit``); unlimited when None.
        structure : dict, optional
            Data-dependent structure (thresholds, knots) for models that need it.
        drive_unit : {"deg", "mm"}
            The unit of the command the values are for (a knob's deg, a linear drive's mm).

        Returns
        -------
        self
        """
        self._check_common()
        effects = self._ordered(self._effects())
        st = self._resolve_structure(effects, None, None)
        if structure:
            st.update(structure)
        owners = self._owners(effects, st)
        missing = sorted(set(owners) - set(values))
        extra = sorted(set(values) - set(owners))
        if missing or extra:
            raise ModelError(f"set_parameters: missing {missing}, unknown {extra}; this model has {list(owners)}")
        self._owner_map_ = owners
        self.effects_ = effects
        self.structure_ = st
        self.fixed_ = {}
        self.params_ = {n: float(values[n]) for n in owners}
        self.stderr_ = {n: math.nan for n in owners}
        self.param_names_ = []
        self.covariance_ = np.zeros((0, 0))
        self.correlation_ = np.zeros((0, 0))
        self.cmd_range_deg_ = (-math.inf, math.inf) if cmd_range_deg is None else tuple(map(float, cmd_range_deg))
        self.drive_unit_ = str(drive_unit)
        self.training_data_ = []
        self.fit_report_ = None
        return self

    def parameter_labels(self) -> dict[str, str]:
        """Each parameter's full name as printed: an input effect's in the drive's unit
        (``deadzone_slack_deg`` reads ``deadzone_slack_mm`` for a linear drive; :func:`in_drive_unit`)."""
        self._require_fitted()
        return {n: parameter_label(n, owner, self.drive_unit_) for n, (owner, _) in self._owner_map_.items()}

    def parameter_names(self) -> list[str]:
        """Full names of all parameters (base first, then effects); needs a fitted model or no data-dependent structure."""
        effects = self._ordered(self._effects())
        st = self.structure_ if hasattr(self, "structure_") else self._resolve_structure(effects, None, None)
        return list(self._owners(effects, st))

    # ------------------------------------------------------------------ predict / inverse
    def check_drive_unit(self, data, what: str = "these data") -> None:
        """Refuse data commanded in another unit than this model was fitted in.

        Parameters
        ----------
        data : HysteresisData or str or None
            The data (its ``drive_unit``), or a unit; None (arrays given directly) states none.
        what : str
            The data in the message (``"run/ (validation data)"``).

        Raises
        ------
        ModelError
            One line naming both units and what to do.
        """
        self._require_fitted()
        unit = data.drive_unit if isinstance(data, HysteresisData) else data
        if unit is None or unit == self.drive_unit_:
            return
        axis = f"{self.axis} " if self.axis else ""
        raise ModelError(f"the {axis}model was fitted on a drive commanded in {self.drive_unit_} "
                         f"({DRIVES.get(self.drive_unit_, self.drive_unit_)}), but {what} command it in {unit} "
                         f"({DRIVES.get(unit, unit)}): a model holds only for the drive it was fitted on; give records "
                         f"in {self.drive_unit_}, or fit a model on these")

    def _range_check(self, cmd: np.ndarray, what: str) -> np.ndarray:
        lo, hi = self.cmd_range_deg_
        tol = 1e-9 * max(1.0, abs(lo) if math.isfinite(lo) else 1.0, abs(hi) if math.isfinite(hi) else 1.0)
        bad = (cmd < lo - tol) | (cmd > hi + tol)
        if not bad.any():
            return cmd
        k = int(np.flatnonzero(bad)[0])
        u = self.drive_unit_
        msg = (f"{what} {cmd[k]:.3f} {u} at sample {k} lies outside the fitted command range "
               f"[{lo:.3f}, {hi:.3f}] {u} ({int(bad.sum())} samples)")
        if self.out_of_range == "error":
            raise ModelError(msg + "; refit on wider data, reduce the amplitude, or clamp to the fitted range "
                             "(--out-of-range clamp; out_of_range='clamp' in Python)")
        warnings.warn(msg + "; clamped", OutOfRangeWarning, stacklevel=3)
        return np.clip(cmd, lo, hi)

    def predict(self, data, *, t_s=None, extras=None):
        """Bending angle (deg) predicted from knob commands.

        Parameters
        ----------
        data : ndarray (n,), list of ndarray, HysteresisData or list of them
            Knob commands (deg, or mm for a model of a linear drive: ``drive_unit_``); a list is
            several runs (states restart per run).
        t_s, extras : optional
            Time stamps (s) and extra columns when effects need them.

        Returns
        -------
        ndarray (n,), or a list of arrays when runs were given as a list.

        Raises
        ------
        ModelError
            Unfitted model, bad input, data whose ``drive_unit`` is not the model's, or (with
            ``out_of_range="error"``) commands beyond the fitted range.
        """
        self._require_fitted()
        self._check_common()
        d, was_list = as_data(data, t_s=t_s, extras=extras)
        self.check_drive_unit(d)
        for e in self.effects_:
            e.check(d)
        cmd = d.cmd_deg if self.out_of_range == "extrapolate" else self._range_check(d.cmd_deg, "command")
        if cmd is not d.cmd_deg:
            d = d.with_cmd(cmd)
        base_p, eff_p = self._grouped(self.params_)
        y = self._forward(d, base_p, eff_p, self.structure_, self.effects_)
        return d.split(y) if was_list else y

    def _v_range(self) -> tuple[float, float]:
        """Range of the effective base input over the fitted command range (for numerical inverses)."""
        lo, hi = self.cmd_range_deg_
        if not (math.isfinite(lo) and math.isfinite(hi)):
            return (-1e6, 1e6)
        span = hi - lo
        grid = np.linspace(lo - span, hi + span, 64)
        base_p, eff_p = self._grouped(self.params_)
        v = grid
        probe = HysteresisData(cmd_deg=grid, t_s=np.arange(grid.size, dtype=float))
        for e in self.effects_:
            if isinstance(e, InputEffect) and e.position_map:  # a static map of the position: its image
                v = e.apply(eff_p[id(e)], v, probe)
        return (float(v.min()), float(v.max()))

    def check_effects_invert(self) -> None:
        """Refuse compensation in one line when an effect has no inverse (``Effect.has_inverse``), naming why.

        Raises
        ------
        CompensationRefusedError
        """
        for e in self.effects_:
            if not e.has_inverse:
                why = e.no_inverse or "nothing undoes its equation"
                raise CompensationRefusedError(f"effect '{e.label}' has no inverse: {why}; compensation refused "
                                               "(refit without it to compensate)")

    def inverse(self, desired_deg, *, t_s=None, extras=None, max_iter: int = 50, tol_deg: float = 1e-10):
        """Knob commands (deg) that make the model output follow ``desired_deg`` (feedforward compensation).

        The base inverse is analytic for ``pi`` (duodenoscope paper, eqs. 9-11) and
        numerical (sample-by-sample bisection) for ``linear`` and ``bspline``; output
        filters (``creep``) and input effects are undone in reverse order, each exactly
        (``delay`` advances the trajectory in time: exact for whole-sample delays, within
        the linear-interpolation error otherwise); output terms that depend on the
        command are handled by fixed-point iteration.

        Parameters
        ----------
        desired_deg : ndarray (n,) or list of ndarray
            Desired bending angle (deg); a list is several runs.
        t_s, extras : optional
            Time stamps (s) and extra columns when effects need them.
        max_iter : int
            Fixed-point iterations for command-dependent output terms.
        tol_deg : float
            Convergence tolerance of that iteration (deg).

        Returns
        -------
        ndarray (n,) of commands (deg, or mm for a model of a linear drive: ``drive_unit_``), or a
        list per run.

        Raises
        ------
        ModelError
            Unfitted model, bad input, or (``out_of_range="error"``) a desired angle that
            needs a command outside the fitted range.
        """
        self._require_fitted()
        self._check_common()
        self.check_effects_invert()
        d, was_list = as_data(desired_deg, t_s=t_s, extras=extras)
        for e in self.effects_:
            e.check(d)
        y_des = d.cmd_deg
        base_p, eff_p = self._grouped(self.params_)
        outputs = [e for e in self.effects_ if isinstance(e, OutputEffect)]
        filters = [e for e in self.effects_ if isinstance(e, OutputFilter)]
        inputs = [e for e in self.effects_ if isinstance(e, InputEffect)]
        v_range = self._v_range()
        terms = np.zeros_like(y_des)
        iterate = any(e.depends_on_command for e in outputs)
        for e in outputs:
            if not e.depends_on_command:
                terms = terms + e.term(eff_p[id(e)], y_des, d)
        fixed_terms = terms.copy()
        u = y_des
        for _ in range(max_iter if iterate else 1):
            y_base = y_des - terms
            for e in reversed(filters):
                y_base = e.invert(eff_p[id(e)], y_base, d, **self._filter_inputs(e, eff_p, d, self.effects_))
            # a friction bound scaled by a logged condition is known ahead (an effect whose factor follows the
            # command has no inverse: check_effects_invert refused it above)
            v = self._base_inverse(self.structure_, base_p, y_base, d.run_starts, v_range,
                                   **self._friction_factor(eff_p, None, d, self.effects_))
            u = v
            for e in reversed(inputs):
                u = e.invert(eff_p[id(e)], u, d)
            if not iterate:
                break
            new = fixed_terms.copy()
            for e in outputs:
                if e.depends_on_command:
                    new = new + e.term(eff_p[id(e)], u, d)
            change = float(np.max(np.abs(new - terms))) if new.size else 0.0
            terms = new
            if change <= tol_deg:
                break
        u = self._range_check(np.asarray(u, dtype=float), "command needed for the desired angle")
        return d.split(u) if was_list else u

    # ------------------------------------------------------------------ streaming
    def compensator(self, dt_s: float | None = None) -> StreamingCompensator:
        """A streaming compensator for a control loop: ``step(desired_deg) -> cmd_deg``.

        Parameters
        ----------
        dt_s : float, optional
            The loop's fixed sample period (s); needed by time-based effects that stream
            (``rate``, ``creep``).

        See :class:`endocal.models.compensator.StreamingCompensator` (which reads the model
        through its attributes only, so it does not import this module).
        """
        return StreamingCompensator(self, dt_s=dt_s)

    # ------------------------------------------------------------------ printing
    def effect_params(self, effect) -> dict[str, float]:
        """The fitted values of one of ``effects_``, by the effect's own (unprefixed) names."""
        self._require_fitted()
        return self._grouped(self.params_)[1].get(id(effect), {})

    def equation(self) -> str:
        """The fitted model as an equation with values and standard errors; zero terms dropped."""
        self._require_fitted()
        base_p, eff_p = self._grouped(self.params_)
        base_se, eff_se = self._grouped(self.stderr_)
        inner = "cmd"
        defs = []
        for e in self.effects_:
            if isinstance(e, InputEffect) and not e.is_zero(eff_p[id(e)]):
                inner = e.wrap(inner)
                # an input effect acts on the command: its parameters are in the drive's unit
                defs.append(in_drive_unit(e.describe(eff_p[id(e)], eff_se.get(id(e), {})), self.drive_unit_))
        out = self._base_describe(self.structure_, base_p, base_se, inner)
        for e in self.effects_:
            if isinstance(e, OutputFilter) and not e.is_zero(eff_p[id(e)]):
                out = e.wrap(out) + " " + e.describe(eff_p[id(e)], eff_se.get(id(e), {}))
        for e in self.effects_:
            if isinstance(e, OutputEffect) and not e.is_zero(eff_p[id(e)]):
                out += " + " + e.describe(eff_p[id(e)], eff_se.get(id(e), {}))
        lhs = f"{self.axis}_deg" if self.axis else "angle_deg"
        return f"{lhs} = {out}" + "".join(f"; {s}" for s in defs)

    def _settings_repr(self) -> str:
        parts = [f"{k}={v!r}" for k, v in self.get_settings().items()]
        if self.effects:
            parts.append(f"effects={[e if isinstance(e, str) else e.label for e in self.effects]!r}")
        if self.fixed is not None:
            parts.append(f"fixed={self.fixed!r}")
        if self.axis is not None:
            parts.append(f"axis={self.axis!r}")
        if self.out_of_range != "error":
            parts.append(f"out_of_range={self.out_of_range!r}")
        return f"{type(self).__name__}({', '.join(parts)})"

    def __repr__(self) -> str:
        if hasattr(self, "params_"):
            return self.equation() + f"  (inverse: {self.inverse_kind})"
        return self._settings_repr() + f"  (unfitted; inverse: {self.inverse_kind})"

    __str__ = __repr__


def _solve(fns: Residuals, x0: np.ndarray, bounds: tuple, max_nfev: int | None):
    """:func:`scipy.optimize.least_squares`, trust-region reflective within ``bounds``, as every fit here runs it.

    With analytic derivatives it runs on the problem's compressed form (:func:`endocal.models.lsq.solve`: the
    same steps, without the SVD of the n x p Jacobian at every iteration).

    It stops when a step lowers the cost by less than FTOL of itself, or the ``ftol`` the running
    :meth:`HysteresisModel.fit` was given (scipy's default is 1e-8):
    an RMSE change below 5e-8 relative per step, far under anything endocal decides on (a 5 %
    start gain, a 10 % candidate gain). At 1e-8 a parameter the data barely holds made fits crawl
    to their evaluation cap (a B-spline `coupling` candidate on the thesis's sine-set: 2 600
    evaluations, 15 s, to an RMSE 3e-5 lower than it reached in 11).
    """
    return solve(fns, x0, bounds=bounds, ftol=_FTOL_NOW.get(), max_nfev=max_nfev)


def _columns(block: np.ndarray) -> np.ndarray:
    """A Jacobian block as :func:`numpy.column_stack` reads it: a 1-D array is one column."""
    return block[:, None] if np.ndim(block) == 1 else block


def _subsample(d: HysteresisData) -> HysteresisData:
    """Every k-th sample of a record over 2 x SUBSAMPLE_SAMPLES long, about SUBSAMPLE_SAMPLES of them
    (the knob moves little between samples, so the loops keep their shape); else ``d``."""
    return d.decimate(d.n_samples // SUBSAMPLE_SAMPLES) if d.n_samples >= 2 * SUBSAMPLE_SAMPLES else d


def _no_better_than_a_line(d: HysteresisData, rmse_deg: float, base: str) -> list[str]:
    """A warning when the fit is within 5 % of the least-squares straight line ``meas = a*cmd + b``.

    Such a model has found no hysteresis it can shape: a loop the base cannot draw (a `pi`
    branch stiffens away from each reversal, so it cannot follow a loop that flattens towards
    its ends, as saturating friction draws one), or a record without a loop.
    """
    A = np.column_stack([d.cmd_deg, np.ones(d.n_samples)])
    coef, *_ = np.linalg.lstsq(A, d.meas_deg, rcond=None)
    line = float(np.sqrt(np.mean((A @ coef - d.meas_deg) ** 2)))
    if not (line > 0 and rmse_deg >= 0.95 * line):
        return []
    return [Message(f"the fit ({rmse_deg:.3g} deg RMSE) is no better than a straight line through the data "
                    f"({line:.3g} deg): the {base} model found no loop it can shape; look at the loop (endocal report) "
                    "and try another base (--model bspline or linear)", "line-fit")]


def _loose_parameters(free: list[str], owners: dict, values: dict, stderr: dict, lo: np.ndarray,
                      hi: np.ndarray, drive_unit: str = "deg") -> list[str]:
    """Warnings for effect parameters the data does not pin down (at a bound, or standard error > |value|).

    The base's shape coefficients (B-spline increments, PI weights) sit at their zero bound
    by design and are not reported. An effect whose ``why_loose`` explains its loose values
    (a parametrisation, not missing data) gets that one line instead of a line per parameter.
    An input effect's lines are in the ``drive_unit`` (:func:`in_drive_unit`).
    """
    out = []
    explained: set[str] = set()
    for e in {id(o): o for o, _ in owners.values() if isinstance(o, Effect)}.values():
        if hasattr(e, "why_loose"):
            p = {short: values[full] for full, (o, short) in owners.items() if o is e}
            why = e.why_loose(p, {short: stderr[full] for full, (o, short) in owners.items() if o is e})
            if why:
                out.append(Message(in_drive_unit(why, drive_unit) if isinstance(e, InputEffect) else why,
                                   getattr(why, "key", "dead-band")))
                explained.update(full for full, (o, _) in owners.items() if o is e)
    for i, n in enumerate(free):
        if owners[n][0] == "base" or n in explained:
            continue
        v, se = values[n], stderr[n]
        name = in_drive_unit(n, drive_unit) if isinstance(owners[n][0], InputEffect) else n
        span = hi[i] - lo[i] if math.isfinite(hi[i] - lo[i]) else max(abs(v), 1.0)
        for bound, word in ((lo[i], "lower"), (hi[i], "upper")):
            if math.isfinite(bound) and abs(v - bound) <= 1e-4 * span:
                out.append(Message(f"{name} = {v:.4g} sits at its {word} bound {bound:.4g}: the data does not "
                                   "constrain it (the term may be absent from this data, or compensate for something "
                                   "else)", "at-bound"))
                break
        else:
            if not math.isfinite(se) or se > abs(v):
                out.append(Message(f"{name} = {v:.4g} +- {se:.2g}: its standard error exceeds its value, the data "
                                   "does not identify it (record motion that exercises the term, or drop it)",
                                   "unidentified"))
    return out


def _covariance(J: np.ndarray, s2: float) -> tuple[np.ndarray, bool]:
    """Parameter covariance ``s² (JᵀJ)⁻¹`` via SVD; unidentified directions get infinite variance."""
    p = J.shape[1]
    if p == 0:
        return np.zeros((0, 0)), False
    _, sv, vt = np.linalg.svd(J, full_matrices=False)
    thresh = np.finfo(float).eps * max(J.shape) * (sv[0] if sv.size else 0.0)
    good = sv > thresh
    inv = np.where(good, 1.0 / np.where(good, sv, 1.0) ** 2, 0.0)
    cov = (vt.T * inv) @ vt * s2
    rank_def = not bool(good.all())
    if rank_def:
        # parameters touched by a null direction are not identified
        null = vt[~good]
        touched = np.any(np.abs(null) > 1e-8, axis=0)
        cov[touched, :] = np.inf
        cov[:, touched] = np.inf
    return cov, rank_def
