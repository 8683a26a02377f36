"""A griffe extension: the reStructuredText left in endocal's docstrings, as Markdown.

endocal's docstrings are numpydoc, read by mkdocstrings as Markdown, but some carry Sphinx
roles (``:func:`load_run```, ``:class:`~endocal.errors.EndocalError```), ``::`` before a
literal block, and simple tables (``=====  =====``). Rendered raw, the roles show their colons
and a table collapses into one paragraph. Each docstring is rewritten before it is parsed:
a role becomes inline code of its target's last name, ``::`` a colon, a simple table a
Markdown table. Loaded by mkdocs.yml (``extensions``) from this file's path.
"""

from __future__ import annotations

import re

from griffe import Extension

ROLE = re.compile(r":(?:py:)?(?:func|class|mod|meth|attr|data|exc|obj|const|ref|term):`~?([^`<]+?)(?:\s*<[^>]+>)?`")
BORDER = re.compile(r"^(\s*)(=+)((?:\s+=+)+)\s*$")


def rst_to_markdown(text: str) -> str:
    """``text`` with Sphinx roles, ``::`` markers and simple tables rewritten as Markdown."""
    text = _tables(text)  # first: the columns are where the roles still are
    text = ROLE.sub(lambda m: f"`{m.group(1).split('.')[-1] if m.group(0).count('~') else m.group(1)}`", text)
    return re.sub(r"(\S)::[ \t]*$", r"\1:", text, flags=re.M)


def _tables(text: str) -> str:
    lines = text.split("\n")
    out: list[str] = []
    i = 0
    while i < len(lines):
        m = BORDER.match(lines[i])
        if not m:
            out.append(lines[i])
            i += 1
            continue
        spans = [(c.start(), c.end()) for c in re.finditer(r"=+", lines[i])]
        borders = [i]
        j = i + 1
        while j < len(lines) and lines[j].strip() and len(borders) < 3:
            if BORDER.match(lines[j]):
                borders.append(j)
            j += 1
        if len(borders) < 3:  # not a header + body table: leave it
            out.append(lines[i])
            i += 1
            continue

        def cells(line: str) -> list[str]:
            edges = [s for s, _ in spans] + [None]
            return [line[a:b].strip() if b is not None else line[a:].strip() for a, b in zip(edges, edges[1:])]

        header = [cells(ln) for ln in lines[borders[0] + 1:borders[1]]]
        body = [cells(ln) for ln in lines[borders[1] + 1:borders[2]] if ln.strip()]
        indent = m.group(1)
        out.append(indent + "| " + " | ".join(" ".join(c) for c in zip(*header)) + " |")
        out.append(indent + "|" + "---|" * len(spans))
        out += [indent + "| " + " | ".join(row) + " |" for row in body]
        i = borders[2] + 1
    return "\n".join(out)


class RstToMarkdown(Extension):
    """Rewrite every docstring (:func:`rst_to_markdown`) when griffe creates its object."""

    def on_instance(self, *, obj, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = rst_to_markdown(obj.docstring.value)
