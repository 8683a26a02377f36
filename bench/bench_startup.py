"""Start-up time of the command line: ``endocal --help`` and ``endocal COMMAND --help`` (issue 26). Prints; asserts nothing.

Target: every help screen in at most 0.3 s on this 2-core machine. Each is a fresh child
process (what a shell, a typo or a tab completion pays), timed as the best of N runs, beside
two references measured in the same run: ``python -c pass`` (the interpreter alone) and the
help screen of a one-command Typer app with endocal's settings (the floor of any Typer
command line: typer and its vendored Click; help in Click's plain format, no rich). What ``--help`` may
import is asserted by ``tests/test_cli_startup.py``; this file only times it.

Run: ``.venv/bin/python bench/bench_startup.py [--runs 7]``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

#: The help screens timed: the root, every command and every subcommand group's members that
#: a user reaches first (the subcommands of one group share their group's imports).
COMMANDS = (
    (),
    ("excite",),
    ("fit", "planes"),
    ("fit", "hysteresis"),
    ("validate",),
    ("report",),
    ("import", "csv"),
    ("emulate", "rig"),
    ("protocols", "show"),
)
TARGET_S = 0.3

#: The reference: the smallest Typer app rendering its help as endocal's does (plain Click format).
TYPER_FLOOR = """
import typer
app = typer.Typer(rich_markup_mode=None, add_completion=False)
@app.command()
def hello(name: str = typer.Option("x", help="A name.")) -> None:
    \"\"\"Say hello.\"\"\"
app(["--help"], prog_name="hello")
"""


def best_of(argv: list[str], runs: int) -> tuple[float, float]:
    """Shortest wall time and shortest CPU time (user + system) of ``runs`` child processes running ``argv`` (s).

    The CPU time is what the process itself spent; on a shared machine it moves less than the
    wall time, which also counts the waits for a core. The process is single-threaded and reads
    cached files, so on an idle machine its wall time is close to its CPU time.
    """
    wall, cpu = float("inf"), float("inf")
    for _ in range(runs):
        t0 = time.perf_counter()
        proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = min(wall, time.perf_counter() - t0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != 0:
            raise SystemExit(f"{' '.join(argv)} exited with {proc.returncode}")
        cpu = min(cpu, usage.ru_utime + usage.ru_stime)
    return wall, cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=7, help="child processes per command; the best is kept")
    runs = ap.parse_args().runs

    py = sys.executable
    best_of([py, "-m", "endocal", "--help"], 1)  # bytecode caches written before anything is timed
    t_pass, c_pass = best_of([py, "-c", "pass"], runs)
    t_typer, c_typer = best_of([py, "-c", TYPER_FLOOR], runs)
    print(f"reference: python -c pass {t_pass:.3f} s (cpu {c_pass:.3f} s); "
          f"a one-command Typer app's --help {t_typer:.3f} s (cpu {c_typer:.3f} s)")
    worst, worst_cpu = 0.0, 0.0
    for args in COMMANDS:
        t, c = best_of([py, "-m", "endocal", *args, "--help"], runs)
        worst, worst_cpu = max(worst, t), max(worst_cpu, c)
        print(f"endocal {' '.join((*args, '--help')):<26} {t:.3f} s (cpu {c:.3f} s)  "
              f"{t / t_pass:4.1f}x python -c pass, {t / t_typer:.1f}x the Typer floor")
    print(f"slowest help screen: {worst:.3f} s wall, {worst_cpu:.3f} s cpu (target <= {TARGET_S} s; best of {runs} "
          "runs each; on a busy machine the cpu time is the better estimate of the wall time on an idle one)")


if __name__ == "__main__":
    main()
