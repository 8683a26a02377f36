"""The effect-term contract: what every composable physical effect provides.

A hysteresis model is a base (``linear``, ``bspline``, ``pi``) plus effect terms::

    u   = cmd                      knob command (deg)
    u   = E_in_k(... E_in_1(u))    input effects, in ascending ``order`` (delay, rate, deadzone, envelope)
    y   = base(u)                  direction-dependent hysteresis of the base model
    y  += sum_j E_out_j(cmd, data) output effects (drift, coupling, creep, load, ...)

An :class:`InputEffect` transforms the command sequence and knows its inverse; an
:class:`OutputEffect` adds a term in degrees of bending. Each effect owns its
parameters (named ``<prefix>_<short>``), their bounds and a starting guess from the
data, and may need more than the command: ``t_s``, the other axis, extra columns.
Adding an effect never changes a base model.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np

from endocal.errors import ModelError
from endocal.models.data import HysteresisData
from endocal.models.params import Parameter, fmt_value


#: The placeholder of a column in a column effect's other forms (``Effect.variants``: ``load:friction:COLUMN``).
COLUMN = "COLUMN"


def from_form(name: str, settings: dict, forms: dict, plain: str) -> Effect:
    """The effect a model file's entry describes, for an effect of several forms: ``settings["form"]`` (``plain``
    when absent, as files written before the forms are) picks its class in ``forms``; the rest are its arguments.
    A refusal names the effect, as every effect's own does; the model-file reader puts the file in front."""
    settings = dict(settings)
    form = settings.pop("form", plain)
    if form not in forms:
        named = [f"'{f}'" for f in forms if f] + (["none"] if "" in forms else [])
        raise ModelError(f"effect '{name}': unknown form '{form}' (its forms: {', '.join(named)})")
    return forms[form](**settings)


