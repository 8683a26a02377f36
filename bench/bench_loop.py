"""Speed of one turn of the user's loop: `endocal validate` on the demo's records (issue 12). Prints; asserts nothing.

Target: validate on the demo's two validation records (random + triangle, 18 000 samples,
with the damped sine + chirp as estimation data, 26 000 samples) in at most 15 s on this
2-core machine. The model is the demo's second rung, ``pi + envelope + deadzone``: the one
with the most candidates to test (delay, rate, creep, tension, ...). Beside it, in the same run, the plain reference:
the same scan with every candidate structure fitted from a cold start (each repeats the
start-candidate search of every effect the model already has), which is what validate did
before it warm-started the candidates from the model's own fitted values.

Run: ``.venv/bin/python bench/bench_loop.py``
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from endocal.backends.registry import make_backend
from endocal.excite import run_excitation
from endocal.fitting import fit_hysteresis
from endocal.probe import PRESETS
from endocal.protocols import load_protocol
from endocal.runs.aligned import load_aligned
from endocal.validation import scan
from endocal.validation.offline import validate_offline
from endocal.validation.structure import template

TEE = PRESETS["tee"]
#: The demo's records (scripts/demo.sh): protocol, amplitude (deg), seed.
RECORDS = {"train": ("damped-sine", 85.0, 2), "chirp": ("chirp", 50.0, 4), "test": ("random", 60.0, 3),
           "check": ("triangle", 50.0, 5)}


def records(root: Path) -> dict[str, Path]:
    out = {}
    for name, (proto, amp, seed) in RECORDS.items():
        p = load_protocol(proto, overrides={"amplitude_deg": amp})
        run_excitation(p.trajectory(TEE, seed=seed), make_backend("sim", TEE, seed=seed), TEE, root / name,
                       protocol_info=p.to_dict(), seed=seed)
        out[name] = root / name
    return out


def cold_split_fit(model, effects, train, stride=1):
    """The reference: a candidate structure fitted from scratch (no warm start)."""
    dt = train.decimate(stride) if stride > 1 else train
    return template(model, effects).fit(dt)


def time_validate(model, val, train, paths) -> tuple[float, object]:
    t0 = time.perf_counter()
    res = validate_offline(model, val, train=train, train_paths=[str(paths["train"]), str(paths["chirp"])],
                           data_paths=[str(paths["test"]), str(paths["check"])])
    return time.perf_counter() - t0, res


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        paths = records(Path(tmp))
        fit = fit_hysteresis([paths["train"], paths["chirp"]], "ap", "pi", ["envelope", "deadzone"])
        model = fit.model
        val = [load_aligned(paths["test"]), load_aligned(paths["check"])]
        train = [load_aligned(paths["train"]), load_aligned(paths["chirp"])]
        n_val = sum(len(v.table) for v in val)
        n_train = sum(len(t.table) for t in train)
        fast_s, fast = time_validate(model, val, train, paths)
        warm = scan.split_fit  # the scan's candidate fits (scan_split, split_errors)
        scan.split_fit = cold_split_fit
        try:
            ref_s, ref = time_validate(model, val, train, paths)
        finally:
            scan.split_fit = warm
    print(f"validate, {model.base_name}+{'+'.join(e.label for e in model.effects_)} on {n_val} validation samples "
          f"(estimation: {n_train}), {len(fast.scan.tested)} candidates:")
    print(f"  warm-started candidates: {fast_s:6.1f} s (target <= 15 s); validation RMSE {fast.scan.baseline_rmse_heldout_deg:.3f} deg, "
          f"first suspect {fast.scan.suspects[0].effect if fast.scan.suspects else 'none'}")
    print(f"  cold-started reference: {ref_s:6.1f} s; validation RMSE {ref.scan.baseline_rmse_heldout_deg:.3f} deg, "
          f"first suspect {ref.scan.suspects[0].effect if ref.scan.suspects else 'none'}")
    print(f"  speed-up {ref_s / fast_s:.1f}x")


if __name__ == "__main__":
    main()
