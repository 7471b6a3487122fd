# feeder_ros: `make demo` runs the simulated feeder cell end to end, `make test` runs every check.
# Both install what they need first (system tools, the project venv with pinned wheels, the
# interfaces built with rosidl); a second run rebuilds nothing that has not changed.

SHELL := /bin/bash
.DEFAULT_GOAL := help

VENV := .venv
PY := $(VENV)/bin/python
WORK := .work
STAMPS := $(WORK)/stamps
WS := $(WORK)/ws

INTERFACE_SOURCES := CMakeLists.txt package.xml $(wildcard msg/*.msg srv/*.srv) tools/install_interfaces.py
PACKAGE_SOURCES := $(shell find feeder_ros config resource -type f -not -path '*/__pycache__/*' 2>/dev/null)
LINT_PATHS := $(wildcard feeder_ros test bench tools examples launch) setup.py

.PHONY: help install workspace test lint typecheck pytest demo bench constraints clean

help:
	@echo "make demo   - run the simulated feeder cell end to end (installs what it needs)"
	@echo "make test   - lint, type-check, build both install paths and run all tests"
	@echo "make bench  - run the benchmarks and print ratios against their baselines"

$(STAMPS):
	@mkdir -p $@

$(STAMPS)/system: tools/ensure_system.sh | $(STAMPS)
	tools/ensure_system.sh
	@touch $@

$(STAMPS)/venv: requirements.txt constraints.txt $(STAMPS)/system
	@test -x $(PY) || { py=$$(command -v python3.11 || command -v python3); echo "creating $(VENV) with $$py"; $$py -m venv $(VENV); }
	$(PY) -m pip install --quiet --disable-pip-version-check -c constraints.txt -r requirements.txt
	@touch $@

$(STAMPS)/interfaces: $(STAMPS)/venv $(INTERFACE_SOURCES)
	$(PY) tools/install_interfaces.py --build $(WORK)/build-venv
	@touch $@

$(STAMPS)/package: $(STAMPS)/interfaces setup.py
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation \
		--config-settings editable_mode=compat -e .
	@touch $@

# numba compiles the exact solver on first use; do it once here (cached next to the sources)
# so that nodes and tests start in a second instead of paying the compile each time.
$(STAMPS)/solver-cache: $(STAMPS)/package $(wildcard feeder_ros/physics/*.py)
	$(PY) tools/warm_solver_cache.py
	@touch $@

install: $(STAMPS)/package $(STAMPS)/solver-cache

$(STAMPS)/workspace: $(STAMPS)/interfaces setup.py $(PACKAGE_SOURCES) tools/build_workspace.sh
	VENV=$(CURDIR)/$(VENV) tools/build_workspace.sh $(CURDIR)/$(WS)
	source $(WS)/install/local_setup.sh && cd /tmp && $(CURDIR)/$(PY) $(CURDIR)/tools/warm_solver_cache.py
	@touch $@

workspace: $(STAMPS)/workspace

lint: $(STAMPS)/venv
	$(VENV)/bin/ruff check $(LINT_PATHS)
	$(VENV)/bin/ruff format --check $(LINT_PATHS)

typecheck: install
	$(VENV)/bin/mypy

pytest: install workspace
	@FEEDER_ROS_WORKSPACE=$(CURDIR)/$(WS) $(PY) -m pytest $(PYTEST_ARGS); status=$$?; \
	if [ $$status -eq 5 ]; then echo "pytest collected no tests: that is a failure here" >&2; exit 1; fi; \
	if [ $$status -ne 0 ] && [ -s $(WORK)/test-hang.log ]; then cat $(WORK)/test-hang.log >&2; fi; \
	exit $$status

test: lint typecheck pytest

demo: install
	$(PY) -m feeder_ros.demo --output demo-output

bench: install
	$(PY) bench/run_all.py

constraints: $(STAMPS)/venv
	{ echo "# Exact versions for the project venv: make installs requirements.txt under these constraints."; \
	  echo "# Regenerate with: make constraints"; \
	  $(PY) -m pip freeze --exclude feeder_ros --exclude-editable | sort -f; } > constraints.txt

clean:
	rm -rf $(WORK) build *.egg-info demo-output
