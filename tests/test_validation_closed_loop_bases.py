"""The closed loop on a friction family the catalogue's first bases lack (issue 32, part 3).

The plant: the simulator with ``[tendon] friction = "bouc-wen"``: the sheath slides freely and one
smooth Bouc-Wen element at the knob holds the pull back (its lag saturates at ``bouc_wen_lag_deg``
per unit of ``mu * wrap``, so the sheath's wrap and ``[rate]`` still act through it); the bending
section's joint friction is off, so no friction in the plant has return-point memory. Every other
section, each hidden effect's strength, the rig lag (servo 2 x 30 ms, tracker 15 ms), the records
and the loop are those of tests/test_validation_closed_loop.py (issue 27's user-shaped loop), with
one step added: when `validate` suggests another base (`scan.base_suggestions`, the same paired
test as the effects) and the summary's next refit is that change (``scan.base_first``: it gains more than
the first effect suspect and beats its refit in a paired test), the loop refits with that base (the printed
refit: `--model BASE` with the model's effects and any effect the change brings, `--start-from` the
model; :func:`~tests.test_validation_closed_loop.printed_refit`) instead of adding an effect.

The bars (issue 32, "How good"): the loop names the base change (to a base without return-point
memory); it ends within 1.2x the noise (the final structure refitted on its final estimation data
and scored on its final validation record, against the noise floor of that record: the same plan
recorded again without tracker noise, since a record of faster, larger motions reads the tip's noise
into a larger angle noise); it names the hidden effect; and it adds nothing the plant lacks. What the plant
has besides the hidden effect, in every case: `delay` (the rig lag), `coupling` and `load` (as in
the capstan loop: eq. 1 reads the axis from a tip both bends put there, and the wrap --next asks for
scales the element's holding force: `load:friction:sheath_wrap_deg` on a friction base), and `envelope`
(the bending section's stiffness maps the pull past the element: the B-spline's free branches take that
shape up, a Bouc-Wen base takes it as `envelope:tip`).

Expensive (up to seven validations per case, each scanning every effect and every base): marked
``slow``; run with ``pytest -m slow tests/test_validation_closed_loop_bases.py``. Measured numbers
are in docs/evidence/hidden-effects.md.
"""

from __future__ import annotations

import functools
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from endocal.models import BASES, make_model
from endocal.runs.aligned import load_aligned
from endocal.sim import SimConfig
from endocal.validation.data import axis_data
from endocal.validation.offline import validate_offline
from tests.test_validation_closed_loop import SCAN_SAMPLES, _record, follow, printed_refit, start_for
from tests.test_validation_hidden import NO_SLACK, simulate
from tests.test_validation_user_style import HIDDEN

pytestmark = pytest.mark.slow

#: The plant's friction: one Bouc-Wen element, no joint friction (nothing with return-point memory).
BOUC_WEN_PLANT = {"tendon": {"friction": "bouc-wen"}, "bending": {"friction_nmm": 0.0}}
#: What every case's plant has besides its hidden effect (see the module docstring).
PLANT_HAS = {"delay", "coupling", "load", "envelope"}
#: The issue's bar: the loop ends within this factor of the noise floor.
NOISE_BAR = 1.2


@dataclass
class BaseLoop:
    """What one loop did: the start, the bases and effects it refitted with, in order, and its end."""

    start: str
    bases: list = field(default_factory=list)
    named: list = field(default_factory=list)
    steps: list = field(default_factory=list)
    added: int = 0
    end_label: str = ""
    end_deg: float = float("nan")
    noise_deg: float = float("nan")
    end_noise_deg: float = float("nan")
    clean: bool = False
    next_said: str = ""


#: Bouc-Wen elements of other shapes than the suite's (``bouc_wen_sigma``, ``bouc_wen_lag_deg``; the suite's plant
#: is 1.0 and 20): docs/evidence/hidden-effects.md#closed-loop-bases-variants
VARIANTS = {"sigma3-lag12": (3.0, 12.0)}


