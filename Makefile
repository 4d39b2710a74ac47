# The two commands of the README: `make serve` (set up, then start the service) and `make test`
# (set up with the dev tools, then every check and test). Both need only Python 3.11+ and the
# package registries. The Dockerfile runs `make setup`, so the container installs what we test.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DEVSTAMP := $(VENV)/.installed-dev

.PHONY: setup setup-dev serve run demo test lint typecheck pytest bench clean

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "loceval needs Python 3.11 or newer; set PYTHON=python3.11")'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[all]"
	@touch $(STAMP)

$(DEVSTAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	@touch $(DEVSTAMP)

setup: $(STAMP)

setup-dev: $(DEVSTAMP)

serve: setup
	$(BIN)/loceval serve

run: serve

demo: setup
	$(BIN)/loceval demo --out out/demo

lint: setup-dev
	$(BIN)/ruff check loceval exporters service tests benchmarks
	$(BIN)/ruff format --check loceval exporters service tests benchmarks

typecheck: setup-dev
	$(BIN)/mypy

pytest: setup-dev
	$(BIN)/python -m pytest -p no:cacheprovider

test: lint typecheck pytest

bench: setup-dev
	$(BIN)/python -m benchmarks.core

clean:
	rm -rf $(VENV) out var .mypy_cache .ruff_cache
