"""Crash-safe streaming writer of the run streams.

Chunks from a backend are buffered in memory and written as a new Parquet part when the
buffer is ``flush_interval_s`` of wall-clock time old (default 1 s), so ``kill -9`` loses
at most that second plus the chunk in flight. Each part goes to a hidden temporary file
first and is renamed into place: readers never see half a part.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from endocal.streams import StreamChunk
from endocal.errors import RunFormatError
from endocal.runs.aligned import align, read_stream
from endocal.runs.format import (ALIGNED, MOTOR, RUN_JSON, STREAMS, TRACKER, atomic_write_bytes, parquet_bytes,
                                 utc_now, write_json)


class StreamLogger:
    """Append :class:`StreamChunk` objects to the stream folders of a run.

    Parameters
    ----------
    run_dir : Path
        The run folder; stream folders are created inside it.
    flush_interval_s : float
        Wall-clock age of the buffer that triggers a write, seconds.
    max_buffer_rows : int
        Motor rows that trigger a write whatever the age (bounds memory on fast backends).
    """

    def __init__(self, run_dir: Path, flush_interval_s: float = 1.0, max_buffer_rows: int = 400_000):
        self.run_dir = Path(run_dir)
        self.flush_interval_s = flush_interval_s
        self.max_buffer_rows = max_buffer_rows
        self._buffers: dict[str, list[dict[str, np.ndarray]]] = {s: [] for s in STREAMS}
        self._part = 0
        self._last_flush = time.monotonic()
        self.rows_written = {s: 0 for s in STREAMS}
        self._buffered_rows = 0
        self.last_t_s = float("nan")

    def append(self, chunk: StreamChunk) -> None:
        """Buffer one chunk, writing the buffer out if it is old or large enough."""
        for name, cols in ((s, getattr(chunk, s)) for s in STREAMS):
            if cols and len(next(iter(cols.values()))):
                self._buffers[name].append(cols)
        n = len(chunk.motor.get("t_s", ()))
        self._buffered_rows += n
        if n:
            self.last_t_s = float(chunk.motor["t_s"][-1])
        if self._buffered_rows >= self.max_buffer_rows or time.monotonic() - self._last_flush >= self.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        """Write every buffered stream as one new part (no-op when nothing is buffered)."""
        wrote = False
        for name, pieces in self._buffers.items():
            if not pieces:
                continue
            keys = list(pieces[0])
            table = pa.table({k: np.concatenate([p[k] for p in pieces]) for k in keys})
            folder = self.run_dir / name
            folder.mkdir(exist_ok=True)
            final = folder / f"part-{self._part:06d}.parquet"
            tmp = folder / f".{final.name}.tmp"
            pq.write_table(table, tmp)
            os.replace(tmp, final)
            self.rows_written[name] += table.num_rows
            self._buffers[name] = []
            wrote = True
        if wrote:
            self._part += 1
        self._buffered_rows = 0
        self._last_flush = time.monotonic()


def finish_run(out: Path, meta: dict, logger: StreamLogger, status: str, error: str | None, wall_s: float, probe) -> None:
    """Write the aligned table (if anything was logged) and the final ``run.json``."""
    meta["status"] = status
    meta["ended_utc"] = utc_now()
    meta["wall_s"] = round(wall_s, 3)
    meta.setdefault("started_utc", meta["ended_utc"])
    if error:
        meta["error"] = error
    counts = {"motor_rows": logger.rows_written[MOTOR], "tracker_rows": logger.rows_written[TRACKER]}
    if logger.rows_written[MOTOR] and logger.rows_written[TRACKER]:
        try:
            alignment = align(read_stream(out, MOTOR), read_stream(out, TRACKER), probe)
        except RunFormatError as exc:
            # The streams stay on disk; say why there is no aligned table rather than lose the run.
            meta["alignment_error"] = str(exc)
        else:
            atomic_write_bytes(out / ALIGNED, parquet_bytes(alignment.table))
            counts.update(alignment.counts())
    meta["counts"] = counts
    meta["logged_s"] = float(logger.last_t_s) if np.isfinite(logger.last_t_s) else 0.0
    write_json(out / RUN_JSON, meta)
