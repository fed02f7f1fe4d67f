# geosmooth: two commands on a fresh Debian 12 machine (python3 + make):
#   make run    install what is needed, start the service on 127.0.0.1:8000 (embedded queue, no Redis)
#   make test   install what is needed (with dev tools), run ruff, mypy and the whole test suite
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
HOST ?= 127.0.0.1
PORT ?= 8000

.PHONY: run test setup setup-dev lint openapi bench clean

$(BIN)/python:
	scripts/install-system-deps.sh
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip

# The client package (clients/python, pure Python) first: the server package depends on it.
$(VENV)/.installed: pyproject.toml clients/python/pyproject.toml | $(BIN)/python
	scripts/install-system-deps.sh
	$(BIN)/pip install -q -e clients/python
	$(BIN)/pip install -q -e .
	touch $@

$(VENV)/.installed-dev: pyproject.toml $(VENV)/.installed
	$(BIN)/pip install -q -e '.[dev]'
	touch $@

setup: $(VENV)/.installed
setup-dev: $(VENV)/.installed-dev

run: setup
	$(BIN)/geosmooth serve --host $(HOST) --port $(PORT)

lint: setup-dev
	$(BIN)/ruff check .

# The suite on every core (pytest-xdist; TEST_WORKERS=0 runs it in this process), then the few
# tests marked `serial` (they load the whole machine) one at a time. tests/conftest.py says which
# tests share a worker; tests/timing.py why no bound breaks on a busy machine.
TEST_WORKERS ?= auto
test: setup-dev
	$(BIN)/ruff check .
	$(BIN)/mypy service geosmooth
	$(BIN)/python -m pytest -q --durations=25 -n $(TEST_WORKERS) --dist loadgroup -m "not serial"
	$(BIN)/python -m pytest -q --durations=5 -p no:xdist -m serial

openapi: setup
	$(BIN)/python -m service.api.openapi_export openapi/openapi.json

bench: setup
	scripts/install-system-deps.sh --bench
	$(BIN)/pip install -q -e '.[bench]'
	$(BIN)/python -m benchmarks

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
