# The two commands of the README: `make serve` (set up, then start the service) and `make test`
# (set up with the dev tools, then every check and test). Both need only Python 3.11+ and the
# package registries. The Dockerfile runs `make setup`, so the container installs what we test.
# Installs come from the hash-pinned lock files in requirements/ (`make lock` refreshes them);
# pyproject.toml keeps the `>=` ranges for people who install loceval as a library.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DEVSTAMP := $(VENV)/.installed-dev

.PHONY: setup setup-dev serve run demo test lint typecheck pytest bench clean lock vendor-swagger-ui vendor-three vendor-tus-js-client

LOCK_PYTHON := 3.11
PIP_LOCKED := $(BIN)/python -m pip install --quiet --require-hashes --only-binary=:all:

$(STAMP): pyproject.toml requirements/runtime.lock requirements/build.lock
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "loceval needs Python 3.11 or newer; set PYTHON=python3.11")'
	$(PYTHON) -m venv $(VENV)
	$(PIP_LOCKED) -r requirements/build.lock -r requirements/runtime.lock
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	@touch $(STAMP)

$(DEVSTAMP): $(STAMP) requirements/dev.lock
	$(PIP_LOCKED) -r requirements/dev.lock
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

# Refresh the lock files after changing a dependency in pyproject.toml (or to take new
# releases): uv resolves for Python $(LOCK_PYTHON) on every platform and writes the hashes of
# every wheel; uv runs from a scratch environment, it is not a dependency.
lock:
	$(PYTHON) -m venv .lockenv
	.lockenv/bin/python -m pip install --quiet uv
	.lockenv/bin/uv pip compile pyproject.toml --extra dev --generate-hashes --universal \
		--python-version $(LOCK_PYTHON) --no-header -o requirements/dev.lock
	.lockenv/bin/uv pip compile pyproject.toml --extra all --generate-hashes --universal \
		--python-version $(LOCK_PYTHON) --no-header -c requirements/dev.lock -o requirements/runtime.lock
	.lockenv/bin/uv pip compile requirements/build.in --generate-hashes --universal \
		--python-version $(LOCK_PYTHON) --no-header -o requirements/build.lock
	rm -rf .lockenv

# Refresh the Swagger UI that /docs serves (templates/web/vendor/swagger-ui; see its README):
# `make vendor-swagger-ui SWAGGER_UI_VERSION=5.x.y`, then run tests/service/api/test_docs_browser.py.
# npm checks the package against the registry's sha512; the files /docs needs, their licences
# and their SHA-256 sums (checked by the tests) are written; node and npm are needed only here.
SWAGGER_UI_VERSION ?= 5.35.0
SWAGGER_UI_DIR := templates/web/vendor/swagger-ui
SWAGGER_UI_FILES := swagger-ui-bundle.js swagger-ui.css favicon-32x32.png LICENSE NOTICE \
	swagger-ui-bundle.js.LICENSE.txt

vendor-swagger-ui:
	rm -rf .swagger-ui && mkdir .swagger-ui
	cd .swagger-ui && npm pack --silent swagger-ui-dist@$(SWAGGER_UI_VERSION) >/dev/null \
		&& tar -xzf swagger-ui-dist-$(SWAGGER_UI_VERSION).tgz
	mkdir -p $(SWAGGER_UI_DIR)
	cd .swagger-ui/package && cp $(SWAGGER_UI_FILES) $(CURDIR)/$(SWAGGER_UI_DIR)/
	echo $(SWAGGER_UI_VERSION) > $(SWAGGER_UI_DIR)/VERSION
	cd $(SWAGGER_UI_DIR) && sha256sum $(SWAGGER_UI_FILES) > SHA256SUMS
	rm -rf .swagger-ui

# Refresh the vendored three.js (templates/vendor/three) from the npm registry: the module
# build and its licence, byte for byte; then put the printed version and SHA-256 into
# exporters/viewer/vendor.py (THREE_VERSION, THREE_SHA256), which tests/exporters/viewer/test_viewer.py
# checks the file against.
THREE_VERSION ?= 0.170.0
vendor-three:
	rm -rf .vendor-three && mkdir .vendor-three
	cd .vendor-three && npm pack --silent three@$(THREE_VERSION) && tar xzf three-$(THREE_VERSION).tgz
	cp .vendor-three/package/build/three.module.min.js .vendor-three/package/LICENSE templates/vendor/three/
	@echo "three $(THREE_VERSION): sha256 $$(sha256sum templates/vendor/three/three.module.min.js | cut -d' ' -f1)"
	rm -rf .vendor-three

# Refresh the vendored tus-js-client (templates/web/vendor/tus-js-client; see its README), the
# page's resumable upload client: `make vendor-tus-js-client TUS_JS_CLIENT_VERSION=4.x.y`, then
# run tests/service/api/test_web_upload_browser.py. npm checks the package against the registry's
# sha512; the browser bundle and the licence are copied byte for byte with their SHA-256 sums.
TUS_JS_CLIENT_VERSION ?= 4.3.1
TUS_JS_CLIENT_DIR := templates/web/vendor/tus-js-client
vendor-tus-js-client:
	rm -rf .vendor-tus && mkdir .vendor-tus
	cd .vendor-tus && npm pack --silent tus-js-client@$(TUS_JS_CLIENT_VERSION) >/dev/null \
		&& tar xzf tus-js-client-$(TUS_JS_CLIENT_VERSION).tgz
	mkdir -p $(TUS_JS_CLIENT_DIR)
	cp .vendor-tus/package/dist/tus.min.js .vendor-tus/package/LICENSE $(TUS_JS_CLIENT_DIR)/
	echo $(TUS_JS_CLIENT_VERSION) > $(TUS_JS_CLIENT_DIR)/VERSION
	cd $(TUS_JS_CLIENT_DIR) && sha256sum tus.min.js LICENSE > SHA256SUMS
	rm -rf .vendor-tus

clean:
	rm -rf $(VENV) out var .mypy_cache .ruff_cache