class Effect(ABC):
    """Base of all effect terms.

    Class attributes describe the effect for users (``endocal effects``):
    ``name`` (catalog name), ``cause`` (physical cause), ``signature`` (what it leaves
    in residuals), ``protocol`` (which excitation reveals it).
    """

    name: ClassVar[str] = ""
    kind: ClassVar[str] = ""
    cause: ClassVar[str] = ""
    signature: ClassVar[str] = ""
    #: the experiment that reveals it, in words (what ``--next`` prints when :meth:`segment` has none)
    protocol: ClassVar[str] = ""
    #: short parameter names (without prefix) and their units for printing
    units: ClassVar[dict[str, str]] = {}
    #: True when the effect can be compensated one sample at a time (streaming loop)
    streamable: ClassVar[bool] = False
    #: how ``--effects`` writes it (``load:COLUMN``); a subclass that leaves it out gets its ``name``
    usage: ClassVar[str] = ""
    #: what the data must carry besides command and measurement, in words (``t_s``, a column)
    needs: ClassVar[tuple[str, ...]] = ()
    #: whether :meth:`invert` undoes it (feedforward compensation); False: the inverse refuses it
    has_inverse: ClassVar[bool] = True
    #: with ``has_inverse = False``: why, in words (``model.inverse`` and the compensator refuse in one line with it)
    no_inverse: ClassVar[str] = ""
    #: what the records must hold to fit it (``to="fit"``) and to test it (``to="test"``):
    #: :class:`~endocal.models.effects.requirements.Requirement` (ready-made ones in that module)
    requires: ClassVar[tuple] = ()
    #: what in the residual points at it: signal names of the residual's cross-correlation
    #: (``"other command"``, ``"time"``, ``"speed"``, ``"abs speed"``), regimes whose error stands
    #: out (``"regime:other axis"``, ``"regime:hold"``), or callables ``f(resid, regimes) -> list[str]``
    #: returning evidence in words (empty: nothing points)
    residual: ClassVar[tuple] = ()
    #: other effect name -> the records that separate the two, in words
    lookalikes: ClassVar[dict[str, str]] = {}
    #: short names of parameters whose bounds are open on purpose (a drift rate, a position);
    #: every other parameter has at least one finite bound
    open_bounds: ClassVar[tuple[str, ...]] = ()
    #: the simulator's config section that produces it (``None``: the simulator has no such physics;
    #: a user effect gives a :meth:`simulate` method instead)
    sim_section: ClassVar[str | None] = None
    #: an input effect that is a static, monotone map of the knob position (the base's input range
    #: is its image of the command range: the numerical inverse searches there)
    position_map: ClassVar[bool] = False
    #: ``(status, why)`` when ``--next`` considers it whatever ``validate`` said (its segment then decides
    #: whether the records at stake can tell it from a look-alike); None: only when something points at it
    at_stake: ClassVar[tuple[str, str] | None] = None
    #: ``--next`` plans segments in ascending ``segment_order`` (those that reuse the others'
    #: motions, e.g. the full amplitude or a condition for the whole run, come last)
    segment_order: ClassVar[int] = 50
    #: the values of its own parameters (short names) at which an additive term adds nothing (``drift``: no
    #: rate). ``validate`` then checks that a candidate earns its gain through its own term, not through the
    #: parameters refitted beside it. Empty: not checked. Only an additive term can be taken out so: an input
    #: effect or an output filter reshapes what the base's parameters were fitted to (``creep``'s share of a
    #: slow relaxation scales the output, and the base's gain is fitted with it).
    null: ClassVar[dict[str, float]] = {}
    #: other forms of the effect that ``validate`` tries as candidates of their own, as ``--effects`` writes
    #: them (``deadzone:tip``: the slack on the other side of the friction); each must parse to an effect
    #: of this name. A column effect writes its column as :data:`COLUMN` (``load:friction:COLUMN``), and the scan
    #: tries the form for each column it tries the plain effect on
    variants: ClassVar[tuple[str, ...]] = ()
    #: why the effect needs a base with one friction state (``HysteresisModel.friction_state``: ``dahl``, ``bouc-wen``),
    #: in words; "" for an effect any base carries. A base without one refuses it in one line, and ``validate`` tries
    #: such a form in place of the plain term a model changed to a friction base carries
    needs_friction_state: ClassVar[str] = ""
    #: which of its effect's forms this class is (``tip`` for ``deadzone:tip``); "" for the plain one. A form's
    #: parameters are prefixed ``<name>_<form>`` and its model-file settings say ``{"form": ...}``
    form: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if not cls.__dict__.get("usage"):
            cls.usage = cls.name

    #: optional: ``simulate(self, data: HysteresisData, rng: numpy.random.Generator) -> ndarray``,
    #: the measured angle (deg, (n,)) of ``data.meas_deg`` with this effect added, for a simulator
    #: that hides a user's effect in a record (defined by subclasses that can; absent otherwise)
    simulate = None
    #: optional (absent otherwise): ``friction_factor(self, p, v, data) -> ndarray``, the bound of the base's friction at
    #: each sample (n,, > 0) times its own, for an effect that scales the base's holding force instead of transforming
    #: the command (``rate:friction``: ``1 + gamma |dv/dt|``; ``load:friction:COLUMN``: linear in the condition); ``v``
    #: is the command reaching the base. Only a base with one friction state carries it
    #: (``HysteresisModel.friction_state``; the others refuse it in one line), the factors of several such effects
    #: multiply, and the fit then differentiates numerically.

    def for_model(self, model, effects: list[Effect]) -> Effect:
        """This effect as ``model`` carries it beside ``effects`` (all of the model's; itself, unless a rule of the
        effect follows the model's: ``coupling``'s other bend takes the base's memory rule and the model's dead band)."""
        return self

    @property
    def prefix(self) -> str:
        """Parameter-name prefix; unique per effect instance in a model."""
        return f"{self.name}_{self.form}" if self.form else self.name

    @property
    def label(self) -> str:
        """The name as users write it in ``--effects`` (``load:sheath_wrap_deg`` for load terms)."""
        return f"{self.name}:{self.form}" if self.form else self.name

    def settings(self) -> dict:
        """JSON-able constructor arguments (saved in model files)."""
        return {"form": self.form} if self.form else {}

    @classmethod
    def from_settings(cls, settings: dict) -> Effect:
        """The effect a model file's entry describes (:meth:`settings`); an effect whose settings grew
        overrides it to read the files written before."""
        return cls(**settings)

    def param_names(self) -> list[str]:
        """Short parameter names, in a fixed order."""
        return list(self.units)

    def full_names(self) -> list[str]:
        return [f"{self.prefix}_{s}" for s in self.param_names()]

    def check(self, data: HysteresisData) -> None:
        """Raise ModelError when ``data`` lacks what this effect needs (columns, time)."""

    def check_fit(self, data: HysteresisData) -> None:
        """Raise ModelError when ``data`` cannot identify this effect's parameters (default: it can)."""

    @abstractmethod
    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        """Full-named parameters with bounds and a data-driven start; ``u`` is the command reaching this effect."""

    @abstractmethod
    def describe(self, p: dict, se: dict) -> str:
        """Equation fragment with values and standard errors, e.g. ``drift[0.010+-0.002 deg/s]``."""

    def adapt_start(self, start: dict[str, Parameter], fixed: dict[str, float]) -> None:
        """Make the start values agree with parameters the user holds fixed (default: nothing to do)."""

    def is_zero(self, p: dict) -> bool:
        """True when the term has no effect at these values (dropped from the printed equation)."""
        return all(v == 0.0 for v in p.values())

    def implausible(self, p: dict, data: HysteresisData) -> str:
        """Why values fitted on ``data`` cannot be this effect's physics (so the term stands in for
        something else); ``""`` when they can. Default: no physical bound to check."""
        return ""

    def segment(self, design, n_half_cycles: int):
        """The protocol segment of ``validate --next`` that shows this effect (None: it has none, and
        ``--next`` prints :attr:`protocol` in words).

        Parameters
        ----------
        design : endocal.validation.next_experiment.Design
            The experiment being designed: its knob range, speed limits and typical frequency, and
            builders of the motions (``design.add``, ``design.lissajous``, ``design.staircase``, ...);
            see that class.
        n_half_cycles : int
            Half-cycles the paired test of the next ``validate`` needs (the power calculation of
            :mod:`endocal.validation.power`), with ``design.sized(self.name)`` saying how in words.

        Returns
        -------
        endocal.validation.next_experiment.Planned or None
            What a builder of ``design`` returned (a segment, a deferred one shared with other
            effects, or a note why it cannot be designed on this probe), or None.
        """
        return None

    def gauge(self, base_absorbs: str) -> dict[str, float]:
        """Parameters (full names) a model holds fixed so the fit has one solution (default: none).

        ``base_absorbs`` says which maps of its input the base takes up exactly: ``"scale"`` (the
        play operators of ``pi`` are homogeneous, ``Phi_{c r}[c x] = c Phi_r[x]``) or ``"affine"``
        (free branch functions); an effect whose output such a map can trade off against fixes
        the matching parameters.
        """
        return {}

    def shapes_base(self) -> dict:
        """Settings a base resolves from ``"auto"`` when this effect shapes its loop (default: none).

        ``pi`` reads ``{"weights": "exponential", "offset": False}`` (the modified PI of the
        duodenoscope paper when an envelope shapes the input).
        """
        return {}

    def _bracket(self, p: dict, se: dict) -> str:
        parts = [f"{k}={fmt_value(p[k], se.get(k), self.units.get(k, ''))}" for k in self.param_names()]
        return "[" + ", ".join(parts) + "]"

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.settings().items())
        return f"{type(self).__name__}({args})"

    def __eq__(self, other) -> bool:
        return type(self) is type(other) and self.settings() == other.settings()

    def __hash__(self) -> int:
        return hash((type(self).__name__, tuple(sorted(self.settings().items()))))


