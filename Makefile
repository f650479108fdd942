# sim2radar — one-command setup, main job, tests and benchmarks.
#   make demo    set up (once) and run the main job on the built-in default
#   make test    set up (once) and run the test suite
SHELL := /bin/bash
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
export PREFECT_HOME ?= $(CURDIR)/.prefect
export PREFECT_SERVER_ANALYTICS_ENABLED ?= false
export PREFECT_LOGGING_LEVEL ?= WARNING
OUT ?= out
# test processes (pytest-xdist); 0 runs the suite in this one process
TEST_WORKERS ?= 2
# extra pytest arguments, e.g. PYTEST_ARGS=--reverse-within-modules
PYTEST_ARGS ?=
PYTEST = $(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist worksteal $(PYTEST_ARGS)

.PHONY: setup demo test test-all bench lint clean

$(BIN)/.installed: pyproject.toml
	@# Mitsuba's LLVM variants need libllvm19 (LLVM 14 is refused, 15/16 crash): docs/design.md
	@if ! ldconfig -p | grep -q 'libLLVM.so.19\|libLLVM-19'; then \
	  echo "[setup] installing libllvm19 (apt)"; \
	  SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  $$SUDO apt-get update -qq && $$SUDO apt-get install -y -qq libllvm19 >/dev/null; \
	fi
	@# the dashboard's browser tests drive Debian's Chromium through Playwright (no browser
	@# downloads: `playwright install` is never run)
	@if [ ! -x /usr/bin/chromium ] && command -v apt-get >/dev/null; then \
	  echo "[setup] installing chromium (apt)"; \
	  SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  ( $$SUDO apt-get update -qq && $$SUDO apt-get install -y -qq chromium >/dev/null ) \
	    || echo "[setup] could not install chromium: the browser tests will fail until it is installed"; \
	fi
	@# the Prefect-server-on-PostgreSQL test (tests/deploy) runs Debian's server binaries from
	@# /usr/lib/postgresql/<version>/bin on a temporary cluster of its own (no service needed)
	@if ! ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1 && command -v apt-get >/dev/null; then \
	  echo "[setup] installing postgresql (apt)"; \
	  SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  ( $$SUDO apt-get update -qq && $$SUDO env DEBIAN_FRONTEND=noninteractive \
	      apt-get install -y -qq --no-install-recommends postgresql >/dev/null ) \
	    || echo "[setup] could not install postgresql: the Postgres-backed Prefect server test will fail until it is installed"; \
	fi
	@[ -x $(BIN)/python ] || $(PY) -m venv $(VENV)
	@# torch first, pinned: any other spec downloads the multi-GB CUDA build (docs/design.md)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q torch==2.13.0
	$(BIN)/python -m pip install -q -e '.[dev]'
	@touch $@

setup: $(BIN)/.installed

demo: setup
	$(BIN)/sim2radar demo --out $(OUT)

test: setup
	$(PYTEST)

test-all: setup
	$(PYTEST) -m ''

bench: setup
	$(BIN)/python -m benchmarks

lint: setup
	$(BIN)/ruff check .

clean:
	rm -rf $(OUT) .pytest_cache .ruff_cache
