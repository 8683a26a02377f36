"""`fit hysteresis` and `validate` on any records a user may bring: a result or one clear line, never a traceback.

Issue 27.4: real recordings of a tendon-driven robot (two estimation records, decaying sines at
0.1 and 0.2 Hz, and a validation record at 0.5 Hz) ended `validate` in a traceback
(``zero-size array to reduction operation maximum`` in the creep check of the scan). The property
tested here: over combinations of estimation and validation records (one to three, one or two;
different frequencies; decaying or steady amplitudes; cut anywhere, mid-cycle or to a few
samples; a clock from zero or not), every command ends with exit code 0, or with exit code 2 and
one line on stderr. Records come from the simulator (small: 20 Hz, a few cycles, each ending in a
hold as a recording stops) and from the real piezo slice (`data_samples/piezo`, its 1 Hz cycles
stretched in time to 0.5 and 0.2 Hz). The commands run in-process through the real CLI.

Hypothesis is derandomized (the same examples every run) and bounded to a few examples per
source; each costs a fit and a scan of about 600 samples.
"""

from __future__ import annotations

import functools
import json
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from endocal.cli import app
from endocal.cli import commands  # noqa: F401  (registers the subcommands)
from endocal.probe import PRESETS
from endocal.runs.aligned import align, load_aligned
from endocal.sim import SimConfig, Simulator

