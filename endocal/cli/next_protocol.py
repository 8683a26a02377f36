"""``endocal validate ... --next NEXT.toml``: write the next experiment and say how to run it."""

from __future__ import annotations

import shlex
from pathlib import Path

from endocal.cli._common import err, out


def probe_of(tables, fallback: str):
    """The probe the validation records were made on (their ``run.json``), else ``--probe``."""
    from endocal.probe import ProbeConfig, load_probe

    for a in tables:
        if isinstance(getattr(a, "meta", None), dict) and isinstance(a.meta.get("probe"), dict):
            return ProbeConfig.from_dict(a.meta["probe"], where=f"{a.source} (run.json)")
    return load_probe(fallback)


def check_next(model, tables, probe_option: str) -> None:
    """Refuse ``--next`` before the validation runs when no motion can stay inside the model's fitted range."""
    from endocal.validation.next_experiment import motion_range

    motion_range(model, probe_of(tables, probe_option))


def write_next(path: Path, model, result, tables, train_tables, planes, model_path: Path, probe_option: str,
               as_json: bool) -> None:
    """Design the next experiment (:func:`endocal.validation.next_experiment.design_next`), write it to
    ``path`` and print what it tests and the ``excite`` commands that record it (to stderr under
    ``--json``, whose stdout is the JSON object)."""
    from endocal.validation.data import axis_data
    from endocal.validation.next_experiment import design_next

    probe = probe_of(tables, probe_option)
    val = axis_data(tables, result.axis, planes)
    train = axis_data(train_tables, result.axis, planes) if train_tables else val
    nx = design_next(model, result, train, val, probe, name=path.stem, model_path=str(model_path))
    nx.write(path)
    say = err if as_json else out
    say.print(f"[bold]Next experiment[/] written to {path} ({nx.duration_s:.0f} s on probe {probe.name}): tests "
              f"{', '.join(nx.suspects)}")
    for t in nx.tests:
        where = f"segment {t.segment}" if t.segment is not None else "the whole run"
        say.print(f"  {t.effect} ({t.status}): {where}, {t.half_cycles} half-cycles", markup=False)
    for note in nx.notes:
        say.print(f"  not in it: {note}", markup=False)
    args = [str(path)] + (["--probe", probe.name] if probe.name != "tee" else [])
    sets = [a for k in nx.conditions for a in ("--set", f"{k}=VALUE")]
    for k, instruction in nx.conditions.items():
        say.print(f"  condition {k}: {instruction}", markup=False)
    say.print("Record it twice, once to add to the estimation data and once to validate on:", markup=False)
    say.print("  endocal excite " + shlex.join([*args, "--out", f"{path.stem}-fit", *sets]), markup=False)
    say.print("  endocal excite " + shlex.join([*args, "--out", f"{path.stem}-val", "--seed", "1", *sets]),
              markup=False)
