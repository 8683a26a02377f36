"""Rolling-origin cross-validation in contiguous blocks: the folds, and a model structure's held-out errors.

The first ``train_frac`` of the record is training data only; the rest is cut into
``folds`` contiguous test blocks. Fold ``k`` fits on everything before block ``k`` and
predicts block ``k`` by running the fitted model over the record from its start (so the
hysteresis operators, delays and creep states enter the block with the history they
really had). Training data is always one run from the start: hysteresis memory and
time-based effects (drift, creep, delay) would be broken by holes cut into the record,
and the model fit takes no sample mask. Held-out data never precedes its training data,
the honest direction for time series.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from endocal.errors import ModelError
from endocal.models import HysteresisData
from endocal.models.base import HysteresisModel
from endocal.validation.data import prefix
from endocal.validation.regimes import turning_points
from endocal.validation.structure import template


def fold_bounds(n_samples: int, folds: int, train_frac: float = 0.5) -> list[tuple[int, int]]:
    """``(train_end, test_end)`` of each rolling-origin fold: train on ``[0, train_end)``, test ``[train_end, test_end)``.

    On data of several runs the bounds are read as fractions of ``n_samples`` and applied to
    every run at once (:func:`fold_split`).
    """
    first = int(round(train_frac * n_samples))
    edges = np.linspace(first, n_samples, folds + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def fold_split(data: HysteresisData, bound: tuple[int, int]) -> tuple[HysteresisData, HysteresisData, np.ndarray]:
    """Training data, the data to run the fitted model over, and the held-out positions in the latter.

    One run: train on ``[0, a)``, run over ``[0, b)``, hold out ``[a, b)``. Several runs (a
    random input and a chirp, say): the same fractions ``a/n`` and ``b/n`` of *every* run, so
    each training block holds every kind of motion the held-out blocks do; rolling the origin
    over the runs laid end to end would fit on the first runs and ask for the last. That
    holds while the first half of every run already spans its command range
    (:func:`runs_cover_their_range`); runs that go somewhere new later (a staircase up, then
    down) are laid end to end instead, so no fold asks a model for commands it never saw.

    Returns
    -------
    train, evaluate : HysteresisData
        Each run's prefix up to its training end and up to its test end (runs kept apart).
    held : ndarray of int
        Positions in ``evaluate`` of the held-out samples, run by run.
    """
    a, b = bound
    if data.run_starts.size <= 1 or not runs_cover_their_range(data):
        return prefix(data, a), prefix(data, b), np.arange(a, b)
    n = data.n_samples
    train_idx, eval_idx, held = [], [], []
    for sl in data.run_slices():
        length = sl.stop - sl.start
        ra, rb = int(round(a / n * length)), int(round(b / n * length))
        train_idx.append(np.arange(sl.start, sl.start + ra))
        held.append(sum(len(i) for i in eval_idx) + np.arange(ra, rb))
        eval_idx.append(np.arange(sl.start, sl.start + rb))
    return data.take(train_idx), data.take(eval_idx), np.concatenate(held)


def runs_cover_their_range(data: HysteresisData, train_frac: float = 0.5, min_cover: float = 0.75) -> bool:
    """True when the first ``train_frac`` of every run spans at least ``min_cover`` of that run's command range.

    A band-limited random input's first half spans ~85 % of its range (its peaks fall
    anywhere: a model trained on it clamps a little), a chirp's or damped sine's 100 %, a
    staircase up then down 50 % (a model trained on it would have to guess half the range).
    """
    for sl in data.run_slices():
        u = data.cmd_deg[sl]
        head = u[: max(1, int(round(train_frac * u.size)))]
        span = float(np.ptp(u))
        if span > 0 and float(np.ptp(head)) < min_cover * span:
            return False
    return True


def check_cv_data(data: HysteresisData, folds: int, train_frac: float = 0.5, min_block: int = 30) -> None:
    """Refuse data too short for ``folds``-fold blocked cross-validation.

    Raises
    ------
    ModelError
        Fewer than ``min_block`` samples per test block, or a first training block without
        two direction reversals (the model could not be fitted on it).
    """
    if not isinstance(folds, (int, np.integer)) or isinstance(folds, bool) or folds < 2:
        raise ModelError(f"folds must be an integer >= 2, got {folds!r}")
    n = data.n_samples
    need = int(math.ceil(folds * min_block / (1 - train_frac)))
    if n < need:
        raise ModelError(f"data too short for {folds}-fold blocked cross-validation: {n} samples, need at least "
                         f"{need} ({min_block} per held-out block); give a longer run or fewer --folds")
    first = fold_split(data, fold_bounds(n, folds, train_frac)[0])[0]
    n_turns = int(turning_points(first).size)
    if n_turns < 2:
        if np.ptp(first.cmd_deg) <= STILL_FRAC * np.ptp(data.cmd_deg) and turning_points(data).size >= 2:
            # not short: this knob rests, then moves (a sine-set moves one knob, then the other)
            raise ModelError(f"this axis reverses {int(turning_points(data).size)} times in the record but its knob "
                             f"rests through the first {first.n_samples} samples (the first training block), so no "
                             "model can be fitted there")
        raise ModelError(f"data too short for blocked cross-validation: the first {first.n_samples} samples (the first "
                         f"training block) hold {n_turns} direction reversal(s), a hysteresis model needs at least 2; "
                         "give a longer run")


#: A knob "rests" in a stretch of record when its command stays within this fraction of its
#: range over the record: 2 % of a 120 deg sweep is 2.4 deg, below any loop a tendon drive draws.
STILL_FRAC = 0.02


def still_blocks(data: HysteresisData, bounds: Sequence[tuple[int, int]]) -> int:
    """Held-out blocks in which this axis's knob rests (:data:`STILL_FRAC`) while the other moves:
    they test nothing of its hysteresis, only where the model puts the resting bend."""
    span = float(np.ptp(data.cmd_deg))
    still = 0
    for bd in bounds:
        _, over, held = fold_split(data, bd)
        cmd = over.cmd_deg[held]
        still += int(cmd.size == 0 or np.ptp(cmd) <= STILL_FRAC * span)
    return still


def fold_errors(model: HysteresisModel, effects: Sequence[str], data: HysteresisData,
                bound: tuple[int, int], ftol: float | None = None) -> tuple[np.ndarray, HysteresisModel]:
    """Held-out errors ``pred - meas`` (deg) of ``base + effects`` on one rolling-origin fold, and its fitted model.

    The model is fitted on ``[0, train_end)`` and run over ``[0, test_end)`` from the record's
    start; the errors are those of ``[train_end, test_end)``. ``ftol``: the fit's stopping rule (the
    scan's :data:`~endocal.validation.structure.SCAN_FTOL`; None, the fit's own, as the report's ladder
    and its definition by hand).
    """
    train, evaluate, held = fold_split(data, bound)
    m = template(model, effects).fit(train, ftol=ftol)
    pred = m.predict(evaluate)  # a template extrapolates beyond its fitted range
    return pred[held] - evaluate.meas_deg[held], m


def heldout_errors(model: HysteresisModel, effects: Sequence[str], data: HysteresisData,
                   bounds: Sequence[tuple[int, int]], ftol: float | None = None) -> tuple[np.ndarray, list]:
    """Held-out errors ``pred - meas`` of ``base + effects`` on the rolling-origin folds.

    Parameters
    ----------
    model : HysteresisModel
        Gives the base and its settings (its fitted values are not used).
    effects : sequence of str
        Effects of the refitted models.
    data : HysteresisData
    bounds : list of (train_end, test_end)
        From :func:`fold_bounds`.
    ftol : float, optional
        The fits' stopping rule (:func:`fold_errors`).

    Returns
    -------
    errors : ndarray (n_test,)
        Concatenated over the test blocks (deg).
    fitted : list of HysteresisModel
        The model of each fold.
    """
    out = [fold_errors(model, effects, data, bd, ftol) for bd in bounds]
    return np.concatenate([e for e, _ in out]), [m for _, m in out]
