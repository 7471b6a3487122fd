# feeder_ros: `make demo` runs the simulated feeder cell end to end, `make test` runs every check.
# Both install what they need first (system tools, the project venv with pinned wheels, the
# interfaces built with rosidl); a second run rebuilds nothing that has not changed.
# ROS_DISTRO chooses the ROS 2 wheel set (distros/<distro>/): jazzy (default) or kilted. The venv
# records the distribution it holds; asking for another one rebuilds the venv and the build.

SHELL := /bin/bash
.DEFAULT_GOAL := help

SUPPORTED_DISTROS := jazzy kilted
ifeq ($(origin ROS_DISTRO),undefined)
ROS_DISTRO := jazzy
endif
ifeq ($(filter $(ROS_DISTRO),$(SUPPORTED_DISTROS)),)
$(error ROS_DISTRO=$(ROS_DISTRO) has no wheel set here: choose one of $(SUPPORTED_DISTROS) (e.g. make test ROS_DISTRO=kilted))
endif
export ROS_DISTRO
DISTRO_DIR := distros/$(ROS_DISTRO)

VENV := .venv
PY := $(VENV)/bin/python
WORK := .work
STAMPS := $(WORK)/stamps/$(ROS_DISTRO)
WS := $(WORK)/ws

INTERFACE_SOURCES := CMakeLists.txt package.xml $(wildcard msg/*.msg srv/*.srv action/*.action) tools/install_interfaces.py
PACKAGE_SOURCES := $(shell find feeder_ros config resource -type f -not -path '*/__pycache__/*' 2>/dev/null)
LINT_PATHS := $(wildcard feeder_ros test bench tools launch) setup.py

.PHONY: help install workspace browser pictures test test-ros lint typecheck pytest demo bench constraints clean

# The ROS-facing tests: install paths, interface build, DDS smoke, every node over DDS, the cell,
# the demo and the two-host layout. CI runs them on the second distribution (make test-ros
# ROS_DISTRO=kilted); make test runs everything.
ROS_TESTS := test/ros test/test_install_paths.py test/test_interfaces.py test/test_dds_smoke.py \
	test/test_cell.py test/test_demo.py test/test_demo_runs.py test/test_logging_calls.py \
	test/test_dependencies.py

help:
	@echo "make demo   - run the simulated feeder cell end to end (installs what it needs)"
	@echo "make test   - lint, type-check, build both install paths and run all tests"
	@echo "              (ROS_DISTRO=jazzy by default, or kilted; the venv is rebuilt on a switch)"
	@echo "make test-ros - type-check and run only the ROS-facing tests"
	@echo "make bench  - run the benchmarks and print ratios against their baselines"
	@echo "make pictures - the README's picture of the report (after make demo)"

$(STAMPS):
	@mkdir -p $@

$(STAMPS)/system: tools/ensure_system.sh | $(STAMPS)
	tools/ensure_system.sh
	@touch $@

# The venv records the distribution it holds ($(VENV)/ros-distro). Stamps are kept per
# distribution, so asking for another one runs this rule, which wipes the venv and the builds
# (ROS wheels of two distributions cannot share one venv; the CMake caches name the old wheels).
$(STAMPS)/venv: requirements.txt $(DISTRO_DIR)/requirements.txt $(DISTRO_DIR)/constraints.txt $(STAMPS)/system
	@held=$$(cat $(VENV)/ros-distro 2>/dev/null || true); \
	if [ -d $(VENV) ] && [ "$$held" != $(ROS_DISTRO) ]; then \
	  echo "the venv holds ROS 2 $${held:-(unknown)}: rebuilding it and the builds for $(ROS_DISTRO)"; \
	  rm -rf $(VENV) $(WORK)/build-venv $(WS); \
	  find $(WORK)/stamps -mindepth 1 -maxdepth 1 -not -name $(ROS_DISTRO) -exec rm -rf {} +; \
	fi
	@test -x $(PY) || { py=$$(command -v python3.11 || command -v python3); echo "creating $(VENV) for ROS 2 $(ROS_DISTRO) with $$py"; $$py -m venv $(VENV); }
	$(PY) -m pip install --quiet --disable-pip-version-check -c $(DISTRO_DIR)/constraints.txt \
		-r requirements.txt -r $(DISTRO_DIR)/requirements.txt
	echo $(ROS_DISTRO) > $(VENV)/ros-distro
	@touch $@

$(STAMPS)/interfaces: $(STAMPS)/venv $(INTERFACE_SOURCES)
	$(PY) tools/install_interfaces.py --build $(WORK)/build-venv
	@touch $@

$(STAMPS)/package: $(STAMPS)/interfaces setup.py
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation \
		--config-settings editable_mode=compat -e .
	@touch $@

# numba compiles the exact solver and the estimator on first use; do it once here (cached next to
# the sources) so that nodes and tests start in a second instead of paying the compile each time.
$(STAMPS)/solver-cache: $(STAMPS)/package $(wildcard feeder_ros/physics/*.py feeder_ros/physics/exact/*.py \
		feeder_ros/estimation/*.py) \
		tools/warm_solver_cache.py
	$(PY) tools/warm_solver_cache.py
	@touch $@

install: $(STAMPS)/package $(STAMPS)/solver-cache

$(STAMPS)/workspace: $(STAMPS)/interfaces setup.py $(PACKAGE_SOURCES) tools/build_workspace.sh \
		tools/warm_solver_cache.py
	VENV=$(CURDIR)/$(VENV) tools/build_workspace.sh $(CURDIR)/$(WS)
	source $(WS)/install/local_setup.sh && cd /tmp && $(CURDIR)/$(PY) $(CURDIR)/tools/warm_solver_cache.py
	@touch $@

workspace: $(STAMPS)/workspace

lint: $(STAMPS)/venv
	$(VENV)/bin/ruff check $(LINT_PATHS)
	$(VENV)/bin/ruff format --check $(LINT_PATHS)

typecheck: install
	$(VENV)/bin/mypy

# the report tests render the HTML report in a real browser
browser:
	@tools/ensure_browser.sh

pytest: install workspace browser
	@FEEDER_ROS_WORKSPACE=$(CURDIR)/$(WS) $(PY) -m pytest $(PYTEST_ARGS); status=$$?; \
	if [ $$status -eq 5 ]; then echo "pytest collected no tests: that is a failure here" >&2; exit 1; fi; \
	if [ $$status -ne 0 ] && [ -s $(WORK)/test-hang.log ]; then cat $(WORK)/test-hang.log >&2; fi; \
	exit $$status

test: lint typecheck pytest

test-ros: PYTEST_ARGS := $(ROS_TESTS)
test-ros: typecheck pytest

demo: install
	$(PY) -m feeder_ros.demo --output demo-output

# the README's picture of the report: the top of the demo's report as a 1280 px window shows it
pictures: browser
	@test -f demo-output/report/report.html || { echo "run make demo first: it writes demo-output/report/report.html" >&2; exit 1; }
	mkdir -p docs/images
	chromium --headless --no-sandbox --disable-gpu --hide-scrollbars --window-size=1280,1500 \
		--screenshot=$(CURDIR)/docs/images/report.png file://$(CURDIR)/demo-output/report/report.html

bench: install
	$(PY) bench/run_all.py

constraints: $(STAMPS)/venv
	{ echo "# Exact versions for the project venv on ROS 2 $(ROS_DISTRO): make installs requirements.txt"; \
	  echo "# and $(DISTRO_DIR)/requirements.txt under these constraints."; \
	  echo "# Regenerate with: make constraints ROS_DISTRO=$(ROS_DISTRO)"; \
	  $(PY) -m pip freeze --exclude feeder_ros --exclude-editable | sort -f; } > $(DISTRO_DIR)/constraints.txt

clean:
	rm -rf $(WORK) build *.egg-info demo-output
