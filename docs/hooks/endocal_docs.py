"""MkDocs hooks: the parts of the site generated from the code, so they cannot drift from it.

- ``<!-- endocal:cli -->`` on a page becomes the command-line reference: every command and
  subcommand of ``endocal`` (Typer's app with every subcommand registered), its help, usage,
  arguments and options, each row exactly the line ``endocal COMMAND --help`` prints
  (``get_help_record``). Typer 0.29 vendors its own Click, whose classes mkdocs-click's
  ``isinstance(…, click.Option)`` checks do not recognise (it renders no option at all), so the
  tree is walked here through the Click API Typer keeps (``list_commands``, ``get_command``,
  ``get_params``).
- ``<!-- endocal:effects -->`` on a page becomes the effect catalogue: for each entry of
  :func:`endocal.models.effects.catalog`, its cause, signature, excitation, parameters and the
  physics its module's docstring writes down.
- ``<!-- endocal:notebook PATH -->`` becomes the jupytext script at PATH as a page: its markdown
  cells as text, its code cells as Python blocks, each followed by what it showed when it ran
  (its repr or printout as text, its figures as images). The outputs are not computed here: the
  test that executes the notebook (``tests/test_tutorial_notebook.py``) writes them beside the
  script with :func:`write_notebook_outputs` (``PATH-stem_outputs/``: ``outputs.json`` and one PNG a
  figure), so building the site stays quick and the page shows what the suite ran. A code cell
  whose source differs from the one that was run shows no output (the page says so), never
  another cell's.
"""

from __future__ import annotations

import base64
import functools
import importlib.util
import json
import os
import re
import sys
import textwrap
from pathlib import Path

CLI_MARKER = "<!-- endocal:cli -->"
#: ``<!-- endocal:notebook PATH -->``: a jupytext percent script (PATH from the repository root) rendered as the page
NOTEBOOK_MARKER = re.compile(r"<!-- endocal:notebook (\S+) -->")
EFFECTS_MARKER = "<!-- endocal:effects -->"


def on_page_markdown(markdown, page, config, files):
    if CLI_MARKER in markdown:
        markdown = markdown.replace(CLI_MARKER, cli_markdown())
    if EFFECTS_MARKER in markdown:
        markdown = markdown.replace(EFFECTS_MARKER, effects_markdown())
    root = Path(config["config_file_path"]).parent
    markdown = NOTEBOOK_MARKER.sub(lambda m: notebook_markdown(root / m.group(1), m.group(1)), markdown)
    return markdown


REPOSITORY = Path(__file__).resolve().parents[2]
#: The outputs of a notebook ``X.py``: ``X_outputs/outputs.json`` and the figures beside it
OUTPUTS_INDEX = "outputs.json"


def outputs_dir(path: Path) -> Path:
    """Where the outputs of the jupytext script ``path`` are kept (``notebook.py`` -> ``notebook_outputs/``)."""
    return path.with_name(f"{path.stem}_outputs")


def relative_paths(text: str, bases: list[tuple[Path, str]]) -> str:
    """``text`` with every machine path under one of ``bases`` written relative to it.

    ``bases`` holds ``(folder, written as)`` pairs: ``""`` writes a path under the folder relative
    to it (the folder itself as ``.``), ``"~"`` as ``~/...``. The longest folder is replaced first,
    each also as its resolved path (``/tmp`` may be ``/private/tmp``).
    """
    pairs = {(form.rstrip("/"), label) for base, label in bases for form in (str(base), str(Path(base).resolve()))}
    for form, label in sorted(pairs, key=lambda p: -len(p[0])):
        if not form:  # the file system's root: nothing to make relative
            continue
        text = text.replace(form + "/", f"{label}/" if label else "")
        text = re.sub(re.escape(form) + r"(?![\w.-])", label or ".", text)
    return text


