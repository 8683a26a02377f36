"""Speed of the effect scan of `endocal validate` (issue 5). Prints; asserts nothing.

Target: scanning all catalog effects on 60 000 samples of one axis in at most 30 s on one
core. The record is 600 s of the simulator at 100 Hz: both knobs follow independent
band-limited random inputs at once, the first knob holding still for 4 s every 30 s, under a
varying sheath wrap, with a delay and the wrap's load hidden; the model a B-spline. Every
catalog effect is testable on it (several frequencies, holds, the other knob moving, a
varying covariate) and every rolling-origin block holds the same kinds of motion, so the
scan must also find the two hidden effects. Beside it, a naive reference in the same run: every candidate refitted
from scratch on every fold at full resolution, with no screening; to keep the bench short
it is timed on two candidates and scaled to the full candidate list (the per-candidate cost
is what the scan saves).

Run: ``OPENBLAS_NUM_THREADS=1 taskset -c 0 .venv/bin/python bench/bench_scan.py``
"""

from __future__ import annotations

import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from endocal.models import make_model  # noqa: E402
from endocal.probe import PRESETS  # noqa: E402
from endocal.protocols import load_protocol  # noqa: E402
from endocal.runs.aligned import AlignedData, align, check_aligned  # noqa: E402
from endocal.sim import SimConfig, Simulator  # noqa: E402
from endocal.validation.data import axis_data  # noqa: E402
from endocal.validation.folds import fold_bounds, heldout_errors  # noqa: E402
from endocal.validation.scan import scan_effects  # noqa: E402

TEE = PRESETS["tee"]


def record():
    """The bench's 60 000-sample record of axis ap (HysteresisData)."""
    cfg = SimConfig.default().replace(deadzone={"enabled": False}, delay={"enabled": True}, load={"enabled": True})
    traj = load_protocol("random", overrides={"duration_s": 600.0, "axes": ["axis1"]}).trajectory(TEE, seed=0)
    other = load_protocol("random", overrides={"duration_s": 600.0, "axes": ["axis2"], "amplitude_deg": 30.0})
    goal = dict(traj.goal, ml=other.trajectory(TEE, seed=1).goal["ml"])
    # holds of the first knob (creep is testable only where the knob stops after moving)
    ap = goal["ap"].copy()
    for start in np.flatnonzero((traj.t_s % 30.0 < 0.005) & (traj.t_s > 0)):
        stop = min(start + int(4.0 * traj.sample_rate_hz), ap.size)
        ap[start:stop] = ap[start]
    # the jump back onto the random input after a hold, at most the knob's top speed
    step = TEE.max_knob_speed_dps / traj.sample_rate_hz * 0.99
    for k in range(1, ap.size):
        ap[k] = ap[k - 1] + np.clip(ap[k] - ap[k - 1], -step, step)
    goal["ap"] = ap
    chunk = Simulator(cfg, TEE, seed=0).execute(traj.t_s, goal)
    df = align(pd.DataFrame(chunk.motor), pd.DataFrame(chunk.tracker), TEE).table
    df = df.iloc[:60000]
    return axis_data(AlignedData(df, check_aligned(df, "bench"), "bench", "", {}), "ap")


def main() -> None:
    data = record()
    print(f"data: {data.n_samples} samples of axis ap ({data.t_s[-1] - data.t_s[0]:.0f} s at 100 Hz)")
    model = make_model("bspline", axis="ap").fit(data.decimate(5))
    scan_effects(model, data.decimate(50), folds=3)  # compile the kernels once (numba cache)

    t0 = time.perf_counter()
    res = scan_effects(model, data, bending_axes=TEE.bending_axes)
    scan_s = time.perf_counter() - t0
    n_cand = len(res.tested)
    print(f"scan: {scan_s:.1f} s for {n_cand} candidates x {res.folds} folds on {res.n_samples} samples "
          f"(every {res.stride}th), target <= 30 s")
    print("  suspects: " + (", ".join(f"{s.effect} (-{s.gain_pct:.0f} %)" for s in res.suspects) or "none"))

    # Naive reference: full resolution, every fold, no screening, two candidates timed.
    bounds = fold_bounds(data.n_samples, res.folds)
    t0 = time.perf_counter()
    heldout_errors(model, [], data, bounds)
    base_s = time.perf_counter() - t0
    timed = ["drift", "deadzone"]
    t0 = time.perf_counter()
    for c in timed:
        heldout_errors(model, [c], data, bounds)
    per_cand_s = (time.perf_counter() - t0) / len(timed)
    naive_s = base_s + per_cand_s * n_cand
    print(f"naive reference (refits from scratch at full resolution, all folds, no screening): "
          f"~{naive_s:.0f} s (baseline {base_s:.1f} s + {per_cand_s:.1f} s x {n_cand} candidates, "
          f"timed on {', '.join(timed)})")
    print(f"ratio naive / scan: {naive_s / scan_s:.1f}x")
    print(f"numbers: scan_s={scan_s:.2f} naive_s={naive_s:.1f} samples={data.n_samples} "
          f"baseline_heldout_rmse_deg={res.baseline_rmse_heldout_deg:.3f}")


if __name__ == "__main__":
    main()
