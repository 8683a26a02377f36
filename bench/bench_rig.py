"""The control loop on the emulated rig at 200 Hz with two servos, for a minute (issue 14). Prints; asserts nothing.

Target: at most 1 % overruns (a tick beginning more than half a period late) on this 2-core
machine. The emulated rig (servo bus on a pty, Aurora on another, the simulator's probe
between them) runs in this process; `endocal excite --backend hardware` runs as a user runs
it, in its own process, through the real dynamixel-sdk and scikit-surgerynditracker, and
records its timing in run.json. Beside it, in the same run, the plain reference: a loop that
only sleeps until each 5 ms deadline (no bus, no tracker) for 10 s, whose overruns are the
scheduler's own on this machine.

Run: ``.venv/bin/python bench/bench_rig.py``
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from endocal.emulate.rig import EmulatedRig
from endocal.probe import PRESETS

RATE_HZ = 200.0
RUN_S = 60.0


def plain_loop(duration_s: float, rate_hz: float) -> tuple[int, int, float]:
    """Ticks, overruns (late by more than half a period) and the latest tick (ms) of a sleep-paced loop."""
    period = 1.0 / rate_hz
    t0 = time.monotonic()
    n = int(duration_s * rate_hz)
    overruns, worst = 0, 0.0
    for i in range(n):
        deadline = t0 + i * period
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                break
            time.sleep(min(left, 0.001) if left > 0.002 else 0)
        late = time.monotonic() - deadline
        worst = max(worst, late)
        overruns += late > 0.5 * period
    return n, overruns, 1000 * worst


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp, EmulatedRig(PRESETS["tee"], seed=0) as rig:
        cfg = rig.write_config(Path(tmp) / "rig.toml")
        cycles = int(RUN_S * 0.1)
        proc = subprocess.run([sys.executable, "-m", "endocal", "excite", "sine", "--set", "frequency_hz=0.1", "--set",
                               f"cycles={cycles}", "--amplitude", "20", "--sample-rate", str(RATE_HZ), "--backend",
                               "hardware", "--hardware-config", str(cfg), "--out", str(Path(tmp) / "run"), "-q"],
                              capture_output=True, text=True)
        if proc.returncode:
            print(proc.stderr)
            raise SystemExit(1)
        timing = json.loads((Path(tmp) / "run" / "run.json").read_text())["backend"]["timing"]
    n, ref_over, ref_worst = plain_loop(10.0, RATE_HZ)
    print(f"emulated rig, two servos + Aurora, {RUN_S:.0f} s at {RATE_HZ:.0f} Hz (endocal excite --backend hardware):")
    print(f"  achieved {timing['achieved_rate_hz']:.2f} Hz, overruns {timing['overruns']} "
          f"({timing['overrun_pct']:.2f} %, target <= 1 %), latest tick {timing['max_late_ms']:.1f} ms late")
    print(f"  plain sleep-paced loop, 10 s at {RATE_HZ:.0f} Hz: overruns {ref_over} of {n} ({100 * ref_over / n:.2f} %), "
          f"latest tick {ref_worst:.1f} ms late")


if __name__ == "__main__":
    main()
