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
"""

from __future__ import annotations

import functools
import importlib.util
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


def notebook_markdown(path: Path, shown: str) -> str:
    """A jupytext percent script as Markdown: markdown cells as text, code cells as Python blocks."""
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
    out: list[str] = []
    for kind, body in cells:
        text = "\n".join(body).strip("\n")
        if not text.strip():
            continue
        if kind == "markdown":
            out += [re.sub(r"^# ?", "", ln) for ln in text.splitlines()] + [""]
        else:
            out += ["```python", text, "```", ""]
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
