"""``endocal history DIR``: every probe's last check and state; one probe's control charts; SQL over the fleet."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from endocal.cli._common import cli_errors, err, fail, out


@cli_errors
def history(
    folder: Path = typer.Argument(..., help="The history folder (`endocal check --history DIR`)."),
    probe: Optional[str] = typer.Option(None, "--probe", help="One probe's ID: its checks since calibration, "
                                        "figure by figure (with --plot: its control charts)."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="With --probe: write its control charts (individuals, "
                                        "moving range, EWMA of every figure) to this PNG."),
    sql: Optional[str] = typer.Option(None, "--sql", help="One SELECT over the view `checks` (every check of every "
                                      "probe; DuckDB, read-only), e.g. \"SELECT probe, state FROM checks\"."),
    force: bool = typer.Option(False, "--force", help="Overwrite --plot."),
    as_json: bool = typer.Option(False, "--json", help="Print the table (or the query's rows) as JSON."),
) -> None:
    """A fleet's probe checks: every probe's last check and state (in control, drifting, out of control).

    `--probe ID --plot FILE.png` draws the probe's control charts; `--sql` runs DuckDB over the whole dataset.
    A month file that cannot be read is named on one line (exit code 2) and the rest is still shown.
    """
    if plot is not None and probe is None:
        fail("--plot draws one probe's control charts: give --probe ID")
    if sql is not None and (probe is not None or plot is not None):
        fail("--sql queries the whole history: give it without --probe and --plot (filter in the query)")
    if sql is not None:
        from endocal.check.sql import query

        res = query(folder, sql, as_frame=False)
        _print_rows(res.columns, res.rows, as_json)
        _corrupt(res.corrupt_line())
        return
    from endocal.check.summary import read_history

    h = read_history(folder)
    if probe is None:
        table = h.table()
        if not len(table) and not h.corrupt:
            err.print(f"no checks in {folder} yet: endocal check --history {folder} adds them", markup=False)
        _print_frame(table, as_json)
    else:
        pc = h.charts(probe)
        if plot is not None:
            from endocal.cli._common import refuse_input_as_output
            from endocal.errors import OutputExistsError

            if plot.exists() and not force:
                raise OutputExistsError(f"{plot} already exists: choose another path or pass --force")
            refuse_input_as_output("--plot", plot, [folder])
            from endocal.report.checks import charts_figure
            from endocal.report.figures import to_png
            from endocal.runs.format import atomic_write_bytes

            atomic_write_bytes(plot, to_png(charts_figure(pc)))
            err.print(f"wrote {plot}", markup=False)
        out.print(f"{probe}: {pc.state}, {pc.n_checks} checks since calibration", markup=False)
        _print_frame(_chart_table(pc), as_json)
    _corrupt(h.corrupt_line())


def _chart_table(pc):
    import pandas as pd

    rows = []
    for name, c in pc.charts.items():
        rows.append({"figure": name, "last": c.x[-1], "centre": c.mu, "sigma": c.sigma,
                     "ewma": c.z[-1], "state": c.state_at(len(c.x) - 1)})
    return pd.DataFrame(rows)


def _print_frame(df, as_json: bool) -> None:
    _print_rows(list(df.columns), list(df.itertuples(index=False, name=None)), as_json)


def _cell(v) -> str:
    if v is None:
        return "NULL"
    if isinstance(v, float):
        return "nan" if v != v else f"{v:.4g}"
    if hasattr(v, "item") and not isinstance(v, (str, bytes)):  # a numpy scalar
        return _cell(v.item())
    return str(v)


def _print_rows(columns: list, rows: list, as_json: bool) -> None:
    """Rows as a table, right-aligned as a terminal reads numbers (no pandas: `--sql` starts quickly)."""
    if as_json:
        import json

        from endocal.cli._common import finite

        records = [{c: (v.item() if hasattr(v, "item") else v) for c, v in zip(columns, r)} for r in rows]
        out.print(json.dumps(finite(records), default=str), markup=False, soft_wrap=True)
        return
    if not rows:
        return
    import numbers

    cells = [[_cell(v) for v in r] for r in rows]
    widths = [max([len(str(c))] + [len(r[k]) for r in cells]) for k, c in enumerate(columns)]
    numeric = [all(v is None or isinstance(v, numbers.Number) for v in col) for col in zip(*rows)]

    def line(values):
        return "  ".join(v.rjust(w) if num else v.ljust(w) for v, w, num in zip(values, widths, numeric)).rstrip()

    out.print(line([str(c) for c in columns]), markup=False)
    for r in cells:
        out.print(line(r), markup=False)


def _corrupt(line: str | None) -> None:
    if line is not None:
        fail(line)
