"""Fit the scan's candidate models on every core.

The effect scan fits one model per candidate effect (and per fold); the fits are
independent and each is single-threaded (the fit pins BLAS to one thread), so they
parallelise across processes. Workers are *forked* after the job is set up, so they share
the data and the numba-compiled kernels of the parent without pickling or recompiling
anything; only each job's result travels back. Where fork is unavailable (Windows, and
macOS's default), or with one job or one core, the jobs run in this process.

``ENDOCAL_JOBS`` caps the number of processes (``1``: no parallelism; the test suite sets
it, because pytest-xdist already runs one worker per core).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
from collections.abc import Callable, Sequence
from typing import Any

from endocal.errors import EndocalError

try:  # BLAS threads fight each other on the many small least-squares problems of a scan
    from threadpoolctl import threadpool_limits
except ImportError:  # pragma: no cover - threadpoolctl is a declared dependency
    threadpool_limits = None

_TASK: tuple[Callable[[Any], Any], Sequence[Any]] | None = None


def n_jobs(n_items: int, requested: int | None = None) -> int:
    """Processes to use for ``n_items`` jobs: ``requested``, else ``ENDOCAL_JOBS``, else the core count."""
    if requested is None:
        env = os.environ.get("ENDOCAL_JOBS", "").strip()
        requested = int(env) if env.isdigit() else (os.cpu_count() or 1)
    return max(1, min(int(requested), n_items))


def _call(fn: Callable[[Any], Any], item: Any) -> Any:
    try:
        return fn(item)
    except EndocalError as exc:  # a candidate that cannot be fitted is a result, not a crash
        return exc


def _run(i: int) -> Any:
    fn, items = _TASK
    return _call(fn, items[i])


def map_jobs(fn: Callable[[Any], Any], items: Sequence[Any], jobs: int | None = None,
             meanwhile: Callable[[], Any] | None = None) -> list[Any]:
    """``[fn(x) for x in items]`` over forked worker processes, in order.

    An :class:`~endocal.errors.EndocalError` raised by a job is returned in its place (the
    caller decides what a failed job means); any other exception propagates.

    Parameters
    ----------
    fn : callable
        The job; it may close over large arrays (they are shared by fork, not pickled).
    items : sequence
        One item per job.
    jobs : int, optional
        Processes (default: :func:`n_jobs`).
    meanwhile : callable, optional
        Work of this process's own, run while the workers fit (after they are forked, so they do not
        see it), instead of this process waiting idle; run before the jobs where they run here.

    Returns
    -------
    list
        ``fn(item)`` or the EndocalError it raised, per item.
    """
    global _TASK
    n = n_jobs(len(items), jobs)
    if n <= 1 or "fork" not in multiprocessing.get_all_start_methods():
        if meanwhile is not None:
            meanwhile()
        return [_call(fn, x) for x in items]
    _TASK = (fn, items)
    try:
        with multiprocessing.get_context("fork").Pool(n) as pool:
            pending = pool.map_async(_run, range(len(items)), chunksize=1)
            if meanwhile is not None:
                meanwhile()
            return pending.get()
    finally:
        _TASK = None


def one_blas_thread():
    """Context limiting BLAS to one thread (many small least-squares problems run faster that way)."""
    return threadpool_limits(limits=1, user_api="blas") if threadpool_limits else contextlib.nullcontext()
