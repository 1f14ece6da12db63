# grail-bench: `make demo` and `make test` set up .venv on first use.
VENV   ?= .venv
# The lowest versions pyproject.toml's ranges admit (constraints-lowest.txt), for `make test-lowest`.
LOWEST ?= .venv-lowest
PYTHON ?= python3
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.grail-bench-installed
LOWEST_STAMP := $(LOWEST)/.grail-bench-installed

.PHONY: demo test test-fast test-lowest bench clean

# $(1): the venv, $(2): its constraints file.
define install
	test -x $(1)/bin/python || $(PYTHON) -m venv $(1)
	# torch first: the CPU build (a plain torch requirement pulls CUDA wheels).
	$(1)/bin/python -m pip install --quiet torch==2.13.0
	$(1)/bin/python -m pip install --quiet -c $(2) -e ".[test]"
	$(1)/bin/python -m pip check
	touch $(1)/.grail-bench-installed
endef

$(STAMP): pyproject.toml constraints.txt
	$(call install,$(VENV),constraints.txt)

$(LOWEST_STAMP): pyproject.toml constraints-lowest.txt
	$(call install,$(LOWEST),constraints-lowest.txt)

demo: $(STAMP)
	$(VENV)/bin/grail-bench run

# Tests run on every core (pytest-xdist); benchmarks stay serial (`make bench`), so their timings stay clean.
test: $(STAMP)
	$(VENV)/bin/lint-imports
	$(PY) -m pytest -n logical --dist worksteal

test-fast: $(STAMP)
	$(PY) -m pytest -n logical --dist worksteal -m "not slow"

# The fast tests on the lowest versions the ranges admit, so the ranges stay true.
test-lowest: $(LOWEST_STAMP)
	$(LOWEST)/bin/lint-imports
	$(LOWEST)/bin/python -m pytest -n logical --dist worksteal -m "not slow"

bench: $(STAMP)
	$(PY) -m pytest tests/benchmarks --benchmark-only --benchmark-columns=min,median,max,rounds

clean:
	rm -rf $(VENV) $(LOWEST) .pytest_cache .benchmarks *.egg-info
