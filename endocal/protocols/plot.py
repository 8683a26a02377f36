"""Goal-versus-time figures of a trajectory, written as PNG.

Uses matplotlib's object API on the Agg canvas (no pyplot, no global state, no display),
so it is safe in tests, on servers and inside other programs.
"""

from __future__ import annotations

from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from endocal.errors import OutputPathError
from endocal.probe import ProbeConfig
from endocal.protocols.trajectory import Trajectory
from endocal.runs.format import check_parent


def trajectory_figure(traj: Trajectory, probe: ProbeConfig | None = None, title: str | None = None) -> Figure:
    """One panel per moving degree of freedom: goal against time.

    Parameters
    ----------
    traj : Trajectory
        What to draw.
    probe : ProbeConfig, optional
        Draws the DoF limits as dashed lines and labels units.
    title : str, optional
        Figure title (default: the protocol name and duration).

    Returns
    -------
    matplotlib.figure.Figure
        Attached to an Agg canvas. If nothing moves, the bending knobs (or every DoF) are drawn flat.
    """
    dofs = list(traj.moving_dofs)
    if not dofs:
        dofs = list(probe.bending_axes) if probe is not None else list(traj.goal)
    fig = Figure(figsize=(9.0, 1.0 + 2.0 * len(dofs)), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(dofs), 1, sharex=True, squeeze=False)[:, 0]
    for ax, dof in zip(axes, dofs):
        unit = probe.unit(dof) if probe is not None else ("mm" if dof == "translation" else "deg")
        ax.plot(traj.t_s, traj.goal[dof], lw=1.0, color="C0")
        if probe is not None:
            for lim in probe.limits(dof):
                ax.axhline(lim, color="0.5", lw=0.8, ls="--")
        ax.set_ylabel(f"{dof} goal ({unit})")
        ax.grid(True, alpha=0.3)
        ax.margins(x=0)
    if len(traj.segments) <= 40:  # beyond that the markers only grey the panel out
        for seg in traj.segments:
            for ax in axes:
                ax.axvline(seg.start_s, color="0.85", lw=0.6, zorder=0)
    axes[-1].set_xlabel("t (s)")
    head = title or f"{traj.protocol or 'trajectory'}: {traj.duration_s:g} s at {traj.sample_rate_hz:g} Hz"
    fig.suptitle(head)
    return fig


def plot_trajectory(traj: Trajectory, path: str | Path, probe: ProbeConfig | None = None, title: str | None = None) -> Path:
    """Draw :func:`trajectory_figure` into a PNG file.

    Parameters
    ----------
    traj : Trajectory
    path : str or Path
        Output file; its folder must exist. A ``.png`` suffix is expected.
    probe : ProbeConfig, optional
    title : str, optional

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    OutputPathError
        The path does not end in ``.png`` or cannot be written.
    """
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise OutputPathError(f"plot output {path} must be a .png file")
    check_parent(path)
    fig = trajectory_figure(traj, probe, title)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, format="png", dpi=100)
    except OSError as exc:
        raise OutputPathError(f"cannot write {path}: {exc.strerror or exc}") from None
    return path

