"""`endocal validate AP.json ML.json --planes planes.json --trajectory circle-1`: task-space control in mm.

Walks a tip path (:mod:`endocal.protocols.paths`) with each set of models on a backend and
reports the per-point tip error (:mod:`endocal.validation.tip_path`); with ``--compare`` the
sets are compared with the report's paired tests on stretches of the path.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from endocal.cli._common import apply_out_of_range, emit_json, err, guard_factory, out, warnings_as_lines
from endocal.errors import ModelError


def model_sets(files: list[Path], compare: list[Path]) -> list[dict[str, Path]]:
    """Group model files into sets, one model per axis: the given files, then the k-th
    ``--compare`` file of each axis forms set k + 1.

    Raises
    ------
    ModelError
        Two files of one axis in the given set, or compare files that do not make whole sets.
    """
    from endocal.models import load_model

    def axis_of(p: Path) -> str:
        return load_model(p).axis

    first: dict[str, Path] = {}
    for f in files:
        a = axis_of(f)
        if a in first:
            raise ModelError(f"two model files for axis '{a}' ({first[a]}, {f}): give one per axis, and other "
                             "models to compare with --compare")
        first[a] = f
    per_axis: dict[str, list[Path]] = {a: [] for a in first}
    for f in compare:
        a = axis_of(f)
        if a not in per_axis:
            raise ModelError(f"--compare {f} is a model of axis '{a}', but the models compared are for "
                             f"{', '.join(first)}")
        per_axis[a].append(f)
    counts = {a: len(v) for a, v in per_axis.items()}
    if len(set(counts.values())) > 1:
        raise ModelError("--compare must give one model per axis for every set compared "
                         f"(got {', '.join(f'{n} for {a}' for a, n in counts.items())})")
    n_sets = 1 + next(iter(counts.values()), 0)
    return [first] + [{a: per_axis[a][k] for a in first} for k in range(n_sets - 1)]


def _label(files: dict[str, Path]) -> str:
    return ", ".join(f"{a}={Path(p).stem}" for a, p in files.items())


def run_trajectory(files: list[Path], compare: list[Path], trajectory: str, *, backend: str, probe: str, sim_config,
                   hardware_config, planes: Path | None, seed: int, sets: list[str], out_of_range: str | None,
                   runs_out: Path | None, as_json: bool, json_out: Path | None, force_model=None, max_force_n=None) -> None:
    """Walk ``trajectory`` with each model set and print (or write) the tip errors and their comparison."""
    from endocal.backends.registry import make_backend
    from endocal.models import load_model
    from endocal.planes import load_planes
    from endocal.probe import load_probe
    from endocal.protocols import parse_overrides
    from endocal.protocols.paths import load_path, path_trajectory
    from endocal.report.stats import compare_models
    from endocal.validation.tip_path import tip_error_units, walk_tip_path

    probe_cfg = load_probe(probe)
    path = load_path(trajectory, overrides=parse_overrides(sets) or None)
    path_trajectory(path, probe_cfg)  # every point reachable, before anything else is loaded or moves
    groups = model_sets(files, compare)
    if planes is not None:
        cal = load_planes(planes)
    else:  # the planes the models were fitted through (recorded in their files), as offline validate does
        from endocal.validation.estimation import recorded_planes

        found = {}
        for f in groups[0].values():
            c, p = recorded_planes(load_model(f), f)
            found[str(Path(p).resolve()) if p else None] = (c, p)
        if len(found) > 1:
            raise ModelError("the models were fitted through different bending planes "
                             f"({', '.join(str(p) for _, p in found.values())}): give the planes to play with --planes")
        cal, planes = next(iter(found.values()))
    make_backend(backend, probe_cfg, seed=seed, sim_config=sim_config, hardware_config=hardware_config)  # configs first
    make_guard = guard_factory(force_model, max_force_n, probe_cfg)
    root = Path(runs_out) if runs_out is not None else None
    results = []
    loaded = []
    for files_k in groups:
        models = {a: load_model(p) for a, p in files_k.items()}
        for m in models.values():
            apply_out_of_range(m, out_of_range)
        loaded.append(models)
    for k, (files_k, models) in enumerate(zip(groups, loaded)):
        run = root / f"walk-{k + 1}" if root is not None else None
        with warnings_as_lines():
            results.append(walk_tip_path(
                path, models, probe_cfg,
                lambda: make_backend(backend, probe_cfg, seed=seed, sim_config=sim_config, hardware_config=hardware_config),
                planes=cal, seed=seed, out=run, label=_label(files_k), model_files=files_k,
                guard=make_guard() if make_guard is not None else None))
    comparison = None
    if len(results) > 1:
        units, errors = tip_error_units(results)
        unit_errors = {r.label: np.array([np.sqrt(np.mean(e[a:b] ** 2)) for a, b in units.bounds])
                       for r, e in zip(results, errors)}
        comparison = compare_models(unit_errors, units)
    d = {"trajectory": path.to_dict(), "backend": backend, "probe": probe_cfg.name,
         "planes": str(planes) if planes is not None else None,
         "metrics": results[0].metrics.to_dict(), "walks": [r.to_dict() for r in results],
         "comparison": comparison.to_dict() if comparison is not None else None}
    if emit_json(d, as_json, json_out):
        return
    _render(path, results, comparison)


def _render(path, results, comparison) -> None:
    m0 = results[0].metrics
    from rich.table import Table

    table = Table(title=f"tip path '{path.name}' ({m0.length_mm:.1f} mm, {m0.n} points): error |P_r - P_d|")
    for col in ("models", "median mm", "RMSE mm", "max mm", "median % of path"):
        table.add_column(col, justify="left" if col == "models" else "right")
    for r in results:
        m = r.metrics
        table.add_row(r.label, f"{m.median_mm:.2f}", f"{m.rmse_mm:.2f}", f"{m.max_mm:.2f}", f"{m.path_pct:.2f}")
    out.print(table)
    if comparison is not None:
        out.print(f"comparison: {comparison.why}", markup=False)
        for p in comparison.pairs:
            verdict = (f"{p.better} is better" if p.better and p.significant(comparison.alpha) else "no significant difference")
            out.print(f"  {p.a} vs {p.b}: p = {p.p_adjusted:.3g}, rank-biserial r = {p.rank_biserial:+.2f}, median "
                      f"difference {p.median_diff_deg:+.2f} mm per stretch: {verdict}", markup=False)
    for r in results:
        stops = [e for e in r.events if e.get("kind") == "stop"]
        if stops:
            out.print(f"force guard, {r.label}: {len(stops)} stop(s)", markup=False)
        if r.run is not None:
            err.print(f"run: {r.run}")
