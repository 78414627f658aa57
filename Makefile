# Two commands do all setup on a fresh machine:
#   make test   venv + pinned wheels + message build, then pytest
#   make demo   the same setup, then one docking episode on the mock profile (episode.png)
# Every step is stamped, so a second run with nothing changed goes straight to pytest.
# ROS_DISTRO selects the ROS 2 wheels from PyPI: kilted (default, what CI runs) or jazzy
# (`make test ROS_DISTRO=jazzy`), each in its own venv with its own pinned requirements.

ROS_DISTRO ?= kilted
ifeq ($(ROS_DISTRO),kilted)
VENV         ?= .venv
REQUIREMENTS := requirements.txt
else ifeq ($(ROS_DISTRO),jazzy)
VENV         ?= .venv-jazzy
REQUIREMENTS := requirements-jazzy.txt
else
$(error ROS_DISTRO=$(ROS_DISTRO): PyPI has ROS 2 wheels for kilted (default) and jazzy only)
endif

PYTHON ?= $(shell command -v python3.11 || command -v python3)
BUILD  ?= build/$(ROS_DISTRO)
PY      = $(VENV)/bin/python
STAMPS  = $(VENV)/.stamps
PYTEST_ARGS ?=

# Run-time environment: ament_index finds our share/ directory in the venv prefix.
export AMENT_PREFIX_PATH := $(abspath $(VENV))
# One OpenBLAS thread (as the launch file gives each node): the matrices are small, and a second
# thread spin-waits while the node processes the tests start hold the other core (2026-11-28,
# test_prior_select + test_learned_prior beside one busy process: 107 s with the default, 10 s).
export OPENBLAS_NUM_THREADS ?= 1

.PHONY: test test-slow test-perturbed colcon-test setup lint format clean distclean demo
.DEFAULT_GOAL := test

setup: $(STAMPS)/msgs

# The default suite covers every feature end to end; the long statistical checks and the checks
# of the checks (pytest -m slow) run in CI after it (.ci/run). TEST_WORKERS pytest processes
# (pytest-xdist; 0: one process) share it: most of its time is nodes' processes waiting on DDS
# and the simulated arm, and each worker has its own DDS domain (test/conftest.py). Measured
# 2026-11-28, 2 cores, one clone: 9:41 in one process, 6:34 with 2 workers (same 748 passed).
TEST_WORKERS ?= 2
test: setup
	$(PY) -m pytest -m "not slow" -n $(TEST_WORKERS) $(PYTEST_ARGS)

test-slow: setup
	$(PY) -m pytest -m slow $(PYTEST_ARGS)

# The robot workflow: `colcon build` of this package in a workspace (build/colcon, the venv as
# its underlay), then `colcon test` of what depends on the installed layout (the CMake install
# with every message, script and share file; package.xml against the imports) and
# `colcon test-result`. A broken colcon build or install layout fails here, not on the robot.
COLCON_WS     = build/colcon-$(ROS_DISTRO)
COLCON_ENV    = PATH="$(abspath $(VENV))/bin:$$PATH" CMAKE_PREFIX_PATH="$(abspath $(VENV))"
COLCON_PYTEST = -m "not slow" -k "install_layout or test_package"
colcon-test: $(STAMPS)/colcon
	@mkdir -p $(COLCON_WS)/src && ln -sfn $(CURDIR) $(COLCON_WS)/src/tactile_dock_ros
	cd $(COLCON_WS) && env $(COLCON_ENV) colcon build --packages-select tactile_dock_ros \
	  --cmake-args -DPython3_EXECUTABLE="$(abspath $(PY))" -Wno-dev > build.log 2>&1 \
	  || { tail -50 build.log; exit 1; }
	cd $(COLCON_WS) && env $(COLCON_ENV) PYTEST_ADDOPTS='$(COLCON_PYTEST)' colcon test \
	  --packages-select tactile_dock_ros --ctest-args -R pytest > test.log 2>&1 \
	  || { tail -50 test.log; exit 1; }
	cd $(COLCON_WS) && env $(COLCON_ENV) colcon test-result --verbose

$(STAMPS)/colcon: requirements-colcon.txt | $(STAMPS)/venv
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements-colcon.txt
	@touch $@

# The suite with the numeric environment of another machine: numba compiled for a generic
# x86-64 CPU, OpenBLAS forced to an older kernel set, one thread each. A test that passes only
# on this machine's floating point asserts one seed's coin (docs/testing.md).
PERTURBED_ENV ?= NUMBA_CPU_NAME=generic OPENBLAS_CORETYPE=Prescott OPENBLAS_NUM_THREADS=1 \
                 NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1
test-perturbed: setup
	env $(PERTURBED_ENV) $(PY) -m pytest $(PYTEST_ARGS)

# One episode on the mock profile: the five nodes as processes (as `ros2 launch ... profile:=mock`
# would start them), per-cycle progress, result, latency breakdown, episode.png; exit 0 on DOCKED.
DEMO_ARGS ?= --problem sloper --seed 0
demo: setup
	$(PY) -m tactile_dock_ros.tools.demo $(DEMO_ARGS) --png episode.png

lint: $(STAMPS)/venv
	$(VENV)/bin/ruff check . && $(VENV)/bin/ruff format --check .

format: $(STAMPS)/venv
	$(VENV)/bin/ruff format . && $(VENV)/bin/ruff check --fix .

$(STAMPS)/python:
	@$(PYTHON) -c 'import sys; assert sys.version_info[:2] == (3, 11), "Python 3.11 is required (the ROS 2 wheels on PyPI are cp311), found " + sys.version' \
	  || { echo "set PYTHON=/path/to/python3.11"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	@mkdir -p $(STAMPS) && touch $@

$(STAMPS)/venv: $(REQUIREMENTS) | $(STAMPS)/python
	$(PY) -m pip install --quiet --disable-pip-version-check -r $(REQUIREMENTS)
	@touch $@

# The messages are built with the very same CMake project `colcon build` uses, installed into
# the venv prefix. The hand-written Python package is NOT copied in for this developer build
# (TACTILE_DOCK_INSTALL_PYTHON=OFF): it is imported from the work tree, so edits need no reinstall.
# The share files (launch, config, security, node scripts) are installed too: a change to any of
# them reinstalls, so launch files and tools that look them up never run a stale copy.
SHARE_FILES = $(wildcard launch/* config/* security/* scripts/*)
$(STAMPS)/msgs: $(STAMPS)/venv CMakeLists.txt package.xml $(wildcard msg/*.msg srv/*.srv action/*.action) $(SHARE_FILES)
	@mkdir -p $(BUILD)
	PATH="$(abspath $(VENV))/bin:$$PATH" cmake -S . -B $(BUILD) -Wno-dev \
	  -DCMAKE_PREFIX_PATH="$(abspath $(VENV))" -DCMAKE_INSTALL_PREFIX="$(abspath $(VENV))" \
	  -DPython3_EXECUTABLE="$(abspath $(PY))" -DBUILD_TESTING=OFF \
	  -DTACTILE_DOCK_INSTALL_PYTHON=OFF > $(BUILD)/configure.log 2>&1 \
	  || { cat $(BUILD)/configure.log; exit 1; }
	cmake --build $(BUILD) -j2 > $(BUILD)/build.log 2>&1 || { tail -50 $(BUILD)/build.log; exit 1; }
	cmake --install $(BUILD) > $(BUILD)/install.log 2>&1 || { tail -50 $(BUILD)/install.log; exit 1; }
	@touch $@

clean:
	rm -rf build .pytest_cache .hypothesis

distclean: clean
	rm -rf $(VENV)
