# camtraj: everything runs inside a project-local virtual environment (.venv),
# created on first use from the machine's Python 3.11+.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: all demo test lint typecheck unit bench clean samples chromium

all: demo

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
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

unit: $(STAMP) $(if $(filter true,$(CI)),chromium)
	$(BIN)/pytest

# Headless Chromium renders the HTML report in the tests (they skip, saying so, without it).
# Idempotent: installs the Debian package only when no chromium is on the PATH. `make test`
# runs it when CI=true.
chromium:
	@command -v chromium >/dev/null || (apt-get update && apt-get install -y --no-install-recommends chromium)

bench: $(STAMP)
	$(BIN)/python bench/run.py

samples: $(STAMP)
	$(BIN)/python samples/shots/make_samples.py

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache
