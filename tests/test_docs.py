"""The documentation site: `mkdocs build --strict` passes, and its generated pages say what the code says.

Skipped only when mkdocs is not installed (`make install` installs the docs extra, so the suite
runs it). The CLI reference is checked against the command tree itself, walked through Click's
API independently of the hook that writes the page: every command and every option of every
command appears in that command's own section of the built page.
"""

from __future__ import annotations

import html
import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mkdocs")
pytest.importorskip("material")
pytest.importorskip("mkdocstrings")

ROOT = Path(__file__).resolve().parents[1]


def _env() -> dict:
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    return env


def _build(config: Path, site: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(config),
                           "--site-dir", str(site)], capture_output=True, text=True, cwd=ROOT, env=_env())


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site")
    proc = _build(ROOT / "mkdocs.yml", out)
    assert proc.returncode == 0, proc.stderr[-4000:]
    return out


def _text(page: Path) -> str:
    return html.unescape(re.sub(r"<[^>]+>", "", page.read_text()))


def _sections(page: Path) -> dict[str, str]:
    """Text under each heading of a built page, by the heading's id."""
    raw = page.read_text()
    heads = list(re.finditer(r'<h[1-6] id="([^"]+)"', raw))
    return {m.group(1): html.unescape(re.sub(r"<[^>]+>", "", raw[m.end():nxt.start() if nxt else len(raw)]))
            for m, nxt in zip(heads, heads[1:] + [None])}


def _commands():
    """(command path, option strings) for the root and every visible subcommand of `endocal`."""
    import typer

    from endocal.cli import app
    from endocal.cli import commands  # noqa: F401  (registers the subcommands)

    def walk(cmd, ctx, name):
        ctx = cmd.context_class(cmd, info_name=name, parent=ctx)
        if getattr(cmd, "hidden", False):
            return
        opts = [o for p in cmd.get_params(ctx) if p.param_type_name == "option" and not getattr(p, "hidden", False)
                for o in [*p.opts, *p.secondary_opts]]
        yield ctx.command_path, opts
        for sub in getattr(cmd, "list_commands", lambda _ctx: [])(ctx):
            yield from walk(cmd.get_command(ctx, sub), ctx, sub)

    return list(walk(typer.main.get_command(app), None, "endocal"))


def test_every_nav_page_is_built(site):
    import yaml

    nav = yaml.safe_load((ROOT / "mkdocs.yml").read_text())["nav"]

    def pages(items):
        for item in items:
            value = next(iter(item.values())) if isinstance(item, dict) else item
            yield from (pages(value) if isinstance(value, list) else [value])

    built = [site / Path(p).with_suffix(".html") for p in pages(nav)]
    assert len(built) >= 25 and all(p.is_file() for p in built), [p for p in built if not p.is_file()]


def test_cli_reference_shows_every_command_and_option_in_its_own_section(site):
    sections = _sections(site / "reference" / "cli.html")
    cmds = _commands()
    assert len(cmds) >= 20  # root, 7 commands, 4 groups and their subcommands
    for path, opts in cmds:
        slug = re.sub(r"[-\s]+", "-", path)
        assert slug in sections, f"no section for `{path}` in reference/cli.html"
        missing = [o for o in opts if not re.search(rf"(?<![\w-]){re.escape(o)}(?![\w-])", sections[slug])]
        assert not missing, f"`{path}`: options {missing} are not on its reference section"
    # the rows are --help's own: a default and a required marker as the terminal prints them
    hyst = sections["endocal-fit-hysteresis"]
    assert "[default: pi]" in hyst and "[required]" in hyst


def test_effect_catalogue_has_every_effect_with_its_physics(site):
    from endocal.models.effects import catalog

    sections = _sections(site / "reference" / "effects.html")
    for info in catalog():
        text = sections.get(info.name, "")
        assert info.cause[:40] in text and info.protocol[:30] in text, info.name
    assert "s_k = clip(p_k, x_k - h, x_k + h)" in sections["deadzone"]  # the module docstring's equation, verbatim


def test_strict_build_fails_on_a_broken_link(tmp_path):
    # the project's own settings (INHERIT) on a one-page site whose page links to nothing
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "index.md").write_text("# t\n\nSee [the missing page](missing.md).\n")
    (tmp_path / "mkdocs.yml").write_text(f"INHERIT: {ROOT / 'mkdocs.yml'}\ndocs_dir: {tmp_path / 'docs'}\n"
                                         "hooks: []\nnav:\n  - index.md\n")
    proc = _build(tmp_path / "mkdocs.yml", tmp_path / "site")
    assert proc.returncode != 0 and "missing.md" in proc.stderr, proc.stderr[-2000:]


