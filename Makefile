# Two commands set everything up on a fresh machine: `make demo` and `make test`; `make docs` builds the site.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
DEMO   := demo-out

.PHONY: install compile test test-slow wheel-check demo bench docs clean data-samples

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,ros,aurora,docs,mcap,fleet]'
	touch $(STAMP)

# endocal's modules compiled to bytecode, as pip compiles a wheel's at install: an editable install is read
# from the source tree, and where PYTHONDONTWRITEBYTECODE is set (it is on this workplace's machines) every command
# would compile the modules it imports afresh (0.13 s of each `endocal validate`; bench/bench_loop.py).
# Quick when nothing changed; run before the targets that time or start many commands.
compile: $(STAMP)
	@$(BIN)/python -m compileall -q endocal

install: $(STAMP)

# One worker per core (pytest-xdist); a test file stays on one worker, so its module fixtures run once.
# Files in collection order, the longest first (tests/conftest.py, LONGEST_FIRST), not by test count.
test: compile
	$(BIN)/python -m pytest -n auto --dist loadfile --no-loadscope-reorder --durations=12

# The suites marked slow (minutes each: the closed loop of hidden effects), outside `make test`.
test-slow: compile
	$(BIN)/python -m pytest -n auto --dist loadfile --no-loadscope-reorder -m slow --durations=12

# The wheel a user installs: built (sdist, then wheel), installed into a fresh venv, and run outside
# the source tree (`endocal --help`, the demo's first command); scripts/wheel_check.sh.
wheel-check: $(STAMP)
	PYTHON=$(PYTHON) bash scripts/wheel_check.sh $(BIN)/python

demo: compile
	bash scripts/demo.sh $(DEMO)

bench: compile
	@for b in bench/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

# The documentation site into site/ (open site/index.html; mkdocs.yml, docs/). Without the docs
# extra installed: one line saying so, exit code 2.
docs: $(STAMP)
	@$(BIN)/python scripts/check_docs_extra.py
	NO_MKDOCS_2_WARNING=1 $(BIN)/python -m mkdocs build --strict --site-dir site

# Regenerates the small simulator runs in data_samples/ (see data_samples/README.md).
data-samples: $(STAMP)
	$(BIN)/python data_samples/make_samples.py data_samples

clean:
	rm -rf $(VENV) $(DEMO) .pytest_cache site
