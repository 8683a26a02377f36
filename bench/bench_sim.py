"""Speed of the physics simulator, printed (asserts nothing).

    .venv/bin/python bench/bench_sim.py [--hours 1.0] [--python-seconds 20]

Prints
  * the whole simulator (motors, both tendon axes, tracker, truth) as a multiple of real time
    on one hour of 100 Hz ticks, played in 100 s chunks as ``endocal excite`` does (numba
    compile excluded: a warm-up call runs first; the target is >= 1000x, i.e. < 3.6 s);
  * the compiled tendon step against the same code run as plain Python (numba's
    ``NUMBA_DISABLE_JIT=1``, in a subprocess of this run, on a shorter stretch, extrapolated
    per tick).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

FS_HZ = 100.0


def _goals(t):
    return {"ap": 70 * np.sin(2 * np.pi * 0.05 * t), "ml": 50 * np.sin(2 * np.pi * 0.031 * t + 1.0),
            "translation": 20 * np.sin(2 * np.pi * 0.01 * t), "rotation": 30 * np.sin(2 * np.pi * 0.007 * t)}


def measure(seconds: float, chunk_s: float = 100.0) -> dict:
    """Wall time of the whole simulator and of its tendon kernel over ``seconds`` of run."""
    from endocal.probe import PRESETS
    from endocal.sim import SimConfig, Simulator, tendon
    import endocal.sim.simulator as simulator_module

    probe = PRESETS["tee"]
    t = np.arange(int(round(seconds * FS_HZ))) / FS_HZ
    g = _goals(t)
    Simulator(SimConfig.default(), probe).execute(t[:10], {k: v[:10] for k, v in g.items()})  # compile / load cache
    kernel = tendon.simulate_ticks
    spent = [0.0]

    def timed(*args):
        t0 = time.perf_counter()
        kernel(*args)
        spent[0] += time.perf_counter() - t0

    simulator_module.tendon.simulate_ticks = timed
    try:
        sim = Simulator(SimConfig.default(), probe, seed=0)
        n = max(1, int(round(chunk_s * FS_HZ)))
        t0 = time.perf_counter()
        for a in range(0, t.size, n):
            sim.execute(t[a:a + n], {k: v[a:a + n] for k, v in g.items()})
        total = time.perf_counter() - t0
    finally:
        simulator_module.tendon.simulate_ticks = kernel
    return {"ticks": int(t.size), "sim_s": seconds, "wall_s": total, "kernel_s": spent[0]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=1.0, help="simulated duration for the compiled run (h)")
    ap.add_argument("--python-seconds", type=float, default=20.0, help="simulated duration for the plain-Python run (s)")
    ap.add_argument("--_child", type=float, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args._child is not None:
        print(json.dumps(measure(args._child)))
        return

    fast = measure(args.hours * 3600.0)
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    out = subprocess.run([sys.executable, __file__, "--_child", str(args.python_seconds)], env=env,
                         capture_output=True, text=True, check=True)
    slow = json.loads(out.stdout.strip().splitlines()[-1])

    per_tick_fast = fast["kernel_s"] / fast["ticks"]
    per_tick_slow = slow["kernel_s"] / slow["ticks"]
    print(f"simulator: {fast['sim_s']:.0f} s of 100 Hz ticks (both axes, 4 motors, 40 Hz tracker) "
          f"in {fast['wall_s']:.2f} s wall = {fast['sim_s'] / fast['wall_s']:.0f}x real time "
          f"(target >= 1000x)")
    print(f"  tendon kernel {fast['kernel_s']:.2f} s ({per_tick_fast * 1e6:.2f} us/tick), "
          f"tracker/kinematics/streams {fast['wall_s'] - fast['kernel_s']:.2f} s")
    print(f"plain-Python reference (NUMBA_DISABLE_JIT=1, {slow['sim_s']:.0f} s of ticks): "
          f"{per_tick_slow * 1e6:.0f} us/tick -> {per_tick_slow * fast['ticks']:.0f} s for the same run, "
          f"{fast['sim_s'] / (slow['wall_s'] / slow['ticks'] * fast['ticks']):.1f}x real time")
    print(f"compiled / plain-Python speed-up of the tendon step: {per_tick_slow / per_tick_fast:.0f}x")


if __name__ == "__main__":
    main()
