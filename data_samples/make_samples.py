"""Regenerate data_samples/: small simulator runs and the piezo slice.

    .venv/bin/python data_samples/make_samples.py [DIR]   # DIR: default TMPDIR/endocal-data-samples

`make data-samples` writes them into data_samples/ itself (DIR = data_samples). Without DIR they go
to a folder outside the repository (printed), to compare with the shipped ones before replacing
them. The runs are deterministic: the same endocal version and seed give the same numbers.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
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


def make_runs(out: Path) -> None:
    for folder, protocol, extra in RUNS:
        cmd = [sys.executable, "-m", "endocal", "excite", protocol, "--out", str(out / folder), "--force", "--quiet",
               *extra]
        subprocess.run(cmd, check=True)


def make_piezo(out: Path, rows: int = 4000, rate_hz: float = 200.0) -> None:
    """First `rows` samples of the piezo measurement as an aligned table (see piezo/README.md)."""
    if not PIEZO_SOURCE.exists():
        print(f"skipping the piezo slice: {PIEZO_SOURCE} not found", file=sys.stderr)
        return
    raw = np.loadtxt(PIEZO_SOURCE)
    df = pd.DataFrame({"t_s": np.arange(rows) / rate_hz, "piezo_cmd_deg": raw[:rows, 0], "piezo_meas_deg": raw[:rows, 4]})
    (out / "piezo").mkdir(parents=True, exist_ok=True)
    df.to_csv(out / "piezo" / "piezo_aligned.csv", index=False, float_format="%.6f")


def default_dir() -> Path:
    """Where the samples go without DIR: outside any checkout, in the system's temporary folder."""
    return Path(tempfile.gettempdir()) / "endocal-data-samples"


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    make_runs(out)
    make_piezo(out)
    print(f"wrote {', '.join(f for f, _, _ in RUNS)} and piezo/piezo_aligned.csv in {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else default_dir())
