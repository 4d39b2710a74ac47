# The two commands of the README: `make run` (set up, then the main job) and `make test`
# (set up, then every check and test). Both need only Python 3.11+ and the package registries.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: setup run demo test lint typecheck pytest bench clean

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "loceval needs Python 3.11 or newer; set PYTHON=python3.11")'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	@touch $(STAMP)

setup: $(STAMP)

run: demo

demo: setup
	$(BIN)/loceval demo --out out/demo

lint: setup
	$(BIN)/ruff check loceval exporters service tests benchmarks
	$(BIN)/ruff format --check loceval exporters service tests benchmarks

typecheck: setup
	$(BIN)/mypy

pytest: setup
	$(BIN)/python -m pytest -p no:cacheprovider

test: lint typecheck pytest

bench: setup
	$(BIN)/python -m benchmarks.core

clean:
	rm -rf $(VENV) out .mypy_cache .ruff_cache
