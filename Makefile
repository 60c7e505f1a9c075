# camtraj: everything runs inside a project-local virtual environment (.venv),
# created on first use from the machine's Python 3.11+.
#
#   make test                                   # with python3 into .venv
#   make test PYTHON=python3.13 VENV=.venv313   # the same with another Python, in its own venv
#   make bench ARGS=--quick                     # ARGS go to bench/run.py, pytest, make_samples.py
PYTHON ?= python3
VENV   ?= .venv
ARGS   ?=
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
MIN_PY := 3.11

.PHONY: all demo test lint typecheck unit bench clean samples check-python chromium readme

all: demo

# One line, before anything is installed, when the Python or the venv cannot work: a too-old
# or missing $(PYTHON), a venv whose interpreter no longer runs (moved, uninstalled) or is too
# old (made by an old python3), or a venv of another version than an explicit PYTHON=.
PY_VERSION := import sys; print("%d.%d" % sys.version_info[:2])
PY_TOO_OLD := import sys; sys.exit(sys.version_info[:2] < (3, 11))
check-python:
	@if [ -e "$(VENV)" ]; then \
	  have=$$("$(BIN)/python" -c '$(PY_VERSION)' 2>/dev/null) || { \
	    echo "make: $(VENV) is broken ($(BIN)/python does not run): run 'make clean VENV=$(VENV)', then make again" >&2; exit 1; }; \
	  "$(BIN)/python" -c '$(PY_TOO_OLD)' || { \
	    echo "make: $(VENV) was made by Python $$have; camtraj needs $(MIN_PY) or newer: run 'make clean VENV=$(VENV)', then make PYTHON=python$(MIN_PY) (or newer)" >&2; exit 1; }; \
	  if [ "$(origin PYTHON)" != file ]; then \
	    want=$$($(PYTHON) -c '$(PY_VERSION)' 2>/dev/null); \
	    [ "$$want" = "$$have" ] || { \
	      echo "make: $(VENV) is Python $$have, not PYTHON=$(PYTHON) ($${want:-not found}): use its own venv (make ... PYTHON=$(PYTHON) VENV=.venv$$(echo $$want | tr -d .)) or run 'make clean VENV=$(VENV)'" >&2; exit 1; }; \
	  fi; \
	else \
	  have=$$($(PYTHON) -c '$(PY_VERSION)' 2>/dev/null) || { \
	    echo "make: PYTHON=$(PYTHON) is not a Python that runs; camtraj needs $(MIN_PY) or newer: run make PYTHON=python$(MIN_PY) (or newer)" >&2; exit 1; }; \
	  $(PYTHON) -c '$(PY_TOO_OLD)' || { \
	    echo "make: $(PYTHON) is Python $$have; camtraj needs $(MIN_PY) or newer: run make PYTHON=python$(MIN_PY) (or newer)" >&2; exit 1; }; \
	fi

$(STAMP): pyproject.toml | check-python
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV) || { rm -rf $(VENV); \
	  echo "make: $(PYTHON) -m venv failed (on Debian/Ubuntu: apt install python3-venv); nothing was kept" >&2; exit 1; }
	@$(BIN)/python -m pip --version >/dev/null 2>&1 || { \
	  echo "make: $(VENV) has no pip (made without ensurepip?): run 'make clean VENV=$(VENV)', then make again" >&2; exit 1; }
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,farm]'
	@touch $@

# Install, then run the main job on a shipped sample.
demo: $(STAMP)
	@mkdir -p out
	$(BIN)/camtraj convert samples/shots/blender_crane_up.usda -o out/blender_crane_up.mcap
	$(BIN)/camtraj info out/blender_crane_up.mcap

# The whole test command: lint, types, then the test suite.
test: lint typecheck unit

lint: $(STAMP)
	$(BIN)/ruff check camtraj tests samples pipelines bench

typecheck: $(STAMP)
	$(BIN)/mypy camtraj

# The suite on every core (pytest-xdist), a test file per worker: module fixtures such as
# the shot set's solves run once. One worker more than the cores: many tests wait on the
# camtraj processes they start, and with a worker per core a quarter of the cores' time
# went idle (two cores: 733 s of pytest with two workers, 608-619 s with three).
WORKERS ?= $(shell echo $$(( $$(getconf _NPROCESSORS_ONLN 2>/dev/null || echo 1) + 1 )))
unit: $(STAMP) $(if $(filter true,$(CI)),chromium)
	$(BIN)/pytest -n $(WORKERS) --dist loadfile $(ARGS)

# Headless Chromium renders the HTML report in the tests (they skip, saying so, without it).
# Idempotent: installs the Debian package only when no chromium is on the PATH. `make test`
# runs it when CI=true.
chromium:
	@command -v chromium >/dev/null || (apt-get update && apt-get install -y --no-install-recommends chromium)

bench: $(STAMP)
	$(BIN)/python bench/run.py $(ARGS)

samples: $(STAMP)
	$(BIN)/python samples/shots/make_samples.py $(ARGS)

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache

# Rewrite the example outputs (```console blocks) of README.md and pipelines/README.md with what
# camtraj prints now; tests/test_readme.py fails until they agree (run this after a change that
# moves a number, then read the diff).
readme: $(STAMP)
	$(BIN)/python tests/readme_examples.py --write
