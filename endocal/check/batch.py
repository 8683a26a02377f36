"""Many probes' recorded checks scored in one batch, as Dask tasks (``endocal check --run RUN...``).

Each run is one probe's latest check (its ``run.json`` names the probe ID); it is scored against
that probe's models (given, or the ones its history recorded last), which re-validates each
probe's model on its latest check run. The scoring, the part that grows with a fleet, runs as
one Dask task per run: on a local cluster by default, on an existing one with ``scheduler`` (an
address ``tcp://host:8786``), or in this process with ``scheduler="synchronous"``. The tasks
only read; the rows are appended here, in the order of the runs, so the history and every
result are identical to a serial run (a test holds this).

Everything is refused before any task runs: one bad run, model or probe ID, and nothing is
appended for any probe.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

from endocal.check.extras import require
from endocal.check.run import CheckResult, Prepared, attach_run, commit, load_probe_models, prepare
from endocal.errors import ModelError, RunFormatError


def _probe_id_of(run: Path) -> str | None:
    from endocal.files import read_json_document

    meta_path = Path(run) / "run.json"
    if not meta_path.is_file():
        return None
    meta = read_json_document(meta_path, "run.json", RunFormatError)
    return ((meta.get("protocol") or {}).get("check") or {}).get("probe_id")


def _latest_models(history, probe_id: str) -> list[str]:
    """The model files a probe's latest check was scored against, checked unchanged."""
    from endocal.check.store import HistoryFolder
    from endocal.runs.format import sha256_of

    rows = HistoryFolder(history).read(probe_id).rows
    if not len(rows):
        raise ModelError(f"probe {probe_id} has no checks in {history}, so no model on record: give its models with "
                         "--model (one probe per batch then)")
    files = json.loads(rows["models"].iloc[-1])
    for axis, rec in files.items():
        p = Path(rec["path"])
        if not p.is_file() or sha256_of(p) != rec["sha256"]:
            raise ModelError(f"{p}, probe {probe_id}'s model of axis '{axis}' on record, is missing or changed since "
                             "its last check: give its models with --model")
    return [rec["path"] for _, rec in sorted(files.items())]


def prepare_runs(runs: Sequence, history, *, probe_id: str | None = None, models: Sequence = ()) -> list[Prepared]:
    """Check every run, probe and model of a batch before anything is scored or written.

    Raises
    ------
    RunFormatError
        A run that names no probe ID (without ``probe_id`` for a single run), two runs of one
        probe, or a run of another probe than ``probe_id``.
    ModelError, HistoryError
        As for one check.
    """
    runs = [Path(r) for r in runs]
    if not runs:
        raise RunFormatError("no --run given")
    if len(runs) > 1 and (probe_id is not None or models):
        raise RunFormatError("--probe-id and --model are for one run; a batch takes each run's probe from its run.json "
                             "and each probe's models from its history")
    preps, seen = [], {}
    for run in runs:
        pid = _probe_id_of(run) if probe_id is None else probe_id
        if pid is None:
            raise RunFormatError(f"{run} names no probe ID (its run.json has no protocol.check.probe_id): give it alone "
                                 "with --probe-id ID")
        if pid in seen:
            raise RunFormatError(f"{seen[pid]} and {run} are both checks of probe {pid}: a batch scores one run per probe")
        seen[pid] = run
        pm = load_probe_models(models or _latest_models(history, pid))
        preps.append(attach_run(prepare(pid, history, pm), run))
    return preps


def _score_task(run: str, model_paths: list[str]) -> dict:
    """One Dask task: the figures of ``run`` against the models (reads only)."""
    from endocal.check.scoring import check_figures
    from endocal.runs.aligned import load_aligned

    return check_figures(load_aligned(run), load_probe_models(model_paths).models)


def _task_args(p: Prepared) -> tuple[str, list[str]]:
    return str(p.run_dir), [m["path"] for _, m in sorted(p.models.files.items())]


def score_all(preps: Sequence[Prepared], scheduler: str | None = None) -> list[dict]:
    """The figures of every prepared check, one Dask task each, in the order given.

    Parameters
    ----------
    scheduler : str, optional
        None: a local cluster (one worker process per core, up to 4); ``"synchronous"``: in
        this process, one task after another; otherwise the address of a running scheduler.

    Raises
    ------
    ExtraMissingError
        Dask (or its distributed scheduler) is not installed.
    """
    if len(preps) == 1 and scheduler is None:  # one run: no cluster to start
        return [_score_task(*_task_args(preps[0]))]
    dask = require("dask", "endocal check --run RUN...")
    tasks = [dask.delayed(_score_task, pure=True)(*_task_args(p)) for p in preps]
    if scheduler == "synchronous":
        return list(dask.compute(*tasks, scheduler="synchronous"))
    distributed = require("distributed", "endocal check --run RUN... on a cluster")
    if scheduler is None:
        import os

        import logging

        # silence_logs: the cluster's own start and stop messages (a worker killed at shutdown) are not the user's
        with distributed.LocalCluster(n_workers=max(1, min(4, os.cpu_count() or 1, len(tasks))), threads_per_worker=1,
                                      processes=True, dashboard_address=None, silence_logs=logging.CRITICAL) as cluster, \
                distributed.Client(cluster) as client:
            return list(client.gather(client.compute(tasks)))
    try:
        client = distributed.Client(scheduler, timeout="10s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise RunFormatError(f"--scheduler {scheduler}: cannot connect ({' '.join(str(exc).split())}): give the address "
                             "of a running dask scheduler, e.g. tcp://host:8786") from None
    with client:
        return list(client.gather(client.compute(tasks)))


def check_runs(runs: Sequence, history, *, probe_id: str | None = None, models: Sequence = (),
               scheduler: str | None = None) -> list[CheckResult]:
    """Score recorded checks of many probes (one run each) and append them to the history.

    Parameters
    ----------
    runs : sequence of path
        One check run per probe (``endocal check`` records the probe ID in ``run.json``).
    history : path
    probe_id, models : optional
        For a single run that names no probe (an imported one), and its models.
    scheduler : str, optional
        See :func:`score_all`.

    Returns
    -------
    list of CheckResult
        In the order of ``runs``.
    """
    preps = prepare_runs(runs, history, probe_id=probe_id, models=models)
    figures = score_all(preps, scheduler)
    return [commit(p, f) for p, f in zip(preps, figures)]