class InputEffect(Effect):
    """An effect that transforms the knob command before the base model sees it."""

    kind: ClassVar[str] = "input"
    #: position in the input chain (lower acts first: time shift before static shape)
    order: ClassVar[int] = 50

    def wrap(self, inner: str) -> str:
        """How the equation writes this transform applied to ``inner`` (e.g. ``f(cmd)``)."""
        return f"{self.name}({inner})"

    @abstractmethod
    def apply(self, p: dict, u: np.ndarray, data: HysteresisData) -> np.ndarray:
        """Transformed command (n,); ``p`` maps short names to values."""

    @abstractmethod
    def invert(self, p: dict, v: np.ndarray, data: HysteresisData) -> np.ndarray:
        """Command (n,) whose transform is ``v`` (feedforward compensation)."""

    def stream_state(self, p: dict) -> np.ndarray:
        """Initial state of :meth:`invert_step` (streamable effects only)."""
        return np.zeros(1)

    def invert_step(self, p: dict, v: float, state: np.ndarray) -> float:
        """One sample of :meth:`invert` on a caller-held state (streamable effects only)."""
        raise ModelError(f"effect '{self.label}' cannot be compensated one sample at a time "
                         "(it needs future or logged samples); use the batch inverse")


class OutputFilter(Effect):
    """An effect that transforms the base model's output sequence (applied before additive terms).

    ``y = F(base(u)) + sum E_out``. Subclasses implement :meth:`apply` (``F``),
    :meth:`invert` (``F⁻¹``) and may implement ``apply_jac`` for the analytic Jacobian.
    """

    kind: ClassVar[str] = "filter"
    #: position in the output chain (lower acts first: the bend relaxes, then the tracker reads it)
    order: ClassVar[int] = 50
    #: the column of a knob whose friction the filter models (``coupling``'s other bend): the effects that scale the
    #: base's friction scale that one's too, and the model passes their factor at that knob as ``friction=`` (n,) to
    #: :meth:`apply` and :meth:`invert` (:meth:`~endocal.models.base.HysteresisModel._filter_inputs`; such a model
    #: is differentiated numerically, so ``apply_jac`` never gets one)
    other_friction: ClassVar[str | None] = None

    @abstractmethod
    def apply(self, p: dict, y: np.ndarray, data: HysteresisData) -> np.ndarray:
        """Filtered output (n,) from the base output ``y`` (deg)."""

    @abstractmethod
    def invert(self, p: dict, y: np.ndarray, data: HysteresisData) -> np.ndarray:
        """Base output (n,) whose filtered output is ``y`` (deg)."""

    def wrap(self, inner: str) -> str:
        return f"{self.name}({inner})"


class OutputEffect(Effect):
    """An effect that adds a term (deg of bending) to the base model's output."""

    kind: ClassVar[str] = "output"
    #: True when the term depends on the command (then the inverse iterates)
    depends_on_command: ClassVar[bool] = True

    @abstractmethod
    def term(self, p: dict, cmd: np.ndarray, data: HysteresisData) -> np.ndarray:
        """Additive term (n,) in degrees; ``cmd`` is the knob command (deg)."""
