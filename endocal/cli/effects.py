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
    from endocal.models.effects import catalog

    entries = catalog()
    if as_json:
        out.print_json(json.dumps({"effects": [e.to_dict() for e in entries]}))
        return
    # One block per effect: the texts are sentences, which a many-column table squeezes unreadably.
    for e in entries:
        out.print(f"[bold]{e.usage}[/] ({e.kind} term)")
        out.print(f"  cause:      {e.cause}", markup=False)
        out.print(f"  signature:  {e.signature}", markup=False)
        out.print(f"  excited by: {e.protocol}", markup=False)
        if e.needs:
            out.print(f"  needs:      {', '.join(e.needs)}", markup=False)
        out.print()
