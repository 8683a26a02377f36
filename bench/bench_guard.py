"""Cost of the contact-force guard per control tick (issue 13). Prints; asserts nothing.

Target: the guard's check adds <= 20 µs per control tick. Measured in the same run against
the unguarded tick as reference:

1. ``ForceGuard.step`` alone, per call (what the hardware tick loop adds);
2. the simulator's tick unguarded (compiled chunk) and guarded (stepped tick by tick with
   the guard between ticks), per tick, and their ratio (what ``excite --force-model`` costs
   on the simulator).

The force model is fitted here on short simulated calibration runs (no files needed).

Run: ``.venv/bin/python bench/bench_guard.py``
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from endocal.backends.sim import SimBackend
from endocal.excite import prepare_backend, run_excitation
from endocal.force import ForceGuard, fit_force
from endocal.probe import load_probe
from endocal.protocols import load_protocol
from endocal.sim import SimConfig, Simulator


def calibrate(root: Path):
    probe = load_probe("tee")
    proto = load_protocol("force-calibration")
    traj = proto.trajectory(probe, seed=0)
    runs = []
    for i, load in enumerate([0.0, 0.5, 1.0, 1.5]):
        be, rec = prepare_backend(SimBackend(None, probe, seed=i), proto, probe, tip_load_n=load)
        run_excitation(traj, be, probe, root / f"cal{i}", protocol_info={**proto.to_dict(), **rec}, seed=i, force=True)
        runs.append(root / f"cal{i}")
    return fit_force(runs), probe


def best_of(fn, repeat=5) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        model, probe = calibrate(Path(tmp))
    # 1. the check alone, on a realistic stream (a pass into the load, noisy current)
    n = 100_000
    rng = np.random.default_rng(0)
    theta = list(np.linspace(10.0, 60.0, n))
    cur = list(np.linspace(20.0, 150.0, n) + 3.0 * rng.standard_normal(n))
    t = list(np.arange(n) * 0.01)

    def run_guard():
        g = ForceGuard(model, 1e9)  # never stops: every tick runs the full check
        step = g.step
        for i in range(n):
            step(t[i], theta[i], 24.0, cur[i], theta[i] + 0.5)

    guard_us = best_of(run_guard) / n * 1e6

    # 2. simulator ticks, unguarded vs guarded, same goals
    proto = load_protocol("force-threshold")
    traj = proto.trajectory(probe, seed=0)
    cfg = SimConfig.default().replace(contact={"enabled": True, "wall_deg": 20.0})
    goal = {d: traj.goal[d] for d in probe.dofs}

    def sim_plain():
        Simulator(cfg, probe, 0).execute(traj.t_s, goal)

    def sim_guarded():
        Simulator(cfg, probe, 0).execute(traj.t_s, goal, guard=ForceGuard(model, 1e9))

    sim_plain()
    sim_guarded()  # compile / warm up
    m = traj.t_s.size
    plain_us = best_of(sim_plain) / m * 1e6
    guarded_us = best_of(sim_guarded) / m * 1e6
    print(f"ForceGuard.step: {guard_us:.2f} µs per tick (target <= 20 µs)")
    print(f"simulator tick: unguarded {plain_us:.2f} µs, guarded {guarded_us:.2f} µs "
          f"(+{guarded_us - plain_us:.2f} µs per tick, ratio {guarded_us / plain_us:.1f}x; the guarded sim "
          f"steps its compiled kernel once per tick)")
    print(f"guard check vs unguarded simulator tick: ratio {guard_us / plain_us:.2f}")


if __name__ == "__main__":
    main()
