"""The bending-plane calibration: four half-plane deviations, the thesis's delta, the
compensator they define, confidence intervals, and the deviation left after compensation.

:func:`fit_planes` is the one entry point; it takes the sweeps of one or more ``planes`` runs
(:func:`endocal.planes.segment.segment_planes_run`) and returns a :class:`PlanesCalibration`,
which the terminal view, the JSON output and ``planes.json`` all render from.

Confidence intervals come from a bootstrap over sweeps: the sweeps of each half-plane are
resampled with replacement and everything is refitted. With only ``k`` sweeps a percentile
interval under-covers (the bootstrap variance of a mean is ``(k-1)/k`` of the unbiased one and
its quantiles are coarse), so the interval is ``estimate +- t_{k-1} * SE_boot * sqrt(k/(k-1))``.
A half-plane with a single sweep falls back to resampling its frames (normal quantile; this
ignores any sweep-to-sweep variation and says so in ``ci_method``).

The residual deviation after compensation (the paper's figure 8, "after") is

* ``measured`` when sweeps recorded *with* the compensator are given: their planes are fitted
  like the others;
* ``cross-validated`` otherwise, when every half-plane has at least two sweeps: each sweep in
  turn is left out, the compensator is built from the rest, and the motion is regenerated on a
  plant whose half-plane follows the left-out sweep (sweep-to-sweep repeatability is what a
  new compensated sweep would meet);
* ``in-sample`` with single sweeps: the compensator is played on the plant it was built from,
  which only shows what the ``combine`` rule itself leaves.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.special import ndtri, stdtrit  # t.ppf and norm.ppf, without scipy.stats' import (0.2 s)

from endocal.kinematics.bending import bending_angles_deg
from endocal.planes.compensation import COMBINE, OrthogonalCompensator, residual_deviation
from endocal.planes.delta import fit_delta
from endocal.planes.halfplanes import HALF_PLANES, MODELS, CalibrationError, HalfPlaneFit, fit_half_plane
from endocal.planes.segment import Segmentation, Sweep

SOURCES = ("direction", "position", "both")
RESIDUAL_SOURCES = ("measured", "cross-validated", "in-sample")


def _interval(value: float, boot: np.ndarray, k: int, confidence: float) -> tuple[float, float]:
    se = float(np.std(boot, ddof=1)) if len(boot) > 1 else 0.0
    if k >= 2:
        half = stdtrit(k - 1, 0.5 + confidence / 2) * se * np.sqrt(k / (k - 1))
    else:
        half = ndtri(0.5 + confidence / 2) * se
    return float(value - half), float(value + half)


def fit_pooled(
    sweeps: Sequence[Sweep],
    half_plane: str,
    source: str = "direction",
    min_excursion_deg: float = 5.0,
    model: str = "bend_line",
) -> HalfPlaneFit:
    """Fit one half-plane from all its sweeps pooled (duodenoscope eqs. 1-2).

    Parameters
    ----------
    sweeps : sequence of Sweep
        Sweeps of ``half_plane``.
    half_plane : str
    source : {"direction", "position", "both"}
        Fit the tip directions (the paper's distal-end vectors), the tip positions, or both
        stacked (positions as unit chords), each set weighted by the inverse square of its own
        scatter about a first fit.
    min_excursion_deg : float
        See :func:`endocal.planes.halfplanes.fit_half_plane`.
    model : {"bend_line", "plane"}
        See :func:`endocal.planes.halfplanes.fit_half_plane`.
    """
    if source not in SOURCES:
        raise CalibrationError(f"unknown source '{source}': use one of {', '.join(SOURCES)}")
    if not sweeps:
        raise CalibrationError(f"half-plane '{half_plane}': no sweep found")
    d = np.concatenate([s.tip_dir_in_base for s in sweeps])
    if source == "direction":
        return fit_half_plane(d, half_plane, model=model, min_excursion_deg=min_excursion_deg, what="tip directions")
    p = np.concatenate([s.tip_in_base_mm for s in sweeps])
    chords = p / np.linalg.norm(p, axis=1, keepdims=True)
    if source == "position":
        # a constant-curvature chord leaves the base at half the bend
        return fit_half_plane(chords, half_plane, model=model, angle_scale=2.0, min_excursion_deg=min_excursion_deg,
                              what="tip positions")
    fit_d = fit_half_plane(d, half_plane, model=model, min_excursion_deg=min_excursion_deg, what="tip directions")
    fit_p = fit_half_plane(chords, half_plane, model=model, angle_scale=2.0, min_excursion_deg=0.0, what="tip positions")
    floor = 1e-12
    w = np.concatenate([np.full(len(d), 1.0 / max(fit_d.rms_out_of_plane, floor) ** 2),
                        np.full(len(chords), 1.0 / max(fit_p.rms_out_of_plane, floor) ** 2)])
    scale = np.concatenate([np.ones(len(d)), np.full(len(chords), 2.0)])
    return fit_half_plane(np.concatenate([d, chords]), half_plane, model=model, weights=w / w.max(), angle_scale=scale,
                          min_excursion_deg=0.0, what="tip directions and positions")


@dataclass
class PlanesCalibration:
    """Fitted bending planes of one probe (duodenoscope eqs. 1-4; thesis delta).

    Attributes
    ----------
    deviation_deg, deviation_ci_deg : dict
        Per half-plane (``y+ y- x+ x-`` = the paper's alpha_Y+, alpha_Y-, alpha_X+, alpha_X-):
        unsigned angle to the standard plane (duodenoscope eq. 2) and its confidence interval, deg.
    deviation_signed_deg, deviation_signed_ci_deg : dict
        Signed deviation (counter-clockwise about +z) and its interval, deg; the compensator uses these.
    tilt_deg, offset_deg : dict
        Per half-plane diagnostics of the paper's hypothesis: tilt of the fitted plane from the
        probe axis (``model="plane"``), and the other knob's residual bend across the sweep's
        line (``model="bend_line"``), deg. Both are 0 when the hypothesis holds.
    delta_deg, delta_ci_deg : float, (float, float)
        The thesis's plane twist and its interval, deg.
    residual_deviation_deg, residual_deviation_signed_deg : dict
        Deviation left after compensation per half-plane (RMS over held-out sweeps when
        cross-validated), deg.
    residual_source : str
        ``measured``, ``cross-validated`` or ``in-sample`` (see module docstring).
    sweeps_used : list of dict
        Run, index, half-plane, frames, time span and excursion of every sweep fitted.
    dropped_frames : dict
        Frames dropped, per reason (see :class:`endocal.planes.segment.Segmentation`).
    source, model, combine : str
        What was fitted, with which half-plane model, and how the compensator adds angles.
    confidence : float
    ci_method : dict
        Per half-plane and for ``delta``: ``sweeps`` or ``frames`` (what the bootstrap resampled).
    n_bootstrap : int
    """

    deviation_deg: dict[str, float]
    deviation_ci_deg: dict[str, tuple[float, float]]
    deviation_signed_deg: dict[str, float]
    deviation_signed_ci_deg: dict[str, tuple[float, float]]
    tilt_deg: dict[str, float]
    offset_deg: dict[str, float]
    delta_deg: float
    delta_ci_deg: tuple[float, float]
    residual_deviation_deg: dict[str, float]
    residual_deviation_signed_deg: dict[str, float]
    residual_source: str
    sweeps_used: list[dict] = field(default_factory=list)
    dropped_frames: dict[str, int] = field(default_factory=dict)
    source: str = "direction"
    model: str = "bend_line"
    combine: str = "bend_vector"
    confidence: float = 0.95
    ci_method: dict[str, str] = field(default_factory=dict)
    n_bootstrap: int = 0

    def __str__(self) -> str:
        pct = round(100 * self.confidence)
        lines = [f"bending planes ({self.source}, {self.model}; {pct} % CI, {len(self.sweeps_used)} sweeps)"]
        for h in HALF_PLANES:
            lo, hi = self.deviation_signed_ci_deg[h]
            lines.append(f"  alpha_{h} = {self.deviation_deg[h]:6.2f} deg (signed {self.deviation_signed_deg[h]:+.2f}, "
                         f"CI {lo:+.2f}..{hi:+.2f}) -> after compensation {self.residual_deviation_deg[h]:.2f} deg")
        lines.append(f"  delta    = {self.delta_deg:6.2f} deg (CI {self.delta_ci_deg[0]:.2f}..{self.delta_ci_deg[1]:.2f}); "
                     f"residuals {self.residual_source}")
        return "\n".join(lines)

    @property
    def compensator(self) -> OrthogonalCompensator:
        """The orthogonal compensator (duodenoscope eqs. 3-4) built from the signed deviations."""
        return OrthogonalCompensator(self.deviation_signed_deg, combine=self.combine)

    def compensate(self, cmd_first_deg, cmd_second_deg) -> tuple[np.ndarray, np.ndarray]:
        """Angles to command so that the tip bends to the desired standard-plane angles.

        Parameters
        ----------
        cmd_first_deg, cmd_second_deg : (n,) arrays or scalars
            Desired angles of the first (y-z plane) and second (x-z plane) axis, degrees.

        Returns
        -------
        first_deg, second_deg : (n,) arrays
            Compensated angles (duodenoscope eq. 3 with the quadrant rule of eq. 4), degrees.
        """
        return self.compensator.compensate(cmd_first_deg, cmd_second_deg)

    def aligned_bending_angles_deg(self, tip_in_base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Thesis eq. 1 in the frame turned by ``delta`` (the thesis's corrected AP/ML angles).

        Parameters
        ----------
        tip_in_base : (n, 3) array
            Tip positions in the base frame.

        Returns
        -------
        theta_first_deg, theta_second_deg : (n,) arrays
        """
        c, s = np.cos(np.radians(self.delta_deg)), np.sin(np.radians(self.delta_deg))
        p = np.atleast_2d(np.asarray(tip_in_base, float))
        return bending_angles_deg(np.stack([c * p[:, 0] + s * p[:, 1], -s * p[:, 0] + c * p[:, 1], p[:, 2]], axis=1))

    def to_json(self) -> dict:
        """Plain-JSON view: ``deviation_deg``, ``residual_deviation_deg`` (keyed ``y+ y- x+ x-``),
        ``delta_deg`` and everything else the fit found."""
        def pairs(d):
            return {h: [float(d[h][0]), float(d[h][1])] for h in HALF_PLANES}

        def floats(d):
            return {h: float(d[h]) for h in HALF_PLANES}

        return {
            "deviation_deg": floats(self.deviation_deg),
            "deviation_ci_deg": pairs(self.deviation_ci_deg),
            "deviation_signed_deg": floats(self.deviation_signed_deg),
            "deviation_signed_ci_deg": pairs(self.deviation_signed_ci_deg),
            "tilt_deg": floats(self.tilt_deg),
            "offset_deg": floats(self.offset_deg),
            "delta_deg": float(self.delta_deg),
            "delta_ci_deg": [float(self.delta_ci_deg[0]), float(self.delta_ci_deg[1])],
            "residual_deviation_deg": floats(self.residual_deviation_deg),
            "residual_deviation_signed_deg": floats(self.residual_deviation_signed_deg),
            "residual_source": self.residual_source,
            "confidence": float(self.confidence),
            "ci_method": dict(self.ci_method),
            "n_bootstrap": int(self.n_bootstrap),
            "source": self.source,
            "model": self.model,
            "combine": self.combine,
            "sweeps_used": [dict(s) for s in self.sweeps_used],
            "dropped_frames": {k: int(v) for k, v in self.dropped_frames.items()},
        }

    @classmethod
    def from_json(cls, d: Mapping) -> PlanesCalibration:
        """Rebuild from :meth:`to_json` output.

        Raises
        ------
        CalibrationError
            A key is missing or a value has the wrong shape.
        """
        try:
            def half(key, conv):
                value = d[key]
                if set(value) != set(HALF_PLANES):
                    raise CalibrationError(f"'{key}' must have exactly the keys {', '.join(HALF_PLANES)}")
                return {h: conv(value[h]) for h in HALF_PLANES}

            def pair(x):
                lo, hi = x
                return float(lo), float(hi)

            out = cls(
                deviation_deg=half("deviation_deg", float),
                deviation_ci_deg=half("deviation_ci_deg", pair),
                deviation_signed_deg=half("deviation_signed_deg", float),
                deviation_signed_ci_deg=half("deviation_signed_ci_deg", pair),
                tilt_deg=half("tilt_deg", float),
                offset_deg=half("offset_deg", float),
                delta_deg=float(d["delta_deg"]),
                delta_ci_deg=pair(d["delta_ci_deg"]),
                residual_deviation_deg=half("residual_deviation_deg", float),
                residual_deviation_signed_deg=half("residual_deviation_signed_deg", float),
                residual_source=str(d["residual_source"]),
                sweeps_used=[dict(s) for s in d["sweeps_used"]],
                dropped_frames={str(k): int(v) for k, v in d["dropped_frames"].items()},
                source=str(d["source"]),
                model=str(d["model"]),
                combine=str(d["combine"]),
                confidence=float(d["confidence"]),
                ci_method={str(k): str(v) for k, v in d["ci_method"].items()},
                n_bootstrap=int(d["n_bootstrap"]),
            )
        except KeyError as exc:
            raise CalibrationError(f"planes calibration lacks key {exc.args[0]!r}") from None
        except (TypeError, ValueError, AttributeError, OverflowError) as exc:
            if isinstance(exc, CalibrationError):
                raise
            raise CalibrationError(f"planes calibration has a malformed value: {exc}") from None
        if out.residual_source not in RESIDUAL_SOURCES:
            raise CalibrationError(f"unknown residual_source '{out.residual_source}' (use {', '.join(RESIDUAL_SOURCES)})")
        if out.combine not in COMBINE or out.source not in SOURCES or out.model not in MODELS:
            raise CalibrationError(f"unknown combine '{out.combine}', source '{out.source}' or model '{out.model}'")
        out.compensator  # noqa: B018 -- validates the deviations (ordering, range) at load time
        return out


def _resample(sweeps: list[Sweep], rng: np.random.Generator) -> list[Sweep]:
    """Bootstrap replicate of one half-plane: sweeps with replacement, or frames of a lone sweep."""
    if len(sweeps) >= 2:
        return [sweeps[i] for i in rng.integers(0, len(sweeps), len(sweeps))]
    s = sweeps[0]
    i = np.sort(rng.integers(0, len(s.t_s), len(s.t_s)))
    return [Sweep(s.half_plane, s.run, s.index, s.t_s[i], s.tip_in_base_mm[i], s.tip_dir_in_base[i], s.cmd_deg[i])]


def fit_planes(
    segmentation: Segmentation,
    *,
    source: str = "direction",
    model: str = "bend_line",
    combine: str = "bend_vector",
    min_excursion_deg: float = 5.0,
    symmetry_weight: float = 0.1,
    n_bootstrap: int = 200,
    confidence: float = 0.95,
    seed: int = 0,
    compensated: Segmentation | None = None,
    residual_amplitude_deg: float = 30.0,
) -> PlanesCalibration:
    """Fit the four half-planes, delta, their confidence intervals and the residual after compensation.

    Parameters
    ----------
    segmentation : Segmentation
        Single-knob sweeps of one or more ``planes`` runs (add Segmentations with ``+``).
    source : {"direction", "position", "both"}
        What is fitted (see :func:`fit_pooled`); the paper fits distal-end directions.
    model : {"bend_line", "plane"}
        Half-plane model (see :func:`endocal.planes.halfplanes.fit_half_plane`): the paper's
        plane through the probe axis, or the default line in bend space that tolerates the
        other knob's residual bend.
    combine : {"bend_vector", "direction_sine"}
        How the compensator adds the two knobs (see :mod:`endocal.planes.compensation`).
    min_excursion_deg : float
        Smallest excursion from the probe axis a half-plane needs, degrees (of tip direction,
        or of the tip chord with ``source="position"``).
    symmetry_weight : float
        Weight of the symmetric-ML-range term of the delta fit.
    n_bootstrap : int
        Bootstrap replicates for the confidence intervals (0 gives zero-width intervals).
    confidence : float
        Two-sided confidence level, in (0, 1).
    seed : int
        Seed of the bootstrap's random generator.
    compensated : Segmentation, optional
        Sweeps recorded with this compensator active (segment them with
        ``other_max_deg=None``); their fitted deviations become the measured residuals.
    residual_amplitude_deg : float
        Amplitude of the regenerated sweeps for the predicted residuals, degrees.

    Returns
    -------
    PlanesCalibration

    Raises
    ------
    CalibrationError
        A half-plane has no sweep or too little excursion (the message names it and the
        excursion seen), or an argument is out of range.
    """
    if combine not in COMBINE:
        raise CalibrationError(f"unknown combine '{combine}': use one of {', '.join(COMBINE)}")
    if source not in SOURCES:
        raise CalibrationError(f"unknown source '{source}': use one of {', '.join(SOURCES)}")
    if model not in MODELS:
        raise CalibrationError(f"unknown model '{model}': use one of {', '.join(MODELS)}")
    if not 0 < confidence < 1:
        raise CalibrationError(f"confidence must lie in (0, 1), got {confidence}")
    if n_bootstrap < 0:
        raise CalibrationError(f"n_bootstrap must be >= 0, got {n_bootstrap}")
    groups = segmentation.by_half_plane()
    empty = [h for h in HALF_PLANES if not groups[h]]
    if empty:
        found = ", ".join(f"{h}: {len(groups[h])}" for h in HALF_PLANES)
        raise CalibrationError(
            f"no sweep of half-plane(s) {', '.join(empty)} (sweeps found per half-plane: {found}); a planes run must "
            "move each knob both ways from rest while the other stays near zero"
        )
    fits = {h: fit_pooled(groups[h], h, source, min_excursion_deg, model) for h in HALF_PLANES}
    sweeps = [s for h in HALF_PLANES for s in groups[h]]
    delta = fit_delta(sweeps, symmetry_weight=symmetry_weight)

    # Bootstrap over sweeps (module docstring).
    rng = np.random.default_rng(seed)
    boot_signed = {h: np.empty(n_bootstrap) for h in HALF_PLANES}
    boot_unsigned = {h: np.empty(n_bootstrap) for h in HALF_PLANES}
    boot_delta = np.empty(n_bootstrap)
    for b in range(n_bootstrap):
        replicate = {h: _resample(groups[h], rng) for h in HALF_PLANES}
        for h in HALF_PLANES:
            f = fit_pooled(replicate[h], h, source, 0.0, model)
            boot_signed[h][b], boot_unsigned[h][b] = f.deviation_signed_deg, f.deviation_deg
        boot_delta[b] = fit_delta([s for h in HALF_PLANES for s in replicate[h]], symmetry_weight=symmetry_weight,
                                  around_deg=delta.delta_deg).delta_deg
    k = {h: len(groups[h]) for h in HALF_PLANES}
    ci_signed, ci_unsigned = {}, {}
    for h in HALF_PLANES:
        # Signed deviations are compared by wrapping the replicate around the estimate.
        signed = fits[h].deviation_signed_deg + ((boot_signed[h] - fits[h].deviation_signed_deg + 180.0) % 360.0 - 180.0)
        ci_signed[h] = _interval(fits[h].deviation_signed_deg, signed, k[h], confidence)
        lo, hi = _interval(fits[h].deviation_deg, boot_unsigned[h], k[h], confidence)
        ci_unsigned[h] = (max(0.0, lo), hi)
    k_delta = min(k.values())
    delta_ci = _interval(delta.delta_deg, boot_delta, k_delta, confidence)
    ci_method = {h: ("sweeps" if k[h] >= 2 else "frames") for h in HALF_PLANES}
    ci_method["delta"] = "sweeps" if k_delta >= 2 else "frames"

    signed = {h: fits[h].deviation_signed_deg for h in HALF_PLANES}
    compensator = OrthogonalCompensator(signed, combine=combine)
    residual, residual_signed, residual_source = _residuals(
        compensator, signed, groups, source, model, combine, compensated, residual_amplitude_deg
    )

    used = []
    for h in HALF_PLANES:
        for s in groups[h]:
            vec = s.tip_dir_in_base if source != "position" else s.tip_in_base_mm
            row = s.describe()
            row["excursion_deg"] = float(np.degrees(np.max(np.arctan2(np.hypot(vec[:, 0], vec[:, 1]), vec[:, 2]))))
            used.append(row)
    used.sort(key=lambda r: (r["run"], r["index"]))
    return PlanesCalibration(
        deviation_deg={h: fits[h].deviation_deg for h in HALF_PLANES},
        deviation_ci_deg=ci_unsigned,
        deviation_signed_deg=signed,
        deviation_signed_ci_deg=ci_signed,
        tilt_deg={h: fits[h].tilt_deg for h in HALF_PLANES},
        offset_deg={h: fits[h].offset_deg for h in HALF_PLANES},
        delta_deg=delta.delta_deg,
        delta_ci_deg=delta_ci,
        residual_deviation_deg=residual,
        residual_deviation_signed_deg=residual_signed,
        residual_source=residual_source,
        sweeps_used=used,
        dropped_frames=dict(segmentation.dropped),
        source=source,
        model=model,
        combine=combine,
        confidence=confidence,
        ci_method=ci_method,
        n_bootstrap=n_bootstrap,
    )


def _residuals(compensator, signed, groups, source, model, combine, compensated, amplitude_deg):
    if compensated is not None:
        after = compensated.by_half_plane()
        missing = [h for h in HALF_PLANES if not after[h]]
        if missing:
            raise CalibrationError(f"the compensated sweeps lack half-plane(s) {', '.join(missing)}")
        fits = {h: fit_pooled(after[h], h, source, 0.0, model) for h in HALF_PLANES}
        return ({h: fits[h].deviation_deg for h in HALF_PLANES},
                {h: fits[h].deviation_signed_deg for h in HALF_PLANES}, "measured")
    if all(len(groups[h]) >= 2 for h in HALF_PLANES):
        residual, residual_signed = {}, {}
        for h in HALF_PLANES:
            unsigned, signed_r = [], []
            for k in range(len(groups[h])):
                rest = groups[h][:k] + groups[h][k + 1:]
                trained = dict(signed, **{h: fit_pooled(rest, h, source, 0.0, model).deviation_signed_deg})
                truth = dict(signed, **{h: fit_pooled([groups[h][k]], h, source, 0.0, model).deviation_signed_deg})
                f = residual_deviation(OrthogonalCompensator(trained, combine), truth, amplitude_deg)[h]
                unsigned.append(f.deviation_deg)
                signed_r.append(f.deviation_signed_deg)
            residual[h] = float(np.sqrt(np.mean(np.square(unsigned))))
            residual_signed[h] = float(np.mean(signed_r))
        return residual, residual_signed, "cross-validated"
    fits = residual_deviation(compensator, signed, amplitude_deg)
    return ({h: fits[h].deviation_deg for h in HALF_PLANES},
            {h: fits[h].deviation_signed_deg for h in HALF_PLANES}, "in-sample")
