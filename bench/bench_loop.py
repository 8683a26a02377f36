"""Speed of one turn of the user's loop: ``endocal validate`` on the demo's records (issues 12, 33). Prints; asserts nothing.

Target (issue 33): ``endocal validate`` on the demo's records in at most 2.5 s on this 2-core
machine, timed as a user meets it: a fresh ``endocal`` process, start-up, imports, the scan on
every core and the summary included. The records and the model are scripts/demo.sh's: the damped
sine and the chirp (estimation, 26 000 samples), the random run and the triangle (validation,
18 000 samples), and ``fit hysteresis train chirp --axis ap --model pi --effects envelope``; the
command is ``endocal validate pi-envelope.json test check``. Beside it, in the same run and
alternating with it, the plain reference: ``python -c pass`` (the interpreter's start), and the floor
no endocal code can go under: the libraries ``validate`` runs on imported alone (:data:`LIBRARIES`,
a fresh process). Each
figure is the median of ``--runs`` runs: wall seconds, and CPU seconds of the process and its
scan workers (``RUSAGE_CHILDREN``), which a loaded machine inflates less.

``--vs PATH`` also times a second checkout's ``endocal`` (PATH: a folder holding its ``endocal``
package, e.g. ``git archive main endocal | tar -x -C /tmp/main-code``) in the same alternation:
before and after a change, on the same machine at the same moment.

``--cold`` adds issue 12's comparison (in process, ``pi + envelope + deadzone``): the scan with
warm-started candidates against every candidate fitted from scratch.

Run: ``.venv/bin/python bench/bench_loop.py [--runs 5] [--vs PATH] [--cold]``
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from endocal.backends.registry import make_backend
from endocal.excite import run_excitation
from endocal.probe import PRESETS
from endocal.protocols import load_protocol

TEE = PRESETS["tee"]
#: The demo's records (scripts/demo.sh): protocol, amplitude (deg), seed.
RECORDS = {"train": ("damped-sine", 85.0, 2), "chirp": ("chirp", 50.0, 4), "test": ("random", 60.0, 3),
           "check": ("triangle", 50.0, 5)}
TARGET_S = 2.5
#: What ``validate`` imports before it reads a record: the numerical stack, the table reader, the CLI.
LIBRARIES = "import numpy, scipy.optimize, numba, pyarrow.parquet, typer"
ROOT = Path(__file__).resolve().parents[1]


def records(root: Path) -> dict[str, Path]:
    """The demo's four records, written as ``endocal excite`` writes them."""
    out = {}
    for name, (proto, amp, seed) in RECORDS.items():
        p = load_protocol(proto, overrides={"amplitude_deg": amp})
        run_excitation(p.trajectory(TEE, seed=seed), make_backend("sim", TEE, seed=seed), TEE, root / name,
                       protocol_info=p.to_dict(), seed=seed)
        out[name] = root / name
    return out


def _env(code: Path) -> dict:
    """The environment of a user's shell with ``code``'s endocal first (no ENDOCAL_JOBS: every core)."""
    env = {k: v for k, v in os.environ.items() if k != "ENDOCAL_JOBS"}
    env["PYTHONPATH"] = str(code)
    return env