def write_notebook_outputs(nb, path: Path, ran_in: Path) -> Path:
    """Keep what each code cell of an executed notebook showed, for the page of its script.

    Parameters
    ----------
    nb : nbformat.NotebookNode
        The notebook of the jupytext script ``path``, executed (every output in place).
    path : Path
        The script.
    ran_in : Path
        The folder it ran in: paths under it (and under the repository and the home folder)
        are written relative, so no machine's path reaches the page.

    Returns
    -------
    Path
        ``outputs.json``: per code cell its source and outputs, each ``{"text": ...}`` (a repr,
        a printout) or ``{"image": "cell-NN-K.png"}`` (a figure, written beside it). Files are
        rewritten only when their content changed, each atomically.

    Raises
    ------
    ValueError
        A cell raised: a failing notebook's outputs are not kept.
    """
    folder = outputs_dir(path)
    folder.mkdir(exist_ok=True)
    bases = [(Path(ran_in), ""), (REPOSITORY, ""), (Path.home(), "~")]
    cells, images = [], {}
    for k, cell in enumerate(c for c in nb.cells if c.cell_type == "code"):
        shown = []
        for j, out in enumerate(cell.get("outputs", [])):
            kind = out.get("output_type")
            if kind == "error":
                raise ValueError(f"{path}: code cell {k} raised {out.get('ename')}: {out.get('evalue')}; "
                                 "its outputs are not kept")
            data = out.get("data", {})
            if kind == "stream":
                shown.append({"text": relative_paths(out["text"], bases)})
            elif "image/png" in data:
                name = f"cell-{k:02d}-{j}.png"
                images[name] = base64.b64decode(data["image/png"])
                shown.append({"image": name})
            elif "text/plain" in data:
                shown.append({"text": relative_paths(data["text/plain"], bases)})
        cells.append({"source": cell.source.strip("\n"), "outputs": shown})
    for name, png in images.items():
        _write_if_changed(folder / name, png)
    for old in folder.glob("cell-*.png"):
        if old.name not in images:
            old.unlink()
    index = json.dumps({"notebook": path.name, "cells": cells}, indent=1, ensure_ascii=False) + "\n"
    _write_if_changed(folder / OUTPUTS_INDEX, index.encode())
    return folder / OUTPUTS_INDEX


def _write_if_changed(path: Path, data: bytes) -> None:
    if path.is_file() and path.read_bytes() == data:
        return
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)  # a site built meanwhile reads the old file or the new one, never half of one


def _outputs_markdown(outputs: list[dict], folder: str) -> list[str]:
    out = []
    for o in outputs:
        if "image" in o:
            out += [f"![A figure the cell above drew]({folder}/{o['image']})", ""]
        elif o.get("text", "").strip():
            out += ["```text", o["text"].rstrip("\n"), "```", ""]
    return out


def notebook_markdown(path: Path, shown: str) -> str:
    """A jupytext percent script as Markdown: markdown cells as text, code cells as Python blocks,
    each followed by the outputs :func:`write_notebook_outputs` kept for it."""
    if not path.is_file():
        return (f"!!! note \"Not in this checkout\"\n    The notebook `{shown}` is not in this checkout of the "
                "repository; this page shows it once it is.")
    lines = path.read_text().splitlines()
    if lines and lines[0].strip() == "# ---":  # jupytext's header (kernel metadata): not part of the tutorial
        end = next((i for i in range(1, len(lines)) if lines[i].strip() == "# ---"), 0)
        lines = lines[end + 1:]
    cells: list[tuple[str, list[str]]] = []
    for line in lines:
        if line.startswith("# %%"):
            cells.append(("markdown" if "[markdown]" in line else "code", []))
        elif cells:
            cells[-1][1].append(line)
        elif line.strip():
            cells.append(("code", [line]))
    index = outputs_dir(path) / OUTPUTS_INDEX
    kept = json.loads(index.read_text())["cells"] if index.is_file() else []
    out: list[str] = []
    k, unmatched = 0, 0
    for kind, body in cells:
        text = "\n".join(body).strip("\n")
        if not text.strip():
            continue
        if kind == "markdown":
            out += [re.sub(r"^# ?", "", ln) for ln in text.splitlines()] + [""]
            continue
        out += ["```python", text, "```", ""]
        if k < len(kept) and kept[k]["source"] == text:
            out += _outputs_markdown(kept[k]["outputs"], outputs_dir(path).name)
        else:
            unmatched += 1
        k += 1
    if unmatched:
        note = ("no outputs were kept for this notebook" if not kept else
                f"{unmatched} of its {k} code cells differ from the ones that ran, and show no output")
        out = [f"!!! note \"Outputs\"\n    {note}: `pytest tests/test_tutorial_notebook.py` runs `{shown}` and "
               "keeps them.", ""] + out
    return "\n".join(out)


def root_command():
    """The Click command behind ``endocal``, every subcommand registered."""
    import typer

    from endocal.cli import app
    from endocal.cli import commands  # noqa: F401  (registers the subcommands on ``app``)

    return typer.main.get_command(app)


def walk_commands(command=None, ctx=None, name="endocal"):
    """Yield ``(context, command)`` for the root and every visible subcommand, depth first."""
    command = command if command is not None else root_command()
    ctx = command.context_class(command, info_name=name, parent=ctx)
    if getattr(command, "hidden", False):
        return
    yield ctx, command
    if hasattr(command, "list_commands"):
        for sub in command.list_commands(ctx):
            yield from walk_commands(command.get_command(ctx, sub), ctx, sub)


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "&#124;")


