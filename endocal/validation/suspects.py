"""What the effect scan found: the candidates it tested, the suspects among them, and how it tested them.

:class:`Suspect` is one candidate effect, tested (its held-out gain, its corrected p-value, the
refit that adds it); :class:`ScanResult` holds them all with what could not be tested and why.
The scan itself is :mod:`endocal.validation.scan`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from endocal.validation.power import PowerEstimate
from endocal.validation.refit import Refit


@dataclass(frozen=True)
class Suspect:
    """One candidate effect, tested.

    Attributes
    ----------
    effect : str
        The effect as ``--effects`` writes it (``delay``, ``load:sheath_wrap_deg``).
    column : str or None
        The covariate column of a ``load`` term.
    gain_pct : float
        Held-out RMSE improvement over the model as it stands, percent (negative: worse).
    p_value : float
        Holm-corrected one-sided p-value of that improvement.
    p_raw : float
        Uncorrected p-value.
    rmse_heldout_deg, base_rmse_heldout_deg : float
        Held-out RMSE with and without the candidate (deg).
    significant : bool
        Listed as a suspect (``p_value < alpha`` and ``gain_pct >= min_gain_pct``).
    refit : Refit
        The refit that adds the candidate to the model (the command line prints it as the
        ``endocal fit hysteresis`` command to run).
    cause, signature, protocol : str
        From the effect catalog: physical cause, residual signature, revealing protocol.
    n_blocks : int
        Independent blocks in the paired test.
    screened : bool
        Not refitted beyond the first fold: its training fit gained too little (see
        :func:`~endocal.validation.scan.scan_effects`).
    caution : str
        Under the estimation/validation scheme, why the candidate may stand in for something
        it does not model: its own parameters that its fit left at a nonzero bound
        (``delay_s = -0.5 sits at its lower bound ...``; a share at its zero bound is the term
        switched off, not stretched), or values its physics cannot have
        (:meth:`~endocal.models.effects.base.Effect.implausible`); such a suggestion ranks
        after those without.
    evidence : str
        ``significant``; ``not significant (p = ... over N half-cycles; ...)``, or ``not enough
        evidence (N units, M needed; ...)`` when the validation data holds too few independent
        units for any p-value to reach ``alpha`` (the candidate is then listed as a suggestion on
        its gain alone), each saying about how many units would make it significant at the gain
        seen or that no length will; ``under the 10 % bar (p = ...)`` when significant but too
        small to list.
    power : PowerEstimate or None
        Units of the validation data's kind the paired test needs at the gain seen
        (:mod:`endocal.validation.power`; estimation/validation scheme only).
    """

    effect: str
    column: str | None
    gain_pct: float
    p_value: float
    p_raw: float
    rmse_heldout_deg: float
    base_rmse_heldout_deg: float
    significant: bool
    refit: Refit
    cause: str
    signature: str
    protocol: str
    n_blocks: int
    screened: bool = False
    evidence: str = ""
    caution: str = ""
    power: PowerEstimate | None = None

    def to_dict(self) -> dict:
        return {k: (v.to_dict() if k in ("refit", "power") and v is not None else v)
                for k in self.__dataclass_fields__ for v in (getattr(self, k),)}


@dataclass(frozen=True)
class ScanResult:
    """Result of :func:`~endocal.validation.scan.scan_effects` and :func:`~endocal.validation.scan.scan_split`.

    Attributes
    ----------
    suspects : tuple of Suspect
        Significant candidates, most likely (largest held-out gain) first. Under the
        estimation/validation scheme, when none is significant, the candidates that still
        clear the gain bar, as suggestions (their ``evidence`` says why they are not
        significant: too few units, or a gain not consistent across them); empty when no
        candidate lowers the error.
    tested : tuple of Suspect
        Every candidate tested, by decreasing gain.
    baseline_rmse_heldout_deg : float
        Held-out RMSE of the model as it stands (refitted fold by fold).
    untestable : dict
        Effect -> why this data cannot reveal it (not tested).
    notes : tuple of str
        Ambiguities and identifiability, in words.
    folds, stride, n_samples : int
        Test blocks, decimation step and samples scanned (rolling origin); under the
        estimation/validation scheme ``folds`` is 0 and ``stride``/``n_samples`` are those
        of the estimation data the candidates were fitted on.
    scheme : {"estimation/validation", "rolling-origin", "none"}
        How held-out errors were made: candidates fitted on separate estimation data and
        scored on the validation data, or rolling-origin cross-validation on the validation
        data alone; ``none`` when the data could not support either (``scheme_reason`` says why).
    scheme_reason : str
        Why this scheme ran, in words.
    units : dict or None
        The validation data's units of the paired test (estimation/validation scheme).
    min_units : int
        Fewest units with which the best candidate could reach significance.
    still_blocks : int
        Rolling-origin held-out blocks in which this axis's knob rests (:func:`still_blocks`).
    lookalikes : tuple of Settlement
        The first suggestion against each of its declared look-alikes
        (:func:`~endocal.validation.ambiguity.settle_lookalikes`).
    bases : tuple of BaseCandidate
        The other bases of the catalogue with the model's effects, tested the same way, by decreasing
        gain (:mod:`endocal.validation.bases`); empty when the scan tested given candidates only.
    base_first : bool
        The first base suggestion is the next refit, before the first effect suspect: no effect is
        suspected, or the base change gains more and (estimation/validation) beats the effect's refit in
        a paired test of its own (:func:`~endocal.validation.bases.base_before_effect`).
    """

    suspects: tuple[Suspect, ...]
    tested: tuple[Suspect, ...]
    baseline_rmse_heldout_deg: float
    untestable: dict = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    folds: int = 0
    stride: int = 1
    n_samples: int = 0
    alpha: float = 0.05
    min_gain_pct: float = 0.0
    scheme: str = "rolling-origin"
    scheme_reason: str = ""
    units: dict | None = None
    min_units: int = 0
    still_blocks: int = 0
    lookalikes: tuple = ()
    bases: tuple = ()
    base_first: bool = False

    @property
    def base_suggestions(self) -> tuple:
        """The base candidates that clear both bars (corrected p below ``alpha``, gain at least ``min_gain_pct``)."""
        return tuple(b for b in self.bases if b.significant)

    @property
    def thin_evidence(self) -> bool:
        """True when the data holds too few units for any candidate to reach significance."""
        return any(s.evidence.startswith("not enough") for s in self.tested)

    def to_dict(self) -> dict:
        test = ("sign-flip randomisation test on per-unit loss differentials of the validation data, Holm-corrected"
                if self.scheme == "estimation/validation" else
                "Wilcoxon signed-rank on block-mean loss differentials, Holm-corrected")
        return {
            "suspects": [s.to_dict() for s in self.suspects],
            "tested": [s.to_dict() for s in self.tested],
            "bases": [b.to_dict() for b in self.bases],
            "base_first": self.base_first,
            "baseline_rmse_heldout_deg": self.baseline_rmse_heldout_deg,
            "untestable": dict(self.untestable),
            "notes": list(self.notes),
            "cv": {"scheme": self.scheme, "reason": self.scheme_reason, "folds": self.folds, "stride": self.stride,
                   "n_samples": self.n_samples, "alpha": self.alpha, "min_gain_pct": self.min_gain_pct,
                   "units": self.units, "min_units": self.min_units, "test": test,
                   "still_blocks": self.still_blocks},
            "lookalikes": [x.to_dict() for x in self.lookalikes],
        }
