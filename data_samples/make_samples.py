"""Regenerate data_samples/: small simulator runs and the piezo slice.

Run with `make data-samples` (or `.venv/bin/python data_samples/make_samples.py`). The runs are
deterministic: the same endocal version and seed give the same numbers.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
PIEZO_SOURCE = HERE.parents[1] / "shared" / "data" / "piezo" / "Model_Vi_Do.dat"

# (folder, protocol, extra arguments): short runs the README's examples use.
RUNS = [
    ("sim-damped-sine", "damped-sine", ["--seed", "1"]),
    ("sim-triangle", "triangle", ["--seed", "2"]),
]


def make_runs() -> None:
    for folder, protocol, extra in RUNS:
        cmd = [sys.executable, "-m", "endocal", "excite", protocol, "--out", folder, "--force", "--quiet", *extra]
        subprocess.run(cmd, check=True, cwd=HERE)


def make_piezo(rows: int = 4000, rate_hz: float = 200.0) -> None:
    """First `rows` samples of the piezo measurement as an aligned table (see piezo/README.md)."""
    if not PIEZO_SOURCE.exists():
        print(f"skipping the piezo slice: {PIEZO_SOURCE} not found", file=sys.stderr)
        return
    raw = np.loadtxt(PIEZO_SOURCE)
    df = pd.DataFrame({"t_s": np.arange(rows) / rate_hz, "piezo_cmd_deg": raw[:rows, 0], "piezo_meas_deg": raw[:rows, 4]})
    df.to_csv(HERE / "piezo" / "piezo_aligned.csv", index=False, float_format="%.6f")


if __name__ == "__main__":
    make_runs()
    make_piezo()
