"""The refit a suspect suggests: what to fit, on which data, and where to keep it.

The scan tests each candidate by refitting the model's structure with it; a
:class:`Refit` records that fit for the user to make: the estimation data, the axis, the
base and its settings, the effects, the bending planes, the model it starts from and a
suggested output file. It is data, not a command line: :func:`endocal.shell.refit_command` renders it as the
``endocal fit hysteresis ...`` a user types (the terminal summary, ``validate --json``'s
``command`` and the API's ``Suggestion.command`` alike), and ``Suggestion.refit()`` calls the
library with its fields.

A refit is a promise: it rebuilds the candidate the scan scored, with the same resolved
structure (:func:`~endocal.validation.structure.resolved_settings`: a ``weights="auto"`` fitted
as ``exponential`` is refitted as ``exponential``), the same settings and the same start (the
validated model; and for an effect whose start the scan searched, the values its candidate reached as a
second start, :attr:`Refit.start_values`, kept where it ends lower: a search of its own on every sample can
pick another start and end in a worse minimum than the candidate scored). Where the scan fitted its candidates on 1 estimation sample in N and the
refit fits every sample, the refit's RMSE on the validation data is not the scan's number, and
:attr:`Refit.expected_rmse_deg` gives the range to expect.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from endocal.models.base import HysteresisModel
from endocal.validation.structure import changed_settings, effect_labels, with_candidate


@dataclass(frozen=True)
class Refit:
    """A fit of ``base + effects`` the scan scored, for the user to make.

    Attributes
    ----------
    data_paths : tuple of str
        The data to fit on (the estimation data the candidate was fitted on; with
        ``--refit-on all`` the validation data too).
    axis : str or None
        The bending axis.
    base : str
        The base model (``bspline``, ``pi``, ...).
    effects : tuple of str
        Every effect of the refit, as ``--effects`` writes them (the model's own, then the candidate).
    settings : dict
        Base settings, as the model's fit resolved them, that differ from their defaults
        (``n_knots``, ``weights``, ...; :func:`~endocal.validation.structure.changed_settings`),
        so the refit keeps the structure the scan scored.
    planes_path : str or None
        The bending planes the model was fitted through.
    start_from : str or None
        The model under validation: the scan fitted each candidate starting from its parameters
        (:func:`~endocal.validation.structure.split_fit`), and the refit does the same, so it is the
        fit the scan scored rather than a fit from scratch that may stop in another local minimum.
    out_path : str
        Suggested model file (:func:`refit_path`).
    start_values : dict
        Start values of the added effect's parameters (full names as the model prints them), where
        its fit searches a start among candidates (a slack, a lag): the values the scan's candidate
        reached, a second start the refit fits from beside its own search and keeps where it ends
        lower on the estimation data (``fit hysteresis --start-value``). Empty for an effect without
        a start search.
    scan_stride : int
        The scan fitted the candidate on 1 estimation sample in this many (1: every sample, as
        the refit does).
    expected_rmse_deg : (float, float) or None
        When ``scan_stride`` > 1: the validation RMSE (deg) to expect of the refit on every
        sample, from the candidate fitted on two interleaved subsamples of the estimation data
        (:func:`~endocal.validation.scan.scan_split`); None when the scan fitted every sample (its
        RMSE is the promise) or under rolling origin (the refit's own validation repeats the folds).
    """

    data_paths: tuple[str, ...]
    axis: str | None
    base: str
    effects: tuple[str, ...]
    out_path: str
    settings: dict = field(default_factory=dict)
    planes_path: str | None = None
    start_from: str | None = None
    start_values: dict = field(default_factory=dict)
    scan_stride: int = 1
    expected_rmse_deg: tuple[float, float] | None = None

    def expected_words(self) -> str:
        """``, its refit on every sample expected at 1.3 .. 1.41 deg`` where the scan fitted a subsample, else ``""``
        (a range that rounds to one number prints as that number)."""
        if self.expected_rmse_deg is None:
            return ""
        lo, hi = (f"{x:.3g}" for x in self.expected_rmse_deg)
        return f", its refit on every sample expected at {lo if lo == hi else f'{lo} .. {hi}'} deg"

    def to_dict(self) -> dict:
        return {"data_paths": list(self.data_paths), "axis": self.axis, "base": self.base,
                "effects": list(self.effects), "settings": dict(self.settings), "planes_path": self.planes_path,
                "start_from": self.start_from, "start_values": dict(self.start_values), "out_path": self.out_path,
                "scan_stride": self.scan_stride,
                "expected_rmse_deg": None if self.expected_rmse_deg is None else list(self.expected_rmse_deg)}


def refit_path(model_path: str | None, effect: str, suffix: str = "") -> str:
    """``MODEL-EFFECT.json`` beside ``MODEL.json`` (``load:col`` becomes ``load-col``), with
    ``suffix`` before ``.json`` (``-all`` for a refit on more data than the scan scored)."""
    tag = effect.replace(":", "-") + suffix
    if not model_path:
        return f"model-{tag}.json"
    p = str(model_path)
    stem = p[:-5] if p.endswith(".json") else p
    return f"{stem}-{tag}.json"


def suggest_refit(model: HysteresisModel, effect: str, data_paths: Sequence[str], *, model_path: str | None = None,
                  planes_path: str | None = None, suffix: str = "", start_values: dict | None = None) -> Refit:
    """The refit of ``model``'s structure with ``effect`` added, on ``data_paths``, starting from ``model_path``.

    Parameters
    ----------
    model : HysteresisModel
        The model under validation.
    effect : str
        The candidate effect (``delay``, ``load:sheath_wrap_deg``).
    data_paths : sequence of str
        The data to fit on.
    model_path : str, optional
        The model's file: the refit starts from it and is named beside it.
    planes_path : str, optional
        The bending planes the model was fitted through.
    suffix : str
        Ends the suggested file name (:func:`refit_path`).
    start_values : dict, optional
        :attr:`Refit.start_values`.
    """
    return Refit(data_paths=tuple(str(p) for p in data_paths), axis=model.axis, base=model.base_name,
                 effects=tuple(with_candidate(effect_labels(model), effect)),
                 out_path=refit_path(model_path, effect, suffix),
                 settings=changed_settings(model), planes_path=None if planes_path is None else str(planes_path),
                 start_from=None if model_path is None else str(model_path),
                 # 6 digits, which a start needs (the fit refines it) and the printed command keeps short; the
                 # command (endocal.shell.refit_argv) and Suggestion.refit() both use these very numbers
                 start_values={k: float(f"{v:.6g}") for k, v in (start_values or {}).items()})