def timed(argv: list[str], env: dict, cwd: Path) -> tuple[float, float]:
    """Wall and CPU seconds (the process and the children it waited for) of one run of ``argv``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(argv, env=env, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode not in (0, 1):  # validate exits 1 when it finds something missing
        raise SystemExit(f"{' '.join(argv)} failed ({done.returncode}): {done.stderr.strip()[-500:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def cold_comparison(paths: dict[str, Path]) -> None:
    """Issue 12's figure: the scan with warm-started candidates against one fitting each from scratch."""
    from endocal.fitting import fit_hysteresis
    from endocal.runs.aligned import load_aligned
    from endocal.validation import scan
    from endocal.validation.offline import validate_offline
    from endocal.validation.structure import template

    def cold_split_fit(model, effects, train, stride=1):
        dt = train.decimate(stride) if stride > 1 else train
        return template(model, effects).fit(dt)

    def run(model, val, train):
        t0 = time.perf_counter()
        res = validate_offline(model, val, train=train, train_paths=[str(paths["train"]), str(paths["chirp"])],
                               data_paths=[str(paths["test"]), str(paths["check"])])
        return time.perf_counter() - t0, res

    model = fit_hysteresis([paths["train"], paths["chirp"]], "ap", "pi", ["envelope", "deadzone"]).model
    val = [load_aligned(paths["test"]), load_aligned(paths["check"])]
    train = [load_aligned(paths["train"]), load_aligned(paths["chirp"])]
    fast_s, fast = run(model, val, train)
    warm = scan.split_fit
    scan.split_fit = cold_split_fit
    try:
        ref_s, ref = run(model, val, train)
    finally:
        scan.split_fit = warm
    print(f"issue 12, in process: validate {model.base_name}+{'+'.join(e.label for e in model.effects_)}, "
          f"{len(fast.scan.tested)} candidates: warm-started {fast_s:.1f} s, from scratch {ref_s:.1f} s "
          f"({ref_s / fast_s:.1f}x); validation RMSE {fast.scan.baseline_rmse_heldout_deg:.3f} deg")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5, help="timed runs of each command (median quoted)")
    ap.add_argument("--vs", type=Path, help="a second checkout's code folder, timed in the same alternation")
    ap.add_argument("--cold", action="store_true", help="also issue 12's warm/cold scan comparison (minutes)")
    args = ap.parse_args()
    py = sys.executable
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        paths = records(root)
        fit = [py, "-m", "endocal", "fit", "hysteresis", "train", "chirp", "--axis", "ap", "--model", "pi",
               "--effects", "envelope", "--out", "pi-envelope.json"]
        subprocess.run(fit, env=_env(ROOT), cwd=root, check=True, stdout=subprocess.DEVNULL)
        validate = [py, "-m", "endocal", "validate", "pi-envelope.json", "test", "check"]
        commands = {"python -c pass": ([py, "-c", "pass"], _env(ROOT)),
                    "the libraries' imports alone": ([py, "-c", LIBRARIES], _env(ROOT)),
                    "endocal validate": (validate, _env(ROOT))}
        if args.vs is not None:
            commands[f"endocal validate ({args.vs})"] = (validate, _env(args.vs.resolve()))
        for argv, env in commands.values():  # warm-up: numba's caches, the file system's
            timed(argv, env, root)
        times: dict[str, list[tuple[float, float]]] = {k: [] for k in commands}
        for _ in range(args.runs):
            for name, (argv, env) in commands.items():
                times[name].append(timed(argv, env, root))
        if args.cold:
            cold_comparison(paths)
    load = os.getloadavg()[0]
    ref_wall = statistics.median(w for w, _ in times["python -c pass"])
    print(f"endocal validate pi-envelope.json test check (the demo's records), median of {args.runs} runs, "
          f"{os.cpu_count()} cores, load average {load:.1f} at the end:")
    print(f"  {'command':44s} {'wall s':>8s} {'cpu s':>8s} {'wall / python -c pass':>22s}")
    for name, runs in times.items():
        wall = statistics.median(w for w, _ in runs)
        cpu = statistics.median(c for _, c in runs)
        print(f"  {name:44s} {wall:8.2f} {cpu:8.2f} {wall / ref_wall:22.0f}")
    wall = statistics.median(w for w, _ in times["endocal validate"])
    floor = statistics.median(w for w, _ in times["the libraries' imports alone"])
    print(f"  target: endocal validate <= {TARGET_S} s wall on a quiet machine ({TARGET_S / ref_wall:.0f} x python -c "
          f"pass at this run's {ref_wall * 1000:.0f} ms); {'met' if wall <= TARGET_S else 'not met'} in this run")
    print(f"  beyond the libraries' imports: validate {wall - floor:.2f} s, the target {TARGET_S - floor:.2f} s")
    if args.vs is not None:
        other = statistics.median(w for w, _ in times[f"endocal validate ({args.vs})"])
        other_cpu = statistics.median(c for _, c in times[f"endocal validate ({args.vs})"])
        cpu = statistics.median(c for _, c in times["endocal validate"])
        print(f"  this checkout / {args.vs}: wall {wall / other:.2f}, cpu {cpu / other_cpu:.2f}")


if __name__ == "__main__":
    main()