def test_make_docs_without_the_docs_extra_says_so_in_one_line():
    # -S: no site-packages, so no mkdocs: what `make docs` meets in a venv without the docs extra
    proc = subprocess.run([sys.executable, "-S", str(ROOT / "scripts" / "check_docs_extra.py")],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and "pip install -e '.[docs]'" in proc.stderr, proc.stderr
    ok = subprocess.run([sys.executable, str(ROOT / "scripts" / "check_docs_extra.py")], capture_output=True, text=True)
    assert ok.returncode == 0 and ok.stderr == ""


def test_a_jupytext_notebook_renders_as_text_and_code(tmp_path):
    spec = importlib.util.spec_from_file_location("endocal_docs_hooks", ROOT / "docs" / "hooks" / "endocal_docs.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    nb = tmp_path / "nb.py"
    nb.write_text("# ---\n# jupyter:\n#   kernelspec: {}\n# ---\n\n# %% [markdown]\n# # Title\n#\n# Some *text*.\n\n"
                  "# %%\nimport endocal\nprint(1)\n")
    md = hooks.notebook_markdown(nb, "nb.py")
    assert "# Title\n\nSome *text*." in md and "```python\nimport endocal\nprint(1)\n```" in md
    assert "kernelspec" not in md
    assert "Not in this checkout" in hooks.notebook_markdown(tmp_path / "absent.py", "absent.py")


def test_a_notebook_page_shows_each_cells_outputs_with_paths_made_relative(tmp_path):
    import base64

    import nbformat

    spec = importlib.util.spec_from_file_location("endocal_docs_hooks", ROOT / "docs" / "hooks" / "endocal_docs.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    script = tmp_path / "nb.py"
    script.write_text("# %% [markdown]\n# # Title\n\n# %%\nrun = make()\nrun\n\n# %%\nrun.plot()\n")
    ran_in = tmp_path / "ran"
    png = base64.b64encode(b"\x89PNG fake").decode()
    v4 = nbformat.v4
    nb = v4.new_notebook(cells=[
        v4.new_markdown_cell("# Title"),
        v4.new_code_cell("run = make()\nrun", outputs=[
            v4.new_output("stream", name="stdout", text=f"wrote {ran_in}/out/run.json\n"),
            v4.new_output("execute_result", data={"text/plain": f"Run '{ran_in / 'out'}' in {ran_in}, {ROOT}/docs"},
                          execution_count=1)]),
        v4.new_code_cell("run.plot()", outputs=[v4.new_output("display_data", data={
            "image/png": png, "text/plain": "<Figure>"})]),
    ])
    index = hooks.write_notebook_outputs(nb, script, ran_in)
    assert index == tmp_path / "nb_outputs" / "outputs.json" and (tmp_path / "nb_outputs" / "cell-01-0.png").is_file()
    md = hooks.notebook_markdown(script, "nb.py")
    # a machine path is written relative: to the folder the notebook ran in, to the repository
    assert "```text\nwrote out/run.json\n```" in md and "```text\nRun 'out' in ., docs\n```" in md
    assert str(tmp_path) not in md and str(ROOT) not in md
    assert "```python\nrun.plot()\n```\n\n![A figure the cell above drew](nb_outputs/cell-01-0.png)" in md
    assert "<Figure>" not in md and "Outputs" not in md
    # a cell edited since it ran shows no output (never another cell's), and the page says so
    script.write_text(script.read_text().replace("run.plot()", "run.plot('loop')"))
    md = hooks.notebook_markdown(script, "nb.py")
    assert "cell-01-0.png" not in md and "1 of its 2 code cells differ from the ones that ran" in md
    assert "wrote out/run.json" in md
    # a cell that raised: nothing kept
    nb.cells[2].outputs = [v4.new_output("error", ename="KeyError", evalue="'x'", traceback=[])]
    with pytest.raises(ValueError, match="code cell 1 raised KeyError"):
        hooks.write_notebook_outputs(nb, script, ran_in)


def test_api_reference_renders_the_docstrings_rst_as_markdown(site):
    page = (site / "reference" / "api.html").read_text()
    text = _text(site / "reference" / "api.html")
    assert ":func:`" not in text and ":class:`" not in text  # Sphinx roles rewritten (docs/hooks/griffe_rst.py)
    assert re.search(r"<td><code>fit_planes</code></td>\s*<td><code>Planes</code></td>", page)  # the simple table
    ids = set(re.findall(r'id="([\w.]+)"', page))
    for name in ("endocal.api.load_run", "endocal.api.fit", "endocal.api.validate", "endocal.api.Validation",
                 "endocal.validation.offline.validate_offline", "endocal.runs.aligned.load_aligned"):
        assert name in ids, name