def plant(variant: str | None = None) -> dict:
    """The simulator sections of the Bouc-Wen plant (:data:`BOUC_WEN_PLANT`), or of one of its :data:`VARIANTS`."""
    if variant is None:
        return BOUC_WEN_PLANT
    sigma, lag_deg = VARIANTS[variant]
    return {**BOUC_WEN_PLANT, "tendon": {**BOUC_WEN_PLANT["tendon"], "bouc_wen_sigma": sigma,
                                         "bouc_wen_lag_deg": lag_deg}}


@functools.lru_cache(maxsize=None)
def run_loop(hidden: str | None, variant: str | None = None) -> BaseLoop:
    """The recipe of tests/test_validation_closed_loop.py on the Bouc-Wen plant (or a variant), with base changes."""
    cfg = SimConfig.default().replace(**NO_SLACK).replace(**plant(variant)).replace(**HIDDEN.get(hidden, {}))
    est = [simulate(cfg, "damped-sine", {}, seed=0)[0], simulate(cfg, "chirp", {"amplitude_deg": 50.0}, seed=0)[0]]
    val, noise = simulate(cfg, "random", {"amplitude_deg": 60.0}, seed=0)
    val = [val]
    base, effects = start_for(hidden)
    model = make_model(base, effects, axis="ap").fit(axis_data(est, "ap"))
    out = BaseLoop(start="+".join([base, *effects]), noise_deg=noise)
    tmp = Path(tempfile.mkdtemp(prefix=f"loop-bases-{hidden}-"))
    res = None
    for _ in range(14):  # a bound the loop never reaches: two recordings, a refit per effect, a base change or two
        res = validate_offline(model, val, train=est, model_path=str(tmp / "m.json"), max_scan_samples=SCAN_SAMPLES)
        out.steps.append((model.base_name, [e.label for e in model.effects_], res.scan.baseline_rmse_heldout_deg))
        print(f"loop {hidden or 'control'} step: {out.steps[-1]}, bases suggested "
              f"{[(b.base, round(b.gain_pct)) for b in res.scan.base_suggestions]}, effects suggested "
              f"{[(s.effect, round(s.gain_pct)) for s in res.suspects]}", flush=True)
        change = res.scan.base_suggestions[0] if res.scan.base_suggestions else None
        if res.scan.base_first:  # the summary's next refit is the base change (validation.bases.base_before_effect)
            out.bases.append(change.base)
            out.named += list(change.added)  # a change that needs an effect beside it brings it (validation.bases)
            base = change.base
            model = printed_refit(change.refit, model, est)
            continue
        step = follow(res, base, model, cfg, est, val, tmp, out)
        if step is None:
            break
        model, est, val = step
    else:
        raise AssertionError(f"the loop on {hidden or 'the control'} did not end in 14 turns: {out.steps}")
    out.clean = bool(res.clean)
    # the loop ends on a validate of the model, estimation and validation records it ends with: its scores are the end
    out.end_label, out.end_deg = res.model["label"], res.scan.baseline_rmse_heldout_deg
    out.end_noise_deg = noise if out.added == 0 else record_noise(cfg, tmp, out.added)
    print(f"loop {hidden or 'control'}: {_summary(out)}")  # the numbers of the evidence page (pytest -s)
    return out


def record_noise(cfg: SimConfig, tmp: Path, k: int) -> float:
    """The noise floor (deg) of the loop's k-th validation record: its plan recorded again, with the same seed,
    by a tracker without noise."""
    quiet = cfg.replace(tracker={"noise_mm": 0.0, "orientation_noise_deg": 0.0})
    a = load_aligned(tmp / f"val-{k}").table["ap_meas_deg"].to_numpy()
    b = _record(quiet, tmp / f"next-{k}.toml", 200 + k, tmp / f"val-{k}-quiet").table["ap_meas_deg"].to_numpy()
    return float(np.sqrt(np.mean((a - b) ** 2)))


def _summary(loop: BaseLoop) -> tuple:
    return (loop.start, loop.bases, loop.named, loop.added, [(b, e, round(r, 3)) for b, e, r in loop.steps],
            loop.end_label, round(loop.end_deg, 3), round(loop.end_noise_deg, 3), round(loop.noise_deg, 3),
            loop.next_said)


def _names(loop: BaseLoop) -> set[str]:
    return {e.partition(":")[0] for e in loop.named}


