"""Speed of a fit's least squares on its compressed form (endocal.models.lsq). Prints; asserts nothing.

Each model below is fitted on the demo's estimation records (scripts/demo.sh's damped sine and chirp,
26 000 samples) twice in the same run, alternating: as every fit runs (the compressed form) and with the
plain reference, scipy's ``least_squares`` on the full residual and Jacobian (what every fit ran before
2026-12-08). Both fits end at the same RMSE and evaluation count (printed); the ratio is of their medians.

Run: ``.venv/bin/python bench/bench_lsq.py [--runs 3]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
os.environ.setdefault("ENDOCAL_JOBS", "1")

import endocal.models.base as base  # noqa: E402
from bench_loop import records  # noqa: E402
from endocal.models import make_model  # noqa: E402
from endocal.runs.aligned import load_aligned  # noqa: E402
from endocal.validation.data import axis_data  # noqa: E402

MODELS = [("pi", ["envelope"]), ("bspline", ["delay", "deadzone"]), ("bspline", ["creep"]), ("pi", ["envelope", "deadzone"])]


COMPRESSED = base._solve


def plain(fns, x0, bounds, max_nfev):
    """The reference: the same solve on the full residual and Jacobian (``both`` withheld), as every fit ran it
    before compressing."""
    return COMPRESSED(fns._replace(both=None), x0, bounds, max_nfev)


def timed_fit(data, model: tuple, solve) -> tuple[float, float, int]:
    keep = base._solve
    base._solve = solve
    try:
        t = time.perf_counter()
        fitted = make_model(model[0], model[1], axis="ap").fit(data)
        return time.perf_counter() - t, fitted.fit_report_.rmse_deg, fitted.fit_report_.nfev
    finally:
        base._solve = keep


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        paths = records(Path(tmp))
        data = axis_data([load_aligned(paths["train"]), load_aligned(paths["chirp"])], "ap")
    timed_fit(data, MODELS[0], COMPRESSED)  # the kernels compiled (or loaded from numba's cache) once
    print(f"fits on the demo's estimation records ({data.n_samples} samples), median of {args.runs} runs, one core:")
    print(f"  {'model':28s} {'compressed s':>12s} {'plain s':>9s} {'ratio':>6s}  RMSE deg (compressed / plain), evaluations")
    for model in MODELS:
        new, old = [], []
        for _ in range(args.runs):
            t_new, rmse_new, nfev_new = timed_fit(data, model, COMPRESSED)
            t_old, rmse_old, nfev_old = timed_fit(data, model, plain)
            new.append(t_new)
            old.append(t_old)
        a, b = statistics.median(new), statistics.median(old)
        name = "+".join([model[0], *model[1]])
        print(f"  {name:28s} {a:12.2f} {b:9.2f} {a / b:6.2f}  {rmse_new:.6f} / {rmse_old:.6f}, {nfev_new} / {nfev_old}")


if __name__ == "__main__":
    main()