def cli_markdown() -> str:
    """Markdown for every command: help, usage, and the argument and option rows of ``--help``."""
    out = []
    for ctx, command in walk_commands():
        path = ctx.command_path
        depth = min(2 + path.count(" "), 4)
        out += [f"{'#' * depth} `{path}`", ""]
        if command.help:
            out += [textwrap.dedent(command.help).strip(), ""]
        out += ["```text", command.get_usage(ctx).removeprefix("Usage: ").strip(), "```", ""]
        rows = []
        for param in command.get_params(ctx):
            if getattr(param, "hidden", False):
                continue
            record = param.get_help_record(ctx)
            if record:
                rows.append(f"| `{_cell(record[0])}` | {_cell(record[1])} |")
        if rows:
            out += ["| argument / option | what it does |", "|---|---|", *rows, ""]
        if hasattr(command, "list_commands"):
            subs = []
            for sub in command.list_commands(ctx):
                cmd = command.get_command(ctx, sub)
                if not getattr(cmd, "hidden", False):
                    anchor = _slug(f"{path} {sub}")
                    subs.append(f"| [`{sub}`](#{anchor}) | {_cell(cmd.get_short_help_str(limit=200))} |")
            out += ["| command | what it does |", "|---|---|", *subs, ""]
    return "\n".join(out)


def _slug(text: str) -> str:
    # the toc extension's default slug of a heading `endocal fit hysteresis`
    return re.sub(r"[-\s]+", "-", re.sub(r"[^\w\s-]", "", text).strip().lower())


def effects_markdown() -> str:
    """The effect catalogue as Markdown, one section per effect, in ``endocal effects`` order."""
    from endocal.models.effects import EFFECTS, catalog

    out = []
    for info in catalog():
        cls = EFFECTS[info.name]
        units = getattr(cls, "units", {})
        params = ", ".join(f"`{info.name}_{p}`" + (f" ({u})" if u else "") for p, u in units.items()) or "none"
        out += [
            f"## `{info.name}`",
            "",
            f"| written | `--effects {info.usage}` |",
            "|---|---|",
            f"| kind | {info.kind} term |",
            f"| cause | {info.cause} |",
            f"| signature in the residual | {info.signature} |",
            f"| excited by | {info.protocol} |",
            f"| parameters | {params} |",
            f"| needs | {', '.join(info.needs) or 'command and measurement only'} |",
            f"| streaming compensation | {'yes' if info.streamable else 'no'} |",
            f"| the records must hold | {'; '.join(info.requires) or 'nothing beyond a reversal'} |",
            f"| looks like | {'; '.join(f'`{k}`: {v}' for k, v in info.lookalikes.items()) or 'none declared'} |",
            *([f"| other forms `validate` tries | {', '.join(f'`{v}` ({k} term)' for v, k in info.variants.items())} |"]
              if info.variants else []),
            "",
            "**Physics** (from `" + cls.__module__ + "`):",
            "",
            docstring_markdown(sys.modules[cls.__module__].__doc__ or ""),
            "",
        ]
    return "\n".join(out)


def docstring_markdown(doc: str) -> str:
    """A module docstring as Markdown: its ``::`` literal blocks become fenced code blocks."""
    lines = textwrap.dedent(doc).strip("\n").splitlines()
    # the first line is the summary ("``deadzone``: tendon slack ..."): the heading says the name
    if lines and re.match(r"``\w+``: ", lines[0]):
        summary = lines[0].split(": ", 1)[1]
        lines[0] = summary[:1].upper() + summary[1:]
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.rstrip().endswith("::"):
            out.append(re.sub(r"\s*::$", ":", line.rstrip()) if line.strip() != "::" else "")
            i += 1
            block = []
            while i < len(lines) and (not lines[i].strip() or lines[i].startswith((" ", "\t"))):
                block.append(lines[i])
                i += 1
            while block and not block[-1].strip():
                block.pop()
            out += ["", "```text", textwrap.dedent("\n".join(b for b in block)).strip("\n"), "```", ""]
            continue
        out.append(line)
        i += 1
    return _griffe_rst().rst_to_markdown("\n".join(out).strip())


@functools.cache
def _griffe_rst():
    """``griffe_rst.py`` beside this file (the rewrite mkdocstrings applies to docstrings)."""
    spec = importlib.util.spec_from_file_location("endocal_docs_griffe_rst", Path(__file__).with_name("griffe_rst.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
