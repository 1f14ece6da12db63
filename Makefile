# grail-bench: `make demo` and `make test` set up .venv on first use.
VENV   ?= .venv
PYTHON ?= python3
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.grail-bench-installed

.PHONY: demo test test-fast bench clean

$(STAMP): pyproject.toml constraints.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	# torch first: the pinned CPU build (a looser requirement pulls CUDA wheels).
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -c constraints.txt -e ".[test]"
	$(PY) -m pip check
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/grail-bench run

# Tests run on every core (pytest-xdist); benchmarks stay serial (`make bench`), so their timings stay clean.
test: $(STAMP)
	$(VENV)/bin/lint-imports
	$(PY) -m pytest -n logical --dist worksteal

test-fast: $(STAMP)
	$(PY) -m pytest -n logical --dist worksteal -m "not slow"

bench: $(STAMP)
	$(PY) -m pytest tests/benchmarks --benchmark-only --benchmark-columns=min,median,max,rounds

clean:
	rm -rf $(VENV) .pytest_cache .benchmarks *.egg-info