TEE = PRESETS["tee"]
PIEZO = Path(__file__).resolve().parents[1] / "data_samples" / "piezo" / "piezo_aligned.csv"
runner = CliRunner()
SETTINGS = settings(max_examples=7, derandomize=True, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

#: Simulated records: frequency (Hz) -> cycles (each record 12-30 s at 20 Hz).
SIM_FS_HZ = 20.0
SIM_CYCLES = {0.1: 3, 0.2: 4, 0.5: 6}
HOLD_S = 3.0  # a recording stops with the knob at rest


@functools.lru_cache(maxsize=None)
def sim_record(f_hz: float, decaying: bool) -> pd.DataFrame:
    """Aligned table of a sine at ``f_hz`` on axis ap (60 deg, decaying to 1/e over the record, or steady),
    then a hold."""
    n_move = int(SIM_CYCLES[f_hz] / f_hz * SIM_FS_HZ)
    t = np.arange(n_move + int(HOLD_S * SIM_FS_HZ)) / SIM_FS_HZ
    tau = t[n_move] if decaying else np.inf
    u = 60.0 * np.sin(2 * np.pi * f_hz * np.minimum(t, t[n_move])) * np.exp(-np.minimum(t, t[n_move]) / tau)
    goal = {d: np.zeros_like(t) for d in TEE.dofs}
    goal["ap"] = u
    chunk = Simulator(SimConfig.default(), TEE, seed=int(10 * f_hz) + decaying).execute(t, goal)
    table = align(pd.DataFrame(chunk.motor), pd.DataFrame(chunk.tracker), TEE).table
    return table[["t_s", "ap_cmd_deg", "ap_meas_deg", "ml_cmd_deg", "ml_meas_deg"]]


@functools.lru_cache(maxsize=None)
def piezo_table() -> pd.DataFrame:
    return load_aligned(PIEZO).table


def piezo_record(first_cycle: int, n_cycles: int, stretch: float) -> pd.DataFrame:
    """``n_cycles`` 1 Hz cycles of the piezo slice from ``first_cycle``, at 50 Hz, their clock stretched
    ``stretch`` times (1 Hz becomes 1 / stretch Hz)."""
    part = piezo_table().iloc[200 * first_cycle: 200 * (first_cycle + n_cycles): 4].copy()
    part["t_s"] = (part["t_s"] - part["t_s"].iloc[0]) * stretch
    return part.reset_index(drop=True)


def cut(table: pd.DataFrame, start_frac: float, length_frac: float, rezero: bool) -> pd.DataFrame:
    """Rows ``[start, start + length)`` as fractions of the record (mid-cycle cuts), at least two rows."""
    n = len(table)
    a = int(start_frac * n)
    b = min(n, a + max(2, int(length_frac * n)))
    part = table.iloc[a:b].copy()
    if rezero:
        part["t_s"] -= part["t_s"].iloc[0]
    return part.reset_index(drop=True)


def _cli(*args) -> tuple[int, str]:
    """Run an endocal command in-process; a traceback (any exception the CLI did not turn into an exit) fails."""
    res = runner.invoke(app, [str(a) for a in args])
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        raise AssertionError(f"endocal {' '.join(map(str, args))} ended in a traceback") from res.exception
    assert res.exit_code in (0, 2), (res.exit_code, res.output)
    if res.exit_code == 2:
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and len(lines[0]) > 20, res.stderr
    return res.exit_code, res.stdout


def fit_and_validate(est: list[pd.DataFrame], val: list[pd.DataFrame], axis: str, fallback: pd.DataFrame,
                     as_json: bool) -> None:
    """`fit hysteresis` on ``est``, then `validate` on ``val`` with the records the model names; when the fit
    refuses ``est`` (one line), a model fitted on ``fallback`` is validated with ``--train`` ``est``."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        est_paths = [tmp / f"est{i}.csv" for i in range(len(est))]
        val_paths = [tmp / f"val{i}.csv" for i in range(len(val))]
        for table, path in zip([*est, *val], [*est_paths, *val_paths]):
            table.to_csv(path, index=False)
        model = tmp / "m.json"
        code, _ = _cli("fit", "hysteresis", *est_paths, "--axis", axis, "--model", "linear", "--out", model)
        train = []
        if code != 0:  # the estimation records cannot be fitted: a model from elsewhere, these records as --train
            fallback.to_csv(tmp / "full.csv", index=False)
            code, _ = _cli("fit", "hysteresis", tmp / "full.csv", "--axis", axis, "--model", "linear", "--out", model)
            assert code == 0
            train = [x for p in est_paths for x in ("--train", p)]
        code, stdout = _cli("validate", model, *val_paths, *train, *(["--json"] if as_json else []))
        if code == 0 and as_json:
            json.loads(stdout)


def _cuts(draw, start_max: float, length_min: float):
    """None (the whole record), or where to cut it: start and length as fractions, clock from zero or not."""
    if not draw(st.booleans()):
        return None
    return draw(st.floats(0.0, start_max)), draw(st.floats(length_min, 1.0)), draw(st.booleans())


def _materialize(specs, make) -> list[pd.DataFrame]:
    return [make(*spec[:-1]) if spec[-1] is None else cut(make(*spec[:-1]), *spec[-1]) for spec in specs]


@st.composite
def sim_plans(draw):
    """Estimation and validation records as (frequency, decaying, cut), and whether to ask for --json."""
    def records(n_max):
        return [(draw(st.sampled_from(sorted(SIM_CYCLES))), draw(st.booleans()), _cuts(draw, 0.7, 0.01))
                for _ in range(draw(st.integers(1, n_max)))]

    return records(3), records(2), draw(st.booleans())


@SETTINGS
@given(sim_plans())
# the shape: decaying sines at 0.2 and 0.1 Hz to fit (the shorter first), one at 0.5 Hz to validate
@example(([(0.2, True, None), (0.1, True, None)], [(0.5, True, None)], False))
# records cut to a few samples: an estimation record without a reversal, a validation record of 3 rows
@example(([(0.5, False, (0.0, 0.02, True))], [(0.2, True, None)], True))
@example(([(0.1, True, None)], [(0.5, True, (0.5, 0.01, False))], False))
def test_simulated_records_of_any_frequency_and_cut_end_in_a_result_or_one_line(plan):
    est, val, as_json = plan
    fit_and_validate(_materialize(est, sim_record), _materialize(val, sim_record), "ap", sim_record(0.1, True), as_json)


@st.composite
def piezo_plans(draw):
    """Records as (first cycle, cycles, time stretch, cut): 1 Hz cycles played at 1, 0.5 or 0.2 Hz."""
    def records(n_max):
        return [(draw(st.integers(0, 17)), draw(st.integers(1, 3)), draw(st.sampled_from([1.0, 2.0, 5.0])),
                 _cuts(draw, 0.6, 0.05)) for _ in range(draw(st.integers(1, n_max)))]

    return records(3), records(2), draw(st.booleans())


@SETTINGS
@given(piezo_plans())
# a cycle stretched to 0.2 Hz and cut to a few samples to fit; a mid-cycle cut of 0.05 of a cycle to validate
@example(([(3, 1, 5.0, (0.5, 0.02, True))], [(10, 2, 1.0, None)], False))
@example(([(0, 2, 2.0, None), (5, 3, 5.0, (0.3, 0.5, False))], [(12, 1, 1.0, (0.4, 0.05, True))], True))
def test_real_piezo_records_of_any_frequency_and_cut_end_in_a_result_or_one_line(plan):
    est, val, as_json = plan
    fit_and_validate(_materialize(est, piezo_record), _materialize(val, piezo_record), "piezo", piezo_record(0, 3, 1.0),
                     as_json)
