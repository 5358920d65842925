# Two commands: `make demo` and `make test`. Each sets itself up from nothing.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test setup system-deps bench bench-service clean

setup: $(STAMP) system-deps

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[service,scale,dev]'
	@touch $(STAMP)

# System tools from Debian's packages, installed only where missing.
system-deps:
	@if ! command -v dot >/dev/null 2>&1; then \
	  if command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	    echo "installing graphviz (dot) with apt-get"; \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq graphviz >/dev/null) \
	      || echo "warning: could not install graphviz; 'opportune graph' to svg/png will not work"; \
	  else \
	    echo "warning: graphviz 'dot' is missing: install it (e.g. sudo apt-get install graphviz)"; \
	  fi; \
	fi
	@if ! command -v chromium >/dev/null 2>&1; then \
	  if command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	    echo "installing chromium with apt-get (dashboard browser test)"; \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null) \
	      || echo "warning: could not install chromium; tests/test_service_browser.py will fail"; \
	  else \
	    echo "warning: chromium is missing: install it (e.g. sudo apt-get install chromium)"; \
	  fi; \
	fi

demo: setup
	$(BIN)/opportune check examples/gearbox.yaml
	$(BIN)/opportune count examples/gearbox.yaml
	$(BIN)/opportune replay examples/gearbox.yaml examples/gearbox-table1.looks
	$(BIN)/opportune simulate examples/gearbox.yaml --out demo-output

test: setup
	$(BIN)/python -m pytest -q

bench: setup
	$(BIN)/python benchmarks/bench_count.py
	$(BIN)/python benchmarks/bench_options.py
	$(BIN)/python benchmarks/bench_simulate.py

bench-service: setup
	$(BIN)/python benchmarks/load_service.py --cells 20 --duration 20

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis demo-output
