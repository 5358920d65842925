# Two commands: `make demo` and `make test`. Each sets itself up from nothing.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test setup system-deps bench clean

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

demo: setup
	$(BIN)/opportune check examples/gearbox.yaml
	$(BIN)/opportune count examples/gearbox.yaml
	$(BIN)/opportune replay examples/gearbox.yaml examples/gearbox-table1.looks
	$(BIN)/opportune simulate examples/gearbox.yaml --out demo-output

test: setup
	$(BIN)/python -m pytest -q

bench: setup
	$(BIN)/python benchmarks/bench_count.py

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis demo-output
