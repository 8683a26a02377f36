"""``endocal effects``: the catalog of physical effects a model can be given with ``--effects``."""

from __future__ import annotations

import json

import typer

from endocal.cli._common import cli_errors, out


@cli_errors
def effects(
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of a table."),
) -> None:
    """List every effect: its physical cause, the signature it leaves in residuals, the protocol that excites it.

    Add effects to a model with ``endocal fit hysteresis ... --effects envelope,delay,load:sheath_wrap_deg``.
    """
    from rich.table import Table

    from endocal.models.effects import catalog

    entries = catalog()
    if as_json:
        out.print_json(json.dumps({"effects": [e.to_dict() for e in entries]}))
        return
    table = Table("effect", "kind", "physical cause", "signature in residuals", "excited by", "needs", show_lines=True)
    for e in entries:
        table.add_row(e.usage, e.kind, e.cause, e.signature, e.protocol, ", ".join(e.needs) or "-")
    out.print(table)