#: Cases measured above the 1.2x bar: none since the other bend follows this one through its anchors
#: (`coupling_mutual`, 2026-12-07, seed 0). `coupling` (stronger cross-talk: each bend shifts the other's tendon
#: anchors) ends on a single-knob speed ladder whose other bend spans 32 deg with its knob still; with this axis's
#: anchors shifted by the other knob's drive, not the other bend, it ended at 1.94x. A case that misses goes here with
#: its measured end, as a strict xfail. The floor on the ladder itself: tests/test_friction_family_limits.py
#: (`dahl` with `envelope:tip` 1.13x in-sample).
NOISE_GAPS: dict[str, str] = {}


def _gaps(gaps: dict, cases) -> list:
    return [pytest.param(h, marks=pytest.mark.xfail(strict=True, raises=AssertionError, reason=gaps[h]))
            if h in gaps else h for h in cases]


CASES = [None, *HIDDEN]


@pytest.mark.parametrize("hidden", CASES, ids=lambda h: h or "control")
def test_the_loop_names_the_base_change(hidden):
    loop = run_loop(hidden)
    assert loop.bases and not BASES[loop.bases[-1]].return_point_memory, _summary(loop)


@pytest.mark.parametrize("hidden", _gaps(NOISE_GAPS, CASES), ids=lambda h: h or "control")
def test_the_loop_ends_within_the_bar_of_the_noise(hidden):
    loop = run_loop(hidden)
    assert loop.end_deg <= NOISE_BAR * loop.end_noise_deg, _summary(loop)


@pytest.mark.parametrize("hidden", CASES, ids=lambda h: h or "control")
def test_the_loop_adds_nothing_the_plant_lacks(hidden):
    loop = run_loop(hidden)
    assert _names(loop) <= PLANT_HAS | ({hidden} if hidden else set()), _summary(loop)


@pytest.mark.parametrize("hidden", HIDDEN)
def test_the_loop_names_the_hidden_effect(hidden):
    loop = run_loop(hidden)
    assert hidden in _names(loop) | {e for _, effects, _ in loop.steps for e in effects}, _summary(loop)


def test_the_bars_of_the_issue():
    """Every case names the base change and adds nothing the plant lacks; the hidden effect named in at least
    7 of 8 (the 1.2x noise bar per case: test_the_loop_ends_within_the_bar_of_the_noise)."""
    loops = {h: run_loop(h) for h in CASES}
    named = [h for h in HIDDEN if h in _names(loops[h])]
    assert len(named) >= 7, {h: _summary(lp) for h, lp in loops.items()}
    assert np.all([bool(lp.bases) for lp in loops.values()])
    assert all(_names(lp) <= PLANT_HAS | ({h} if h else set()) for h, lp in loops.items())


@pytest.mark.parametrize("hidden", ["creep", "deadzone"])
def test_a_sharper_element_keeps_its_base_change_names_the_effect_and_adds_nothing_it_lacks(hidden):
    """σ 3, a 12° lag (:data:`VARIANTS`); on 2026-12-07, with the other bend driven as the model drives this axis and
    the printed refit's second start from scratch, they end at 1.13x (`creep`) and 1.04x (`deadzone`) their records'
    noise (1.49x before, in one of two runs). `creep` (-53 %, the plant's 2 s relaxation) carries the caution that no
    record holds the knob still; it ranked after `rate:friction` (-14 %), which the loop then added though the plant
    lacks it: a caution that says only what would confirm the term now gives way where the term beats the first other
    one's refit by 10 % in a paired test (validation.ambiguity.cautioned_last). `deadzone`'s loop changed to
    `bouc-wen` with `deadzone:tip`, then turned back to `bspline` (-19 %) on the sheath-wrap record, which holds no
    small reversal: a change of memory rule is now judged only where the records hold them
    (validation.bases.memory_veto)."""
    loop = run_loop(hidden, "sigma3-lag12")
    assert loop.bases and not BASES[loop.bases[-1]].return_point_memory, _summary(loop)
    assert hidden in _names(loop) and _names(loop) <= PLANT_HAS | {hidden}, _summary(loop)
    assert loop.end_deg <= NOISE_BAR * loop.end_noise_deg, _summary(loop)
