"""A short description of a run or aligned table: what `endocal info` shows."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from endocal.models.data import reversals
from endocal.runs.aligned import MEAS, AlignedData, load_aligned
from endocal.runs.format import sample_rate_hz


@dataclass
class AxisSummary:
    """One axis: its command's range (in ``drive_unit``: deg, or mm for a linear drive), its
    measured angle's (deg), and the command's reversals."""

    axis: str
    cmd_range_deg: tuple[float, float]
    meas_range_deg: tuple[float, float]
    reversals: int
    drive_unit: str = "deg"


@dataclass
class DataSummary:
    """Rows, span, axes and ranges of an aligned table, plus the run's record when it is a run."""

    source: Path
    rows: int
    duration_s: float
    rate_hz: float
    axes: list[AxisSummary]
    extras: list[str]
    sha256: str
    status: str | None = None
    protocol: str | None = None
    backend: str | None = None
    seed: int | None = None
    counts: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        from dataclasses import asdict

        d = asdict(self)
        d["source"] = str(self.source)
        return d


def summarize(path: str | Path | AlignedData) -> DataSummary:
    """Summarise the run folder or aligned table at ``path``, or one already loaded (see
    :func:`load_aligned` for errors)."""
    data = path if isinstance(path, AlignedData) else load_aligned(path)
    t = data.t_s
    axes = []
    for axis in data.axes:
        cmd, meas = data.cmd(axis), data.column(axis + MEAS)
        axes.append(
            AxisSummary(
                axis,
                (float(cmd.min()), float(cmd.max())),
                (float(meas.min()), float(meas.max())),
                reversals(cmd),
                data.drive_unit(axis),
            )
        )
    meta = data.meta
    return DataSummary(
        source=data.source,
        rows=len(t),
        duration_s=float(t[-1] - t[0]),
        rate_hz=sample_rate_hz(t) or float("nan"),
        axes=axes,
        extras=data.extras,
        sha256=data.sha256,
        status=meta.get("status"),
        protocol=(meta.get("protocol") or {}).get("name"),
        backend=(meta.get("backend") or {}).get("name"),
        seed=meta.get("seed"),
        counts=meta.get("counts", {}),
    )
