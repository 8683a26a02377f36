"""Per-tick cost of the exported C compensator (issue 34, part 4). Prints; asserts nothing.

Target: the C step of a 20-operator PI takes <= 1 µs per tick on this machine. The reference,
measured in the same run on the same desired trajectory: the Python streaming compensator's
``step`` (what a Python loop pays per tick). Both start from rest; the C loop runs inside one
ctypes call (``PREFIX_run`` of :func:`endocal.export.c.compile_c`: init, then ``step`` per
sample into an array), so the time is the step's own, not ctypes'.

Models: the paper's modified PI (20 operators, 21 plays, table 1 with the envelope, eqs. 9-11),
and the same with tendon slack (``deadzone``) and tension friction; double and float.

Run: ``.venv/bin/python bench/bench_export_c.py``
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from endocal.export.c import compile_c, find_c_compiler, generate_c
from endocal.models import make_model

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests._models_signals import PAPER_TABLE1  # noqa: E402

N_C = 2_000_000  # ticks through C (33 min of a 1 kHz loop)
N_PY = 20_000  # ticks through Python


def best_of(fn, repeat=5) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def desired(n: int) -> np.ndarray:
    """A 1 kHz desired bend: sines of 0.05-0.7 Hz, +-40 deg, with holds (what a protocol asks)."""
    t = np.arange(n) / 1000.0
    y = 25 * np.sin(2 * np.pi * 0.05 * t) + 10 * np.sin(2 * np.pi * 0.31 * t + 1) + 5 * np.sin(2 * np.pi * 0.7 * t)
    hold = (t % 20) > 17
    for k in np.flatnonzero(hold):
        y[k] = y[k - 1]
    return y


def main() -> None:
    if find_c_compiler() is None:
        print("no C compiler ($CC, cc, gcc, clang): nothing to measure")
        return
    cases = {
        "pi20+envelope": (["envelope"], {}),
        "pi20+envelope+deadzone+tension": (["envelope", "deadzone", "tension"],
                                           {"deadzone_slack_deg": 4.0, "deadzone_band_deg": 6.0,
                                            "deadzone_center_deg": 3.7, "tension_friction": 0.06}),
    }
    y_c = desired(N_C)
    y_py = y_c[:N_PY]
    print(f"{'model':<32} {'arith':<6} {'C us/tick':>10} {'Python us/tick':>15} {'Python/C':>9}  "
          f"max |C - Python| deg (ticks > 1e-3 of {N_PY})")
    with tempfile.TemporaryDirectory() as tmp:
        for label, (effects, extra) in cases.items():
            m = make_model("pi", effects).set_parameters({**PAPER_TABLE1, **extra}, cmd_range_deg=(-100, 100))
            assert m.structure_["n_operators"] == 20
            comp = m.compensator()
            comp.step(0.0)  # compile the numba kernels before timing

            def python_loop():
                c = m.compensator()
                return [c.step(v) for v in y_py]

            t_py = best_of(python_loop, repeat=3) / N_PY
            ref = np.array(python_loop())
            for real in ("double", "float"):
                lib = compile_c(generate_c(m, real=real), Path(tmp) / f"{label}-{real}")
                t_c = best_of(lambda: lib.run(y_c)) / N_C
                diff = np.abs(lib.run(y_py)[0] - ref)
                print(f"{label:<32} {real:<6} {t_c * 1e6:>10.3f} {t_py * 1e6:>15.2f} {t_py / t_c:>9.0f}  "
                      f"{diff.max():.2e} ({int((diff > 1e-3).sum())})")
    print("target: C <= 1 us/tick for 20 operators. A float play (deadzone, tension) jumps a tick after double where "
          "the desired angle turns back by less than float's resolution (warning[float-holds])")


if __name__ == "__main__":
    main()
