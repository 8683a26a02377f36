"""Exit 2 with one line when the packages `make docs` needs are missing (instead of a traceback).

Usage: python scripts/check_docs_extra.py   (run by `make docs` before `mkdocs build`)
"""

from __future__ import annotations

import importlib.util
import sys

#: import name -> the package the `docs` extra installs it from
NEEDED = {"mkdocs": "mkdocs", "material": "mkdocs-material", "mkdocstrings": "mkdocstrings[python]",
          "mkdocstrings_handlers.python": "mkdocstrings[python]"}


def missing() -> list[str]:
    out = []
    for module, package in NEEDED.items():
        try:
            found = importlib.util.find_spec(module) is not None
        except ModuleNotFoundError:  # the parent package of a dotted name is absent
            found = False
        if not found and package not in out:
            out.append(package)
    return out


if __name__ == "__main__":
    absent = missing()
    if absent:
        print(f"error: building the documentation needs {', '.join(absent)}: install the docs extra "
              f"(pip install -e '.[docs]', or make install)", file=sys.stderr)
        sys.exit(2)
