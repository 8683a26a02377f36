"""``endocal effects``: the catalog of physical effects a model can be given with ``--effects``."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from endocal.cli._common import cli_errors, out
from endocal.cli._effects_file import effects_file_option, use_effects_files


@cli_errors
def effects(
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of a table."),
    effects_files: list[Path] = effects_file_option(),
) -> None:
    """List every effect (yours, from --effects-file, marked so): its physical cause, the signature it leaves in residuals, the protocol that excites it.

    Add effects to a model with ``endocal fit hysteresis ... --effects envelope,delay,load:sheath_wrap_deg``.
    """
    from endocal.models.effects import catalog

    use_effects_files(effects_files)
    entries = catalog()
    sources = user_sources(entries)
    if as_json:
        out.print_json(json.dumps({"effects": [e.to_dict() | {"source": sources.get(e.name)} for e in entries]}))
        return
    # One block per effect: the texts are sentences, which a many-column table squeezes unreadably.
    for e in entries:
        yours = f", yours: {sources[e.name]['path']}" if e.name in sources else ""
        out.print(f"[bold]{e.usage}[/] ({e.kind} term{yours})")
        out.print(f"  cause:      {e.cause}", markup=False)
        out.print(f"  signature:  {e.signature}", markup=False)
        out.print(f"  excited by: {e.protocol}", markup=False)
        if e.needs:
            out.print(f"  needs:      {', '.join(e.needs)}", markup=False)
        for form, kind in e.variants.items():
            out.print(f"  also:       {form} ({kind} term; validate tries it too)", markup=False)
        out.print()


def user_sources(entries) -> dict[str, dict]:
    """Effect name -> the source of each of the user's effects among ``entries`` (file and SHA-256)."""
    from endocal.models.effects import EFFECTS
    from endocal.models.userfile import source_of

    return {e.name: src.to_dict() for e in entries if (src := source_of(EFFECTS[e.name])) is not None}
