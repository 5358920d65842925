# Two commands: `make demo` and `make test`. Each sets itself up from nothing.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# The demo needs only the package itself (its compiled core and its dependencies, matplotlib
# included): no extra, no system package.  `setup` builds on it, so the core is compiled once.
CORE_STAMP := $(VENV)/.installed-core
EXTRAS := service,postgres,scale,dev,docs,physics,geometry,step
SOURCES := pyproject.toml CMakeLists.txt $(wildcard src/native/*.cpp src/native/*.hpp)

.PHONY: demo test docs setup core system-deps pg-deps bench bench-service clean

setup: $(STAMP) system-deps

core: $(CORE_STAMP)

$(CORE_STAMP): $(SOURCES)
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet -e .
	@# The package's bytecode, as pip writes it for a package it copies (not for an editable one): where
	@# PYTHONDONTWRITEBYTECODE is set, every process (each test worker, each command and server a test
	@# starts) would otherwise compile the modules it imports again (0.3-0.5 s of CPU each).  A module
	@# edited later is compiled afresh, as Python checks each file's time and size.
	@$(BIN)/python -m compileall -q src/opportune
	@touch $(CORE_STAMP)

# The extras' requirements only, read from pyproject.toml: reinstalling the package itself
# ('.[extras]') would compile the core a second time.
$(STAMP): $(CORE_STAMP) $(SOURCES)
	$(BIN)/python -c 'import tomllib; x = tomllib.load(open("pyproject.toml", "rb"))["project"]["optional-dependencies"]; \
	  print("\n".join(sorted({r for e in "$(EXTRAS)".split(",") for r in x[e]})))' > $(VENV)/extras.txt
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -r $(VENV)/extras.txt
	@touch $(STAMP)

# System tools from Debian's packages, installed only where missing: $(call apt,COMMAND,PACKAGE,WHAT FOR)
define apt
	@if ! command -v $(1) >/dev/null 2>&1; then \
	  if command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	    echo "installing $(2) with apt-get ($(3))"; \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(2) >/dev/null) \
	      || echo "warning: could not install $(2): $(3) will not work"; \
	  else \
	    echo "warning: $(1) is missing: install it (e.g. sudo apt-get install $(2)); $(3) needs it"; \
	  fi; \
	fi
endef

system-deps:
	$(call apt,dot,graphviz,opportune graph to svg/png)
	$(call apt,chromium,chromium,the dashboard browser test)
	@# PostgreSQL's server programs live off the PATH (/usr/lib/postgresql/N/bin): look there too
	@PATH="$$PATH:$$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | tr '\n' ':')" $(MAKE) --no-print-directory pg-deps

pg-deps:
	$(call apt,initdb,postgresql,the service tests on PostgreSQL)

demo: $(CORE_STAMP)
	$(BIN)/opportune check examples/gearbox.yaml
	$(BIN)/opportune count examples/gearbox.yaml
	$(BIN)/opportune replay examples/gearbox.yaml examples/gearbox-table1.looks
	$(BIN)/opportune simulate examples/gearbox.yaml --out demo-output

# On both cores (pytest-xdist); the longest tests start first (tests/conftest.py).
test: setup
	$(BIN)/python -m pytest -q -n 2 --dist worksteal

# The documentation site into site/ (MkDocs, offline; warnings are errors).
docs: setup
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir site

bench: setup
	$(BIN)/python benchmarks/bench_count.py
	$(BIN)/python benchmarks/bench_options.py
	$(BIN)/python benchmarks/bench_simulate.py

bench-service: setup
	$(BIN)/python benchmarks/load_service.py --cells 20 --duration 20 --table

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis demo-output
