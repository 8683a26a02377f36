# Two commands set everything up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
DEMO   := demo-out

.PHONY: install test test-slow demo bench clean data-samples

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,ros,aurora]'
	touch $(STAMP)

install: $(STAMP)

# One worker per core (pytest-xdist); a test file stays on one worker, so its module fixtures run once.
test: $(STAMP)
	$(BIN)/python -m pytest -n auto --dist loadfile --durations=12

# The suites marked slow (minutes each: the closed loop of hidden effects), outside `make test`.
test-slow: $(STAMP)
	$(BIN)/python -m pytest -n auto --dist loadfile -m slow --durations=12

demo: $(STAMP)
	bash scripts/demo.sh $(DEMO)

bench: $(STAMP)
	@for b in bench/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

# Regenerates the small simulator runs in data_samples/ (see data_samples/README.md).
data-samples: $(STAMP)
	$(BIN)/python data_samples/make_samples.py

clean:
	rm -rf $(VENV) $(DEMO) .pytest_cache
